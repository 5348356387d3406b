"""The simulated BWIBot node (``rosrun cc_log sim_bwibot.py``): odometry with labelled anomalies, live.

Node name: ``sim_bwibot``. The robot, its floor and its anomalies are ``cc_log.sim``; this node publishes
them in real time (a tick every 1/rate s, late ticks made up for), stamped with the simulator's clock, which
starts at the ROS time (``rospy.Time.now()``) when the node starts.

Published topics (relative names: push the node into a namespace or remap them)
  ``odom`` (nav_msgs/Odometry, frame ``odom`` -> ``base_link``): at ``~rate`` Hz, steady.
  ``imu/data`` (sensor_msgs/Imu): at the same rate when ``~imu`` is true.
  ``cmd_vel`` (geometry_msgs/Twist, the planner's command) and ``move_base/status``
  (actionlib_msgs/GoalStatusArray) when ``~commands`` is true (see ``cc_log.sim``).
  ``camera/image_raw`` (sensor_msgs/Image, rgb8 320x240, 15 Hz) when ``~camera`` is true and ``scan``
  (sensor_msgs/LaserScan, 10 Hz) when ``~scan`` is true: ray-cast from the simulated pose (``cc_log.sim.sensors``).
  ``sim/anomaly`` (std_msgs/String, JSON): ground truth, one message when an anomaly starts
  ``{"event": "start", "type", "start", "end": null}`` and one when it ends
  ``{"event": "end", "type", "start", "end"}``; stamps are those of the odometry published at that moment.

Parameters (each resolved value is logged once)
  ``~rate`` (double, default 100.0): odometry messages per second.
  ``~seed`` (int, default 0): same seed, same robot run and anomalies.
  ``~anomalies`` (int, default 0): how many anomalies to inject.
  ``~anomaly_types`` (list or comma-separated string, default: all): which types.
  ``~imu`` (bool, default false): also publish ``imu/data``.
  ``~commands`` (bool, default false): also publish ``cmd_vel`` and ``move_base/status``.
  ``~camera``, ``~scan`` (bool, default false): also publish ``camera/image_raw`` / ``scan``.
  ``~minutes`` (double, default 0): how long to run; 0 = until shutdown. The node exits at the end.
  ``~truth_file`` (string, default: none): ground-truth JSON (as ``cc_log.sim.write_truth``), rewritten
  whenever an anomaly ends (and at shutdown when one was cut short; its end is then the last stamp).
  ``~gap`` (double, default 20.0), ``~warmup`` (double, default 20.0): seconds of nominal driving between
  anomalies / before the first.

Bad parameters print one line ``/sim_bwibot: ~<param>: <what is wrong>`` and exit with status 2.
"""
import json
import sys

import rospy
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Image, Imu, LaserScan
from std_msgs.msg import String

from cc_log import sim
from cc_log.nodes.node_common import ConfigError, Params, init_node, node_name, to_bool

NODE_NAME = 'sim_bwibot'
ODOM_TOPIC = 'odom'
IMU_TOPIC = 'imu/data'
TRUTH_TOPIC = 'sim/anomaly'
CMD_TOPIC = 'cmd_vel'
STATUS_TOPIC = 'move_base/status'
CAMERA_TOPIC = 'camera/image_raw'
SCAN_TOPIC = 'scan'
CATCH_UP = 1.0   # s: how far behind its clock the node still catches up
DEFAULTS = {'rate': 100.0, 'seed': 0, 'anomalies': 0, 'anomaly_types': 'all', 'imu': False, 'minutes': 0.0,
            'truth_file': '', 'gap': 20.0, 'warmup': 20.0, 'commands': False, 'camera': False,
            'scan': False}


def read_config(start_time):
    """(SimConfig, truth file or None) from the private parameters; ConfigError names the parameter."""
    params = Params()
    values = dict((name, params.value(name, DEFAULTS[name])) for name in sorted(DEFAULTS) if name != 'truth_file')
    values['truth_file'] = params.text('truth_file', DEFAULTS['truth_file'])
    try:
        config = sim.SimConfig(rate=values['rate'], seed=values['seed'], minutes=values['minutes'],
                               anomalies=values['anomalies'], anomaly_types=values['anomaly_types'],
                               imu=to_bool('imu', values['imu']), start_time=start_time, gap=values['gap'],
                               warmup=values['warmup'], jitter=0.0,
                               commands=to_bool('commands', values['commands']),
                               camera=to_bool('camera', values['camera']),
                               scan=to_bool('scan', values['scan'])).validate()
    except ConfigError:
        raise
    except ValueError as error:
        raise ConfigError('~%s' % error)
    truth_file = str(values['truth_file'] or '').strip() or None
    return config, truth_file


