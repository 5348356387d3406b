"""The pure core (no rospy): the window buffer, the modes' logic, options, the model and training."""
