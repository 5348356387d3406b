"""rosbag 2.0 files: bounded reading, writing, salvage of cut files."""
