#!/usr/bin/env python3
"""Heavy sensors live (issue 28): the smart node beside ``rosbag record`` and ``rosbag record --lz4`` of the same
cameras, lidar, odometry and IMU played from a bag at ~37 MB/s (one camera) or ~100 MB/s (two cameras and a
denser lidar), with one window, windows ~10% of the time, or a window open all the time.

    cd <tree> && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/heavy_sensors.py                          # ~37 MB/s, 30 s, every scenario and format
    python3 bench/heavy_sensors.py --rate 100 --scenarios one,all --format bag-lz4
    python3 bench/heavy_sensors.py --quick                  # 6 s, one window, bag-lz4 (tests)
    python3 bench/heavy_sensors.py --scenarios one,all --format bag-lz4 --wall-clock   # on wall time, no /clock

Workload: bench/heavy_workload.py (30 Hz 640x480 rgb8 images, a 10 Hz PointCloud2 of 28,800 points, 100 Hz
odometry and IMU, ~37 MB/s; --rate 100: a second camera and 131,072 points, ~97 MB/s), built once into --out.

Each run (one scenario, one format) starts, beside a roscore on a free port (cost_live.roscore_session, every
process in its own session, stopped by its id) with /use_sim_time true (--wall-clock: false, as a robot runs):
- the smart node: ``rosrun cc_log smart_logger.py _model:=<model> odom:=/odom _topics:="imu/data
  camera/image_raw velodyne_points" _pre:=2s _post:=2s _format:=<format>``, every other parameter at its
  default. The model is cost_live.train_model's (motion 500, nominal simulated odometry at 100 Hz, 1 min) with
  its threshold lowered so that the classifier runs on the odometry as usual but never fires: the bench's
  triggers alone open windows;
- ``rosbag record -O ...`` and ``rosbag record --lz4 -O ...`` of the same topics;
- ``rosbag play --clock --wait-for-subscribers <workload bag>`` once all three subscribe to every topic
  (--wall-clock: without ``--clock``; nothing publishes /clock).
The played clock, which the bench's plan follows (when it calls the trigger services, where a window starts and
ends, the wall time the clock passed a window's end): /clock; with --wall-clock the header stamps of the played
odometry, which the bench's own node subscribes to (the node places windows by header stamps either way).
Scenarios (bag time from the bag's start):
- one: ``~trigger`` halfway: one 4 s window (pre 2 s, post 2 s);
- tenth: ``~trigger_window`` (before 1.5 s, after 1.5 s) at 15 s and every 30 s: windows open 10% of the time;
- all: ``~trigger_window`` (before 2 s, after the run + 10 s) at 2.5 s: a window open to the end that message
  time never closes; the node is stopped (SIGINT) once the recorders are (2-3 s after the play).

Measured per run:
- CPU: user + system seconds of each process tree (cost_live.cpu_of) from the play's start to 1 s after it
  ends, as % of one core over the play's wall seconds; the node's CPU after that, until it is done, apart;
- peak RSS: VmHWM summed over the process tree (cost_live.memory_mb), sampled every 0.1 s;
- the window directory, listed every 0.1 s; after the play a window is complete when no ``*.tmp-*`` is left,
  no new file came for 2 s and the node's /diagnostics says writer queue 0, within --wait seconds; then the
  node is stopped (SIGINT; after --wait seconds SIGTERM, 5 s later SIGKILL) and the files it writes on the way
  out count too;
- s to disk: from the wall time the played clock passed the last window's end (scenario all: the SIGINT) to
  the first sight of the last file (``*``: written only at shutdown; ``>N``: none by then);
- kept: messages per topic in the window files (log_format.read_window) against the workload's messages whose
  stamps lie in the windows' spans [trigger - before, trigger + after] (trigger: its stamp in a file's
  metadata, else the clock at the call); missing = expected - kept;
- node says: the node's last nonzero /diagnostics values about lost, dropped, trimmed or unwritten messages
  and its log lines about them;
- rosbag record, rosbag record --lz4: messages per topic in their bags against those played.
Figures are printed, never judged: the exit status is non-zero only when the bench itself fails.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402
from heavy_workload import ODOM_RATE, START, Workload, describe_workload, workload_bag  # noqa: E402
from cost_live import cpu_of, memory_mb, roscore_session, train_model, wait_subscribers  # noqa: E402

PRE = POST = 2.0            # the node's _pre and _post, seconds
NODE = '/smart_logger'
ODOM = '/odom'              # the workload's odometry: the node's driving topic; with --wall-clock the played clock
SCENARIOS = ('one', 'tenth', 'all')
LOSS_WORDS = re.compile(r'lost|dropped|trimmed|unwritten|not written', re.I)
STATE = ('windows opened', 'windows saved', 'messages kept', 'messages buffered', 'writer queue', 'feeder CPU s',
         'writer CPU s')  # printed
NOT_LOSSES = {'messages not kept (outside every window)'}  # /diagnostics: let go as they should be


# -- the bench's own ROS node: clock, diagnostics, triggers -----------------------------------------------

class Ros(object):
    """The bench's rospy node: the played clock, the smart node's last diagnostics, its trigger services. The
    played clock is /clock, or with ``wall_clock`` the header stamp of the last odometry message played."""

    def __init__(self, wall_clock=False):
        import rospy
        from diagnostic_msgs.msg import DiagnosticArray
        rospy.init_node('cc_log_bench_heavy', disable_signals=True)
        self.reset()
        if wall_clock:
            rospy.Subscriber(ODOM, rospy.AnyMsg, self._on_odometry)
        else:
            from rosgraph_msgs.msg import Clock
            rospy.Subscriber('/clock', Clock, self._on_clock)
        rospy.Subscriber('/diagnostics', DiagnosticArray, self._on_diagnostics)

    def reset(self):
        self.clock, self.values, self.diagnostics_wall, self.level = None, {}, 0.0, None

    def _on_clock(self, msg):
        self.clock = msg.clock.to_sec()

    def _on_odometry(self, msg):
        from cc_log.base import raw_message
        self.clock = raw_message.stamp(msg._buff, msg._connection_header, self.clock or 0.0)

    def _on_diagnostics(self, array):
        for status in array.status:
            values = {kv.key: kv.value for kv in status.values}
            if 'messages seen' in values:
                self.values, self.level, self.diagnostics_wall = values, (status.level, status.message), time.time()

    def call(self, plan):
        """Call the trigger service of ``plan`` (a dict, updated with clock, ok, message) in a thread."""
        def call():
            import rospy
            from std_srvs.srv import Trigger
            plan['clock'] = self.clock
            try:
                if plan['service'] == 'trigger':
                    response = rospy.ServiceProxy(NODE + '/trigger', Trigger)()
                else:
                    response = rospy.ServiceProxy(NODE + '/trigger_window', trigger_window_class())(
                        plan['reason'], plan['before'], plan['after'])
                plan['ok'], plan['message'] = response.success, response.message
            except Exception as error:  # the service is gone or failed: reported in the run's figures
                plan['ok'], plan['message'] = False, '%s: %s' % (type(error).__name__, str(error)[:200])
        plan['thread'] = threading.Thread(target=call, daemon=True)
        plan['thread'].start()


def trigger_window_class():
    """cc_log/TriggerWindow, generated in the sourced workspace (common.py puts src/cc_log first on sys.path, so
    the generated ``cc_log.srv`` beside it is added to the package's path here)."""
    import cc_log
    for entry in sys.path:
        generated = os.path.join(entry, 'cc_log')
        if os.path.isdir(os.path.join(generated, 'srv')) and generated not in cc_log.__path__:
            cc_log.__path__.append(generated)
    from cc_log.srv import TriggerWindow
    return TriggerWindow


def wait_service(name, seconds=60.0):
    import rosgraph
    master = rosgraph.Master('/cc_log_bench')
    deadline = time.time() + seconds
    while time.time() < deadline:
        try:
            master.lookupService(name)
            return
        except Exception:
            time.sleep(0.2)
    raise RuntimeError('%s: no such service after %g s (did the node start? see its log)' % (name, seconds))


def trigger_plans(scenario, seconds):
    """The triggers of a scenario: dicts of at (bag seconds), service, reason, before, after."""
    if scenario == 'one':
        return [{'at': seconds / 2.0, 'service': 'trigger', 'reason': 'manual', 'before': PRE, 'after': POST}]
    if scenario == 'tenth':
        return [{'at': at, 'service': 'trigger_window', 'reason': 'bench_tenth', 'before': 1.5, 'after': 1.5}
                for at in range(15, int(seconds - 1.5), 30)] or \
            [{'at': seconds / 2.0, 'service': 'trigger_window', 'reason': 'bench_tenth', 'before': 1.5,
              'after': 1.5}]
    return [{'at': min(2.5, seconds / 4.0), 'service': 'trigger_window', 'reason': 'bench_all', 'before': PRE,
             'after': seconds + 10.0}]


# -- one run ------------------------------------------------------------------------------------------------

class Watch(object):
    """Samples, every call, each process's CPU and peak RSS, the window files and the played clock."""

    def __init__(self, pids, directory):
        self.pids, self.directory = pids, directory
        self.cpu = dict.fromkeys(pids, 0.0)
        self.peak = dict.fromkeys(pids, 0.0)
        self.seen = {}      # window file name -> wall time first listed
        self.clock = []     # (wall, played clock)
        self.temporary = []

    def sample(self, clock=None):
        for name, pid in self.pids.items():
            self.cpu[name] = max(self.cpu[name], cpu_of(pid))
            self.peak[name] = max(self.peak[name], memory_mb(pid))
        from cc_log.storage import log_format
        now = time.time()
        for path in log_format.window_files(self.directory):
            self.seen.setdefault(os.path.basename(path), now)
        self.temporary = log_format.temporary_files(self.directory)
        if clock is not None:
            self.clock.append((now, clock))


def sample_until(watch, ros, condition, seconds):
    deadline = time.time() + seconds
    while time.time() < deadline and not condition():
        watch.sample(ros.clock)
        time.sleep(0.1)
    return condition()


def signal_group(process, signum):
    try:
        os.killpg(process.pid, signum)
    except ProcessLookupError:
        pass


def stop_node(node, watch, ros, wait):
    """After its SIGINT: wait for the node to exit, SIGTERM it after ``wait`` s (as roslaunch would), SIGKILL 5 s
    later; return how it ended."""
    import signal
    if sample_until(watch, ros, lambda: node.poll() is not None, wait):
        return 'exit %s' % node.returncode
    signal_group(node, signal.SIGTERM)
    if sample_until(watch, ros, lambda: node.poll() is not None, 5.0):
        return 'exit %s on SIGTERM %g s after SIGINT' % (node.returncode, wait)
    signal_group(node, signal.SIGKILL)
    node.wait(10)
    return 'SIGKILL (no exit %g s after SIGINT nor 5 s after SIGTERM)' % wait


def run(procs, tmp, ros, workload, bag, model, scenario, fmt, args):
    """One scenario with one format: start, play, trigger, measure; return the figures (a dict)."""
    import signal
    work = os.path.join(tmp, '%s_%s' % (scenario, fmt))
    windows = os.path.join(work, 'windows')
    os.makedirs(windows)
    ros.reset()
    node = procs.start('node_%s_%s' % (scenario, fmt), [
        'rosrun', 'cc_log', 'smart_logger.py', '_model:=' + model, 'odom:=' + ODOM, '_directory:=' + windows,
        '_topics:=' + workload.node_topics(), '_pre:=%gs' % PRE, '_post:=%gs' % POST, '_format:=' + fmt]
        + args.node_param)
    bags = {'record': os.path.join(work, 'record.bag'), 'record_lz4': os.path.join(work, 'record_lz4.bag')}
    record = procs.start('record_%s_%s' % (scenario, fmt), ['rosbag', 'record', '-O', bags['record']] + workload.topics)
    record_lz4 = procs.start('record_lz4_%s_%s' % (scenario, fmt),
                             ['rosbag', 'record', '--lz4', '-O', bags['record_lz4']] + workload.topics)
    for topic in workload.topics:  # the node and both recorders (and on wall time the bench's clock on ODOM)
        wait_subscribers(topic, 4 if args.wall_clock and topic == ODOM else 3, 60.0)
    wait_service(NODE + '/trigger_window')
    watch = Watch({'node': node.pid, 'record': record.pid, 'record_lz4': record_lz4.pid}, windows)
    watch.sample()
    cpu0 = dict(watch.cpu)
    plans = trigger_plans(scenario, workload.seconds)
    play = procs.start('play_%s_%s' % (scenario, fmt), ['rosbag', 'play'] + ([] if args.wall_clock else ['--clock'])
                       + ['--wait-for-subscribers', '-q', bag])
    started = time.time()
    while play.poll() is None and time.time() < started + 3 * workload.seconds + 60:
        watch.sample(ros.clock)
        for plan in plans:
            if 'thread' not in plan and ros.clock is not None and ros.clock >= START + plan['at']:
                ros.call(plan)
        time.sleep(0.1)
    if play.poll() is None:
        raise RuntimeError('rosbag play did not end within %g s' % (3 * workload.seconds + 60))
    played = time.time()
    sample_until(watch, ros, lambda: False, 1.0)
    result = {'scenario': scenario, 'format': fmt, 'play_seconds': played - started, 'plans': plans,
              'cpu_play': {name: watch.cpu[name] - cpu0[name] for name in watch.cpu}}
    for plan in plans:
        if 'thread' in plan:
            plan['thread'].join(30.0)
    sample_until(watch, ros, lambda: False, 1.0)
    for process in (record, record_lz4):
        procs.stop(process)
    if scenario != 'all':  # scenario all: its window ends only when the node is stopped

        def complete():
            quiet = not watch.seen or time.time() - max(watch.seen.values()) >= 2.0
            return (quiet and not watch.temporary and ros.diagnostics_wall > played + 1.0
                    and ros.values.get('writer queue') == '0')
        result['complete'] = sample_until(watch, ros, complete, args.wait)
    result['shutdown_wall'] = time.time()
    signal_group(node, signal.SIGINT)
    result['node_exit'] = stop_node(node, watch, ros, args.wait)
    watch.sample()
    result['done_wall'] = time.time()
    result['cpu_after'] = watch.cpu['node'] - cpu0['node'] - result['cpu_play']['node']
    result['peak'] = dict(watch.peak)
    result['diagnostics'] = dict(ros.values)
    result['level'] = ros.level
    result['log'] = loss_lines(os.path.join(tmp, 'node_%s_%s.log' % (scenario, fmt)))
    result['files'] = count_windows(windows)
    result['leftovers'] = len(watch.temporary)
    result['bags'] = {name: bag_counts(path) for name, path in bags.items()}
    result['seen'], result['clock'] = watch.seen, watch.clock
    shutil.rmtree(work, ignore_errors=True)  # the recorders' bags are large
    return result


def loss_lines(path, limit=3):
    """The node log's last lines that speak of lost, dropped or unwritten messages (truncated)."""
    try:
        with open(path, errors='replace') as stream:
            lines = [line.strip()[:200] for line in stream if LOSS_WORDS.search(line)]
    except OSError:
        return []
    return lines[-limit:]


def count_windows(directory):
    """[{name, counts {topic: records}, triggers [(reason, stamp)], error}] of the window files."""
    from cc_log.storage import log_format
    files = []
    for path in log_format.window_files(directory):
        entry = {'name': os.path.basename(path), 'counts': {}, 'triggers': [], 'error': None}
        try:
            meta, records = log_format.read_window(path)
            for record in records:
                entry['counts'][record.topic] = entry['counts'].get(record.topic, 0) + 1
            entry['triggers'] = [(t.get('reason'), t.get('stamp')) for t in meta.get('triggers', [])]
            del records
        except (ValueError, MemoryError) as error:
            entry['error'] = str(error)[:200]
        files.append(entry)
    return files


def bag_counts(path):
    """{topic: messages} of a bag written by rosbag record (None when it could not be read)."""
    import rosbag
    try:
        with rosbag.Bag(path) as bag:
            return {topic: info.message_count for topic, info in bag.get_type_and_topic_info().topics.items()}
    except Exception as error:  # rosbag raises many kinds: the figure is then n/a, with the reason
        print('%s: cannot read (%s: %s)' % (path, type(error).__name__, str(error)[:200]))
        return None


# -- figures ----------------------------------------------------------------------------------------------

def expected_counts(result, info, topics):
    """{topic: messages of the workload inside the windows' spans}, [(start, end)] of the windows asked for."""
    spans = []
    stamps_in_files = [stamp for entry in result['files'] for _, stamp in entry['triggers']]
    for plan in result['plans']:
        if plan.get('ok') is False or plan.get('clock') is None:
            continue
        reason_stamps = [stamp for entry in result['files'] for reason, stamp in entry['triggers']
                         if reason == plan['reason'] and stamp is not None]
        near = [s for s in reason_stamps if abs(s - plan['clock']) < 5.0] or \
            [s for s in stamps_in_files if abs(s - plan['clock']) < 1.0]
        stamp = near[0] if near else plan['clock']
        spans.append((stamp - plan['before'], stamp + plan['after']))
    counts = {topic: sum(1 for t in info['stamps'][topic] if any(a <= t <= b for a, b in spans)) for topic in topics}
    return counts, spans


def to_disk(result, spans):
    """Seconds from the last window's end (wall time the played clock passed it; the node's SIGINT when it
    never did) to the first sight of the last window file; '*' when that came at shutdown, '>N' for none."""
    stop = result['shutdown_wall']
    end = max((b for _, b in spans), default=None)
    end_wall = next((wall for wall, clock in result['clock'] if end is not None and clock >= end), stop)
    if not result['seen']:
        return '>%.0f' % (result['done_wall'] - end_wall)
    last = max(result['seen'].values())
    return '%.1f%s' % (last - end_wall, '*' if last >= stop else '')


def short(topic):
    return topic.strip('/').split('/')[0]


def rows_of(result, info, workload):
    expected, spans = expected_counts(result, info, workload.topics)
    kept = {topic: sum(entry['counts'].get(topic, 0) for entry in result['files']) for topic in workload.topics}
    seconds = result['play_seconds']
    cpu = {name: result['cpu_play'][name] for name in ('node', 'record', 'record_lz4')}
    images = sum(kept[t] for t in workload.camera_topics), sum(expected[t] for t in workload.camera_topics)
    missing = ', '.join('%s %d' % (short(t), expected[t] - kept[t]) for t in workload.topics)
    says = '; '.join('%s %s' % (key, value) for key, value in sorted(result['diagnostics'].items())
                     if LOSS_WORDS.search(key) and key not in NOT_LOSSES and value not in ('0', '0.0', '')) or 'none'
    errors = [entry['error'] for entry in result['files'] if entry['error']]
    failed = [p['message'] for p in result['plans'] if p.get('ok') is False]
    main = [result['scenario'], result['format'],
            '%.2f' % (cpu['node'] / cpu['record']) if cpu['record'] else 'n/a',
            '%.2f' % (cpu['node'] / cpu['record_lz4']) if cpu['record_lz4'] else 'n/a',
            '%.0f / %.0f / %.0f' % tuple(100 * cpu[k] / seconds for k in ('node', 'record', 'record_lz4')),
            '%.1f' % result['cpu_after'],
            '%.0f / %.0f / %.0f' % tuple(result['peak'][k] for k in ('node', 'record', 'record_lz4')),
            '%d / %d' % images, '%d / %d' % (len(result['files']), len(spans)), missing, says, to_disk(result, spans)]
    detail = []
    for topic in workload.topics:
        played = len(info['stamps'][topic])
        recorded = ['%d' % (counts or {}).get(topic, 0) if counts is not None else 'n/a'
                    for counts in (result['bags']['record'], result['bags']['record_lz4'])]
        detail.append([result['scenario'], result['format'], topic, played] + recorded
                      + ['%d / %d' % (kept[topic], expected[topic])])
    notes = ['%s %s: %s' % (result['scenario'], result['format'], text) for text in
             ['node %s; unfinished *.tmp-* files %d; its last /diagnostics: level %s, %s' % (
                 result['node_exit'], result['leftovers'], *(result['level'] or ('none', 'no diagnostics received')))
              + ''.join('; %s %s' % (key, result['diagnostics'][key]) for key in STATE if key in result['diagnostics'])]
             + ['node log: ' + line for line in result['log']]
             + ['unreadable window file: ' + e for e in errors] + ['trigger failed: ' + m for m in failed]]
    return main, detail, notes


MAIN_HEADERS = ['scenario', 'format', 'node / record CPU', 'node / record --lz4 CPU',
                'CPU % node / record / --lz4', 'node CPU s after play', 'peak RSS MB node / record / --lz4',
                'images kept / expected', 'files / windows', 'missing per topic (counted)', 'node says lost',
                's window end to disk']
DETAIL_HEADERS = ['scenario', 'format', 'topic', 'played', 'rosbag record', 'rosbag record --lz4',
                  'node kept / expected']

QUICK = {'seconds': 6.0, 'scenarios': 'one', 'format': ['bag-lz4'], 'wait': 30.0}


def parse(argv):
    from cc_log.storage import log_format
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rate', type=float, choices=(37.0, 100.0), default=None,
                        help='MB/s of the workload: 37 (one camera, the default) or 100 (two cameras, denser lidar)')
    parser.add_argument('--cameras', type=int, choices=(1, 2), default=None, help='cameras (2 = --rate 100)')
    parser.add_argument('--seconds', type=float, default=30.0, help='length of the workload bag (default 30)')
    parser.add_argument('--scenarios', default=','.join(SCENARIOS),
                        help='comma-separated, of: %s (default all three)' % ', '.join(SCENARIOS))
    formats = list(log_format.Format.ALL)
    parser.add_argument('--format', nargs='+', choices=formats, default=formats,
                        help='window formats, one run each (default every format: %s)' % ' '.join(formats))
    parser.add_argument('--wait', type=float, default=65.0,
                        help='at most this many seconds for the windows after the play, and again for the node to '
                        'exit after SIGINT (then SIGTERM, as roslaunch, and SIGKILL 5 s later); default 65')
    parser.add_argument('--out', default='/tmp/cc_log_heavy', help='where the workload bag and model are cached')
    parser.add_argument('--node-param', action='append', default=[], metavar='_NAME:=VALUE',
                        help='another parameter of the node, e.g. _max_buffer_mb:=512 (repeatable)')
    parser.add_argument('--wall-clock', action='store_true',
                        help='run on wall time as a robot does: /use_sim_time false for every process, rosbag play '
                        'without --clock, the bench\'s plan on the played odometry\'s header stamps (default: '
                        '/use_sim_time true and rosbag play --clock)')
    parser.add_argument('--quick', dest='preset', action='store_const', const=QUICK, default={},
                        help='6 s, one window, bag-lz4')
    args = parser.parse_args(argv)
    vars(args).update(args.preset)
    if args.cameras is None:
        args.cameras = 2 if args.rate == 100.0 else 1
    args.scenarios = [s.strip() for s in args.scenarios.split(',') if s.strip()]
    unknown = [s for s in args.scenarios if s not in SCENARIOS]
    if unknown or not args.scenarios:
        parser.error('--scenarios: %r: expected some of %s' % (','.join(unknown)[:60], ', '.join(SCENARIOS)))
    if not 2.0 <= args.seconds <= 600.0:
        parser.error('--seconds: %g is out of range [2, 600]' % args.seconds)
    return args


