#!/usr/bin/env python3
"""Live cost of the smart node next to `rosbag record` of the same topics in the same run: CPU and peak RSS
with odometry + IMU at 100 Hz + 100 Hz and at 1 kHz + 1 kHz.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/cost_live.py                      # 60 s at 100 + 100 Hz, then 60 s at 1000 + 1000 Hz
    python3 bench/cost_live.py --seconds 10         # shorter runs
    python3 bench/cost_live.py --quick              # 3 s runs at 100 and 1000 Hz (tests)

What it starts (each in its own session, all stopped at the end by their process ids):
- ``roscore -p <free port>`` with ROS_MASTER_URI, ROS_HOME and ROS_LOG_DIR pointing at it and a temporary
  directory for every child;
- the smart node: ``rosrun cc_log smart_logger.py _model:=<model> _directory:=<tmp> _topics:=/imu
  odom:=/odom``; the model is trained here, for each rate, on a nominal simulated run at that rate (cc_log.sim
  seed 2, 5 min, 1 with --quick, motion 500-message window, a vector every 0.1 s): the nominal case at every rate;
- ``rosbag record -O <tmp>/record.bag /odom /imu`` (no compression, its default) beside it, in every run;
- a publisher (this script with --publisher): simulated BWIBot odometry and IMU (cc_log.sim seed 3, nominal,
  simulated at the rate it is published, as it goes, for the whole run) on /odom and /imu, each at the given
  rate, with header stamps of the current time; it also listens to /diagnostics and reports the node's last
  "messages seen", the largest "intake queue" it saw and the node's thread CPU times. ``--loop-seconds 20``
  publishes 20 s of it in a loop instead, as the earlier figures did: the robot then jumps back to its start
  every 20 s, which the node rightly keeps as windows (2 in 60 s), so those runs also cost writing them.

CPU % of one core = process CPU time (user + system, psutil, children included for rosbag record, which runs
the C++ `record` under a Python wrapper) from just before the publisher starts to just after it ends (1 s
of connection set-up and 2 s of draining included: a slight overestimate), divided by the publishing
seconds. Peak RSS = VmHWM of /proc/<pid>/status (summed over the process tree for rosbag record).
A rate is sustained when the node has seen every published message within 2 s after the publisher stops
(its intake queue is unbounded: nothing is dropped at the socket, so falling behind shows as a growing
intake queue and messages seen < published).
"""
import argparse
import contextlib
import itertools
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

TARGET = 0.7  # node CPU / rosbag record CPU of the same light topics in the same run (issue 43)
STAGES = ('classifier CPU s', 'feeder CPU s', 'writer CPU s')  # the node's thread CPU times on /diagnostics


# -- the publisher child -------------------------------------------------------------------------------