class SimNode(object):
    """Publishes a ``cc_log.sim.Simulator`` run in real time."""

    def __init__(self, config, truth_file=None):
        self.config = config
        self.truth_file = truth_file
        self.simulator = sim.Simulator(config)
        self.truth = []
        self._open = {}     # simulated start stamp -> published start stamp
        self.odom_pub = rospy.Publisher(ODOM_TOPIC, Odometry, queue_size=50)
        self.imu_pub = rospy.Publisher(IMU_TOPIC, Imu, queue_size=50) if config.imu else None
        self.truth_pub = rospy.Publisher(TRUTH_TOPIC, String, queue_size=20)
        self.publishers = {}   # sim topic -> publisher of the optional topics
        if config.commands:
            from actionlib_msgs.msg import GoalStatusArray
            from geometry_msgs.msg import Twist
            self.publishers = {sim.CMD_TOPIC: rospy.Publisher(CMD_TOPIC, Twist, queue_size=50),
                               sim.STATUS_TOPIC: rospy.Publisher(STATUS_TOPIC, GoalStatusArray, queue_size=20)}
        if config.camera:
            self.publishers[sim.CAMERA_TOPIC] = rospy.Publisher(CAMERA_TOPIC, Image, queue_size=5)
        if config.scan:
            self.publishers[sim.SCAN_TOPIC] = rospy.Publisher(SCAN_TOPIC, LaserScan, queue_size=10)
        self.published = 0

    def run(self):
        """Publish until the run ends or ROS shuts down, one tick every 1/rate s; a tick that took long (a
        camera frame on a busy machine) is made up for by the next ones, up to ``CATCH_UP`` s behind."""
        period = rospy.Duration(1.0 / self.config.rate)
        catch_up = rospy.Duration(CATCH_UP)
        due = rospy.get_rostime()
        last = None
        try:
            while not rospy.is_shutdown() and not self.simulator.done:
                # Stamps are the simulator's clock (started at the ROS time the node started, with the
                # simulator's own small jitter), not the moment of publishing: a loaded machine would
                # otherwise put its scheduling jitter into every velocity and acceleration.
                for topic, stamp, msg in self.simulator.step():
                    if topic == sim.ODOM_TOPIC:
                        self.odom_pub.publish(msg)
                        self.published += 1
                    elif topic == sim.IMU_TOPIC:
                        self.imu_pub.publish(msg)
                    elif topic == sim.TRUTH_TOPIC:
                        self._truth_event(json.loads(msg.data), stamp)
                    elif topic in self.publishers:
                        self.publishers[topic].publish(msg)
                    last = stamp
                due += period
                now = rospy.get_rostime()
                if now - due > catch_up:
                    due = now          # too far behind to catch up: go on from now (stamps stay behind)
                elif due > now:
                    rospy.sleep(due - now)
        except rospy.ROSInterruptException:
            pass
        finally:
            if self._open:   # anomalies cut short by the end of the run or shutdown
                for sim_start, (kind, start) in sorted(self._open.items()):
                    self.truth.append(sim.truth_entry(kind, start, last if last is not None else start))
                self._open.clear()
                self._write_truth()
        rospy.loginfo('%s: published %d odometry messages, %d anomalies', NODE_NAME, self.published,
                      len(self.truth))

    def _truth_event(self, event, now):
        if event['event'] == 'start':
            self._open[event['start']] = (event['type'], now)
            entry = sim.truth_entry(event['type'], now, None)
            rospy.loginfo('anomaly %s starts at %.3f', event['type'], now)
        else:
            kind, start = self._open.pop(event['start'], (event['type'], now))
            entry = sim.truth_entry(kind, start, now)
            self.truth.append(entry)
            rospy.loginfo('anomaly %s ends at %.3f (%.1f s)', kind, now, now - start)
            self._write_truth()
        self.truth_pub.publish(sim.truth_event(event['event'], entry))

    def _write_truth(self):
        if not self.truth_file:
            return
        try:
            sim.write_truth(self.truth_file, self.truth, topic=rospy.resolve_name(ODOM_TOPIC),
                            config=self.config, source='cc_log.nodes.sim_node')
        except (IOError, OSError) as error:
            rospy.logerr('~truth_file: cannot write %s: %s', self.truth_file, error)


def main(argv=None):
    """Run the node; return the exit status (2 with one line on stderr for bad configuration)."""
    argv = sys.argv if argv is None else argv
    try:
        init_node(NODE_NAME, argv)
        config, truth_file = read_config(rospy.Time.now().to_sec())
    except ConfigError as error:
        sys.stderr.write('%s: %s\n' % (node_name(NODE_NAME, argv), error))
        return 2
    SimNode(config, truth_file).run()
    return 0
