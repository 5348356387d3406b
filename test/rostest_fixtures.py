"""Shared fixtures of the cc_log rostests (not a test module): real Husky odometry, injected anomalies, a
model trained on the spot, the expected windows, and starting cc_log nodes as real processes."""
import copy
import os
import signal
import subprocess
import sys
import time

import numpy as np

from cc_log.storage.bag import bagio
from cc_log.learning import learning
from cc_log.logger.collector import VectorStream
from cc_log.features import FeatureConfig
from cc_log.base.records import Record

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
HUSKY = os.path.normpath(os.path.join(ROOT, '..', 'shared', 'data', 'real', 'husky_outdoor_2015.bag'))
ODOM = '/husky_velocity_controller/odom'
IMU = '/imu/data'
CONFIG = FeatureConfig('motion', '20')
BURST = 6            # messages of an injected burst
TRAIN = slice(0, 400)  # the first 40 s train the model; the Husky run is nominal up to about message 1350


def husky():
    """(odometry records, IMU records) of the real Husky bag, in bag order."""
    records = list(bagio.read_messages(HUSKY, [ODOM, IMU]))
    return [r for r in records if r.topic == ODOM], [r for r in records if r.topic == IMU]


def inject(records, at, count=BURST, amplitude=3.0):
    """Copies of odometry records with a jerky burst at ``at``: the twist flips by +-amplitude."""
    out = [Record(r.stamp, r.topic, copy.deepcopy(r.msg)) for r in records]
    for k in range(at, at + count):
        out[k].msg.twist.twist.linear.x += amplitude * (-1) ** k
        out[k].msg.twist.twist.angular.z += amplitude * (-1) ** k
    return out


def vectors(records, stride=1):
    """(index, vector) of odometry records, as collect and smart mode compute them."""
    stream = VectorStream(CONFIG, stride)
    return [(i, v) for i, v in ((i, stream.add(r.msg, r.stamp)) for i, r in enumerate(records)) if v is not None]


def burst_segments(odom, starts, length=BURST + 20):
    """Short runs of odometry beginning with a burst, apart in time: every vector of each is anomalous."""
    out = []
    for start in starts:
        out += inject(odom[start:start + length], 0)
    return out


def train_model(odom):
    """A model trained on the first 40 s, with burst examples as the anomalous vectors."""
    nominal = np.array([v for _, v in vectors(odom[TRAIN])])
    anomalous = np.array([v for _, v in vectors(burst_segments(odom, (40, 110, 180, 250, 320)))])
    model, _ = learning.train(nominal, anomalous, CONFIG)
    return model


def flagged(model, records):
    """Indices of the odometry records the model calls anomalous."""
    return [i for i, v in vectors(records) if model.is_anomalous(v)[0]]


def fired(model, records):
    """Indices of the odometry records at which the smart node's classifier trigger fires (its defaults:
    retrigger 'event', classify_every 50ms; the offline twin of the live node)."""
    from cc_log.triggers import ClassifierTrigger
    trigger = ClassifierTrigger('classifier', model, records[0].topic)
    return [i for i, r in enumerate(records) if trigger.on_record(r)]


def expected_windows(flags, n, pre, post):
    """[(first, last)] index ranges the logger must save: [i-pre, i+post] merged when they touch."""
    runs = []
    for i in sorted(flags):
        lo, hi = max(0, i - pre), min(n - 1, i + post)
        if runs and lo <= runs[-1][1] + 1:
            runs[-1][1] = max(runs[-1][1], hi)
        else:
            runs.append([lo, hi])
    return [tuple(run) for run in runs]


def write_bag(path, odom, imu=(), odom_topic='/odom', imu_topic='/imu/data'):
    """A bag of the records at their header stamps, in stamp order."""
    import rosbag
    merged = sorted([(r.stamp, 0, odom_topic, r.msg) for r in odom] + [(r.stamp, 1, imu_topic, r.msg) for r in imu],
                    key=lambda item: item[:2])
    with rosbag.Bag(path, 'w') as bag:
        for _, _, topic, msg in merged:
            bag.write(topic, msg, t=msg.header.stamp)
    return path


def imu_between(imu, first, last):
    """IMU records with stamps in [first.stamp, last.stamp]."""
    return [r for r in imu if first.stamp <= r.stamp <= last.stamp]


# -- processes ----------------------------------------------------------------------------------------------

def script(name):
    """Path of a cc_log script (run directly: rosrun's package search is slow in this workspace)."""
    return os.path.join(ROOT, 'scripts', name)


def start(name, *args, **kwargs):
    """Start a cc_log script as a process with ROS arguments; stdout/stderr are kept for the asserts.
    ``env``: environment variables to change (e.g. HOME)."""
    env = dict(os.environ, **kwargs.pop('env', {}))
    return subprocess.Popen([sys.executable, script(name)] + list(args), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, universal_newlines=True, env=env, **kwargs)


def stop(process, timeout=30.0):
    """SIGINT (as roslaunch does), wait; return (returncode, stdout, stderr)."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
    return process.returncode, out, err


def finish(process, timeout=30.0):
    """Wait for a process to exit by itself; return (returncode, stdout, stderr)."""
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
    return process.returncode, out, err


def wait_for(predicate, timeout, what):
    """Poll ``predicate`` (wall time) until true and return its value; AssertionError naming ``what`` after
    ``timeout``."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        result = predicate()
        if result:
            return result
        time.sleep(0.05)
    raise AssertionError('timed out after %g s waiting for %s' % (timeout, what))


def status_values(diagnostics, node):
    """``(level, message, {key: value})`` of the newest status of cc_log node ``node`` in ``diagnostics`` (the
    DiagnosticArrays received so far); ``(None, '', {})`` before the first."""
    for array in reversed(diagnostics):
        for status in array.status:
            if status.name == 'cc_log: %s' % node:
                return status.level, status.message, {kv.key: kv.value for kv in status.values}
    return None, '', {}


def received(diagnostics, node):
    """Messages that ``node`` has received, by its newest status: fed to its logger or still in its intake
    queue (-1 before the first status)."""
    values = status_values(diagnostics, node)[2]
    if 'messages seen' not in values:
        return -1
    return int(values['messages seen']) + int(values.get('intake queue', 0))


def settled(diagnostics, node, count):
    """Whether ``node`` has fed all of ``count`` messages to its logger and written what it had to: nothing
    in its intake or writer queue, no window open (smart nodes: as many saved as opened, or more: parts)."""
    values = status_values(diagnostics, node)[2]
    return (int(values.get('messages seen', -1)) >= count and values.get('intake queue') == '0'
            and values.get('writer queue') == '0'
            and int(values.get('windows opened', 0)) <= int(values.get('windows saved', 0)))


def subscribed(topic, node):
    """Whether ``node`` is registered with the master as a subscriber of ``topic``."""
    import rosgraph
    master = rosgraph.Master('/cc_log_test')
    _, subscribers, _ = master.getSystemState()
    return any(name == topic and node in nodes for name, nodes in subscribers)