def publisher(args):
    import rospy
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry
    from cc_log import sim
    from sensor_msgs.msg import Imu
    minutes = (args.loop_seconds or args.seconds + 5.0) / 60.0
    simulator = sim.Simulator(sim.SimConfig(rate=args.rate, seed=3, minutes=minutes, anomalies=0,
                                            imu=True, jitter=0.05 / args.rate))  # simulated at the rate published
    pairs = _odometry_imu_pairs(simulator.messages())
    if args.loop_seconds:
        pairs = itertools.cycle(list(pairs))
    rospy.init_node('cc_log_bench_publisher', disable_signals=True)
    state = {'seen': None, 'intake_max': 0, 'windows': None, 'stages': {}}

    def on_diagnostics(array):
        for status in array.status:
            values = {kv.key: kv.value for kv in status.values}
            if 'messages seen' in values:
                state['seen'] = int(values['messages seen'])
                state['intake_max'] = max(state['intake_max'], int(values.get('intake queue', 0)))
                state['stages'] = {key: float(values.get(key, 'nan')) for key in STAGES}
                state['windows'] = int(values.get('windows saved', 0))
    rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics)
    pub = rospy.Publisher('/odom', Odometry, queue_size=10000)
    imu_pub = rospy.Publisher('/imu', Imu, queue_size=10000)
    deadline = time.time() + 10.0
    while min(pub.get_num_connections(), imu_pub.get_num_connections()) < args.subscribers and \
            time.time() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)
    sent, start = 0, time.time()
    end = start + args.seconds
    while True:
        now = time.time()
        if now >= end:
            break
        due = min(int((now - start) * args.rate) + 1, int(args.seconds * args.rate))
        while sent < due:
            msg, other = next(pairs)
            msg.header.seq = sent
            msg.header.stamp = rospy.Time.from_sec(start + sent / args.rate)
            pub.publish(msg)
            other.header.seq, other.header.stamp = sent, msg.header.stamp
            imu_pub.publish(other)
            sent += 1
        time.sleep(max(0.0, min(0.001, start + (sent / args.rate) - time.time())))
    publish_seconds = time.time() - start
    # wait (up to 2 s after the last diagnostics update) for the node to catch up
    sent *= 2  # odometry and IMU
    drain_end = time.time() + 2.5
    while time.time() < drain_end and (state['seen'] is None or state['seen'] < sent):
        time.sleep(0.1)
    time.sleep(1.2)  # one more diagnostics period
    print(json.dumps({'sent': sent, 'publish_seconds': publish_seconds, 'seen': state['seen'],
                      'intake_max': state['intake_max'], 'windows': state['windows'], 'stages': state['stages']}))
    rospy.signal_shutdown('done')
    return 0


def _odometry_imu_pairs(generated):
    """``(odometry, imu)`` message pairs, each topic in its order, from the simulator's ``(topic, stamp, msg)``."""
    from cc_log import sim
    mine, other = itertools.tee(generated)
    return zip((msg for topic, _, msg in mine if topic == sim.ODOM_TOPIC),
               (msg for topic, _, msg in other if topic == sim.IMU_TOPIC))


# -- processes -----------------------------------------------------------------------------------------

def free_port():
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


class Processes(object):
    """Children started in their own sessions; stop() ends each by its id (SIGINT, then SIGKILL)."""

    def __init__(self, env, logdir):
        self.env, self.logdir, self.children = env, logdir, []

    def start(self, name, command):
        log = open(os.path.join(self.logdir, name + '.log'), 'w')
        process = subprocess.Popen(command, env=self.env, stdout=log, stderr=subprocess.STDOUT,
                                   start_new_session=True)
        self.children.append((name, process, log))
        return process

    def stop(self, process, timeout=15.0):
        if process.poll() is None:
            try:
                os.killpg(process.pid, signal.SIGINT)
            except ProcessLookupError:
                pass
            try:
                process.wait(timeout)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                process.wait(5)

    def stop_all(self):
        for name, process, log in reversed(self.children):
            self.stop(process)
            log.close()


def tree(pid):
    import psutil
    try:
        root = psutil.Process(pid)
        return [root] + root.children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def cpu_of(pid):
    total = 0.0
    for process in tree(pid):
        try:
            times = process.cpu_times()
            total += times.user + times.system + times.children_user + times.children_system
        except Exception:
            pass
    return total


def memory_mb(pid, key='VmHWM'):
    """MB of ``key`` in /proc/<pid>/status (VmHWM: peak RSS, VmRSS: RSS now), summed over the process tree."""
    total = 0
    for process in tree(pid):
        try:
            with open('/proc/%d/status' % process.pid) as stream:
                for line in stream:
                    if line.startswith(key + ':'):
                        total += int(line.split()[1])
        except IOError:
            pass
    return total / 1024.0


def wait_master(env, seconds=30.0):
    import rosgraph
    os.environ['ROS_MASTER_URI'] = env['ROS_MASTER_URI']
    deadline = time.time() + seconds
    while time.time() < deadline:
        try:
            rosgraph.Master('/cc_log_bench').getPid()
            return True
        except Exception:
            time.sleep(0.3)
    raise RuntimeError('roscore did not come up within %g s' % seconds)