def never_firing_model(path):
    """cost_live's motion model for 100 Hz odometry with a threshold no score goes below: it never fires."""
    from cc_log.learning.model import AnomalyModel
    if not os.path.exists(path):
        train_model(path + '.trained', ODOM_RATE, minutes=1.0)
        model = AnomalyModel.load(path + '.trained')
        model.threshold = -1e9
        model.save(path)
    return path


def main(argv=None):
    started = time.time()
    args = parse(argv)
    try:
        os.makedirs(args.out, exist_ok=True)
    except OSError as error:
        print('--out %s: %s' % (args.out, error.strerror or error), file=sys.stderr)
        return 1
    workload = Workload(args.cameras, args.seconds)
    bag, info = workload_bag(workload, args.out)
    model = never_firing_model(os.path.join(args.out, 'motion_never_fires.json'))
    package = subprocess.run(['rospack', 'find', 'cc_log'], stdout=subprocess.PIPE, universal_newlines=True)
    common.header('Heavy sensors: the smart node beside rosbag record and rosbag record --lz4', describe_workload(
        workload, info) + [
        common.describe_data(bag, '(uncompressed chunks)'),
        'date: %s; code: %s; node: rosrun cc_log smart_logger.py from %s' % (
            time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime()), common.revision(), package.stdout.strip() or '?'),
        'runs: scenarios %s x formats %s; node _pre:=%gs _post:=%gs%s, motion model that never fires'
        % (', '.join(args.scenarios), ', '.join(args.format), PRE, POST, ''.join(' ' + p for p in args.node_param)),
        'clock: %s' % ('wall time (/use_sim_time false, rosbag play without --clock; the played clock: %s header '
                       'stamps)' % ODOM if args.wall_clock else 'simulated (/use_sim_time true, rosbag play --clock)')])
    results = []
    with roscore_session('cc_log_bench_heavy_') as (procs, tmp):
        import rosgraph
        rosgraph.Master('/cc_log_bench').setParam('/use_sim_time', not args.wall_clock)
        os.environ.update({key: value for key, value in procs.env.items() if key.startswith('ROS_')})
        trigger_window_class()  # fails here, before any run, without a sourced workspace
        ros = Ros(args.wall_clock)
        for scenario in args.scenarios:
            for fmt in args.format:
                print('run: %s, %s ...' % (scenario, fmt))
                sys.stdout.flush()
                results.append(run(procs, tmp, ros, workload, bag, model, scenario, fmt, args))
        import rospy
        rospy.signal_shutdown('bench done')
    mains, details, notes = [], [], []
    for result in results:
        main_row, detail, note = rows_of(result, info, workload)
        mains.append(main_row)
        details += detail
        notes += note
    print()
    rate = sum(info['bytes'].values()) / workload.seconds / 1e6
    common.table(MAIN_HEADERS, mains, 'Smart node vs rosbag record in the same run (%d camera(s), %.0f MB/s, %g s; '
                 'CPU over the play; *: written at shutdown):' % (workload.cameras, rate, workload.seconds))
    common.table(DETAIL_HEADERS, details, 'Messages per topic: played, in the recorders\' bags, in the node\'s '
                 'window files against those in the windows\' spans:')
    for line in notes:
        print(line)
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
