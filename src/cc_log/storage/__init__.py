"""Storage: window files (a module per format), rosbag 2.0 files, the writer, recovery, the disk guard, uploads."""