def wait_subscribers(topic, count, seconds=30.0):
    import rosgraph
    master = rosgraph.Master('/cc_log_bench')
    deadline = time.time() + seconds
    while time.time() < deadline:
        _, subscribers, _ = master.getSystemState()
        for name, nodes in subscribers:
            if name == topic and len(nodes) >= count:
                return True
        time.sleep(0.3)
    raise RuntimeError('%s: fewer than %d subscribers after %g s' % (topic, count, seconds))


def require_package():
    """Exit with one line when ``rosrun cc_log`` cannot find the package (a shell without the catkin workspace)."""
    found = subprocess.run(['rospack', 'find', 'cc_log'], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                           universal_newlines=True) if shutil.which('rospack') else None
    if found is None or found.returncode:
        sys.exit('bench: rosrun cannot find the cc_log package here: run `./dev.sh setup` once, then '
                 '`source .catkin_ws/devel/setup.bash; export PATH=/usr/bin:$PATH`, and run the bench again')


@contextlib.contextmanager
def roscore_session(prefix):
    """``(Processes, temporary directory)`` with a roscore on a free port running; at the end every process is
    stopped and the directory removed. Exits first when the package cannot be run (``require_package``)."""
    require_package()
    tmp = tempfile.mkdtemp(prefix=prefix)
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI='http://127.0.0.1:%d' % port, ROS_HOME=os.path.join(tmp, 'ros_home'),
               ROS_LOG_DIR=os.path.join(tmp, 'ros_log'), ROS_IP='127.0.0.1')
    env.pop('ROS_HOSTNAME', None)
    procs = Processes(env, tmp)
    try:
        procs.start('roscore', ['roscore', '-p', str(port)])
        wait_master(env)
        yield procs, tmp
    finally:
        procs.stop_all()
        shutil.rmtree(tmp, ignore_errors=True)


def train_model(path, rate, minutes=5.0):
    """A motion model (500-message window) trained on a nominal simulated run (seed 2, ``minutes``) at ``rate``
    Hz, the rate the publisher streams: the nominal case at every rate (one vector per 0.1 s of data)."""
    from cc_log.learning import learning
    from cc_log import sim
    from cc_log.features import FeatureConfig
    records, _ = common.sim_records(sim.SimConfig(rate=rate, seed=2, minutes=minutes, anomalies=0, jitter=0.05 / rate))
    config = FeatureConfig('motion', '500')
    _, X = common.window_vectors(records, sim.ODOM_TOPIC, config, stride=max(1, int(round(rate / 10.0))))
    model, _ = learning.train(X, config=config)
    return model.save(path)


