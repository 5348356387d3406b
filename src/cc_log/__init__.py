"""cc_log: anomaly-triggered, compressed logging for ROS 1 robots.

The library stands in floors, each package importing only from those below it (``test/test_floors.py``):

1. ``base``: records, the grammar of spans, codecs, safe input and files, event kinds, routes, topic selection;
2. ``buffer`` (the window buffer) and ``features`` (what the detectors see);
3. ``learning`` (the classifier's model, training, drift, the physics envelope) and ``storage`` (the window
   formats, the writer, the quota, recovery);
4. ``triggers`` (what opens a window) and ``sim`` (the simulated BWIBot);
5. ``logger``: the smart logger and collect mode shared by the live nodes and offline replay, the options and
   the configuration;
6. ``nodes`` (the ROS edge: rospy only here) and ``offline`` (the ``cclog`` command).
"""

__version__ = '0.1.0'
