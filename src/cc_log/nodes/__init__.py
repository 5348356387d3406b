"""The ROS edge: the nodes, their intake, parameters and topic watching."""