def run(procs, tmp, model, rate, seconds, with_record, loop_seconds=0.0):
    """One run: node (+ rosbag record) + publisher; returns the figures."""
    out_dir = os.path.join(tmp, 'windows_%d' % rate)
    node = procs.start('smart_node_%d' % rate, ['rosrun', 'cc_log', 'smart_logger.py', '_model:=' + model,
                                                '_directory:=' + out_dir, '_topics:=/imu', 'odom:=/odom'])
    record = None
    if with_record:
        record = procs.start('rosbag_record', ['rosbag', 'record', '-O', os.path.join(tmp, 'record_%d.bag' % rate),
                                               '/odom', '/imu'])
    wait_subscribers('/odom', 2 if with_record else 1)
    wait_subscribers('/imu', 2 if with_record else 1)
    time.sleep(1.0)
    cpu0 = {'node': cpu_of(node.pid), 'record': cpu_of(record.pid) if record else 0.0}
    output = subprocess.check_output([sys.executable, os.path.abspath(__file__), '--publisher', '--rate', str(rate),
                                      '--seconds', str(seconds), '--subscribers', '2' if with_record else '1',
                                      '--loop-seconds', str(loop_seconds)],
                                     env=procs.env, universal_newlines=True)
    result = json.loads(output.strip().splitlines()[-1])
    result['node_cpu'] = cpu_of(node.pid) - cpu0['node']
    result['node_rss'] = memory_mb(node.pid)
    if record:
        result['record_cpu'] = cpu_of(record.pid) - cpu0['record']
        result['record_rss'] = memory_mb(record.pid)
        procs.stop(record)
    procs.stop(node)
    result['rate'] = rate
    return result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--rates', default='100,1000', help='rates (Hz of each topic), each run beside rosbag record')
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--publisher', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--rate', type=float, default=100.0, help=argparse.SUPPRESS)
    parser.add_argument('--subscribers', type=int, default=1, help=argparse.SUPPRESS)
    parser.add_argument('--loop-seconds', type=float, default=0.0,
                        help='publish this many seconds of the simulation in a loop (default: one continuous run)')
    args = parser.parse_args(argv)
    if args.publisher:
        return publisher(args)
    if args.quick:
        args.seconds = 3.0
    rates = [int(r) for r in args.rates.split(',') if r]
    started = time.time()
    train_minutes = 1.0 if args.quick else 5.0
    common.header('Live cost of the smart node', [
        'data: cc_log.sim BWIBot odometry and IMU (seed 3, nominal, %s, restamped) published on /odom '
        'and /imu; model: motion 500-message window trained on a nominal simulated run (seed 2, %g min) at the rate '
        'streamed' % ('%g s looped' % args.loop_seconds if args.loop_seconds else 'one continuous run',
                      train_minutes),
        'runs: %s Hz on each topic for %g s each, rosbag record of both topics beside the node in the same run'
        % (', '.join(map(str, rates)), args.seconds)])
    results = []
    with roscore_session('cc_log_bench_live_') as (procs, tmp):
        for rate in rates:
            model = train_model(os.path.join(tmp, 'model_%d.json' % rate), rate, train_minutes)
            results.append(run(procs, tmp, model, rate, args.seconds, True, args.loop_seconds))
    rows = []
    for r in results:
        node, record = (100 * r[key] / r['publish_seconds'] for key in ('node_cpu', 'record_cpu'))
        ok = r['seen'] is not None and r['seen'] >= r['sent']
        rows.append(['%d + %d' % (r['rate'], r['rate']), '%.0f' % r['publish_seconds'], r['sent'], r['seen'],
                     r['intake_max'], '%.2f%%' % node, '%.2f%%' % record, '%.2f' % (node / record),
                     '%.0f' % r['node_rss'], '%.0f' % r['record_rss'], r['windows'], 'yes' if ok else 'NO'])
    common.table(['Hz odom + imu', 'seconds', 'published', 'seen by node', 'max intake queue', 'node CPU %',
                  'rosbag record CPU %', 'node / record', 'node peak RSS MB', 'record peak RSS MB', 'windows',
                  'kept up'], rows, 'Smart node and rosbag record of the same topics in the same run '
                 '(process CPU time / publishing seconds, % of one core):')
    rows = []
    for r in results:
        stages = r.get('stages') or {}
        classifier, feeder, writer = (stages.get(key, float('nan')) for key in STAGES)
        total = r['node_cpu']
        rest = total - feeder - writer
        rows.append(['%d + %d' % (r['rate'], r['rate'])] + ['%.2f s (%.0f%%)' % (value, 100 * value / total)
                                                            for value in (rest, feeder, writer)]
                    + ['%.2f s' % classifier, '%.2f s' % total])
    common.table(['Hz odom + imu', 'intake (rospy receive, queue; main thread, timers)',
                  'feeder thread (buffer, triggers, features, classifier)', 'writer thread',
                  'features + classifier (wall clock, in the feeder)', 'node total'], rows,
                 'Where the node\'s CPU goes (thread CPU times the node reports on /diagnostics at the end):')
    for r in results:
        ratio = r['node_cpu'] / r['record_cpu']
        print('target node CPU <= %.1fx rosbag record CPU at %d + %d Hz: %.2fx -> %s' % (
            TARGET, r['rate'], r['rate'], ratio, 'met' if ratio <= TARGET else 'NOT met'))
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
