"""The simulated BWIBot and its labelled anomalies.

The paper evaluated CC-Log on a BWIBot simulated in Gazebo. Gazebo is not available here, so cc_log ships
this light kinematic simulator instead; it is also what the demo drives when there is no robot. The same
anomaly models also go into recorded odometry (``inject_anomalies``).

By concern:

- ``world``: ``Simulator``, the robot touring its floor, what it publishes, when its anomalies happen.
- ``config``: ``SimConfig``, what to simulate.
- ``floor``: ``FloorPlan``, the office floor as a graph, and the route the robot follows.
- ``kinematics``: ``Limits``, ``BWIBOT_LIMITS`` and the acceleration-limited twist.
- ``anomalies``: ``ANOMALY_TYPES`` and their models, shared by ``world`` and ``inject``.
- ``sensors``: the camera and the laser scanner, ray-cast against the floor's walls.
- ``messages``: topics, frames, stamps; odometry and IMU built and serialized by hand.
- ``truth``: ground truth ({'type', 'start', 'end'}), its ``/sim/anomaly`` events and sidecar files.
- ``bags``: ``simulate_to_bag``, a whole run straight into a bag.
- ``inject``: ``inject_anomalies`` into recorded odometry, ``nominal_envelope`` of a recorded robot.

This package re-exports the names the rest of cc_log uses (``from cc_log import sim; sim.Simulator``).
Everything here is pure and deterministic: the same configuration and seed give identical messages.
``rospy`` and ``rosbag`` are not imported.
"""
from cc_log.sim.anomalies import ANOMALY_TYPES, MAX_ANOMALY_SECONDS, SIM_ONLY_TYPES, parse_anomaly_types
from cc_log.sim.bags import simulate_to_bag
from cc_log.sim.config import DEFAULT_START_TIME, SimConfig
from cc_log.sim.floor import FloorPlan
from cc_log.sim.inject import inject_anomalies, nominal_envelope
from cc_log.sim.kinematics import BWIBOT_LIMITS, Limits
from cc_log.sim.messages import (CMD_TOPIC, IMU_FRAME, IMU_TOPIC, ODOM_TOPIC, STATUS_TOPIC, TRUTH_TOPIC,
                                 serialized)
from cc_log.sim.sensors import CAMERA_TOPIC, SCAN_TOPIC
from cc_log.sim.truth import TRUTH_FORMAT, load_truth, truth_entry, truth_event, truth_path, write_truth
from cc_log.sim.world import Simulator

__all__ = [
    'ANOMALY_TYPES', 'BWIBOT_LIMITS', 'CAMERA_TOPIC', 'CMD_TOPIC', 'DEFAULT_START_TIME', 'FloorPlan', 'IMU_FRAME',
    'IMU_TOPIC', 'Limits', 'MAX_ANOMALY_SECONDS', 'ODOM_TOPIC', 'SCAN_TOPIC', 'STATUS_TOPIC', 'SimConfig',
    'SIM_ONLY_TYPES', 'Simulator', 'TRUTH_FORMAT', 'TRUTH_TOPIC', 'inject_anomalies', 'load_truth', 'nominal_envelope',
    'parse_anomaly_types', 'serialized', 'simulate_to_bag', 'truth_entry', 'truth_event', 'truth_path',
    'write_truth',
]
