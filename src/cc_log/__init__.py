"""cc_log: anomaly-triggered, compressed logging for ROS 1 robots.

The library is a pure core (no rospy) with ROS at the edges:

- ``spans``, ``window_buffer``: window sizes and the buffer of messages around anomalies;
- ``features``, ``model``, ``learning``: what the classifier sees, the model file, training;
- ``msg_codec``, ``log_format``, ``formats`` (one module per format): the window files cc_log writes and reads;
- ``smart_logger``: the smart logger shared by the live node and offline replay;
- ``*_node`` modules and ``cli``: the ROS nodes and the ``cclog`` command.
"""

__version__ = '0.1.0'
