"""Simulated runs written straight into bags (no roscore, no rosbag): ``simulate_to_bag``.

The bag is written by ``storage.bag.bag_writer`` from the simulator's items (``messages.serialized``), with
the ground truth in its sidecar file (``truth``).
"""
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu
from std_msgs.msg import String

from cc_log.base import raw_message
from cc_log.base.safe_files import AtomicFile
from cc_log.sim.config import SimConfig
from cc_log.sim.messages import CMD_TOPIC, IMU_TOPIC, ODOM_TOPIC, TRUTH_TOPIC, ros_time, serialized
from cc_log.sim.truth import truth_path, write_truth
from cc_log.sim.world import Simulator
from cc_log.storage.bag import bag_writer


def simulate_to_bag(path, config=None, truth_file=None, compression='lz4', progress=None):
    """Simulate a whole run straight into a bag (no roscore) and its ground truth next to it.

    Writes ``path`` (odometry; IMU, commands, camera and scan when configured; /sim/anomaly events;
    ``compression`` 'lz4', 'bz2' or 'none') and the sidecar ``truth_file`` (default ``<path>.truth.json``);
    ``progress(done, total)`` is called now and then with simulated ticks. Returns the truth list.
    """
    config = (config or SimConfig()).validate()
    if config.minutes <= 0:
        raise ValueError('minutes: a bag needs a finite run (minutes > 0)')
    if compression not in bag_writer.COMPRESSIONS:
        raise ValueError('compression: expected lz4, bz2 or none, got %r' % (compression,))
    simulator = Simulator(config)
    kinds = {ODOM_TOPIC: Odometry, IMU_TOPIC: Imu, TRUTH_TOPIC: String, CMD_TOPIC: Twist}
    headers = {}

    def messages():
        total = simulator.total_ticks
        every = max(1, int(config.rate * 10))
        while not simulator.done:
            for topic, stamp, item in simulator.advance():
                if topic not in headers:  # filled before write_bag reads it, at the topic's first message
                    headers[topic] = raw_message.class_header(topic, kinds.get(topic) or type(item))
                when = item[1] if isinstance(item, tuple) else ros_time(stamp)[0]
                yield topic, when.secs, when.nsecs, serialized(item)
            if progress is not None and simulator.tick % every == 0:
                progress(simulator.tick, total)
        if progress is not None:
            progress(total, total)

    with AtomicFile(path, overwrite=True) as stream:
        bag_writer.write_bag(stream, messages(), headers, chunk_threshold=1024 * 1024, compression=compression)
    write_truth(truth_file or truth_path(path), simulator.truth, ODOM_TOPIC, config)
    return simulator.truth
