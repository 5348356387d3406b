"""The one-command demo: collect, learn, then the smart logger live on a simulated BWIBot.

``rosrun cc_log demo.py`` (or ``./dev.sh demo`` on a fresh machine):

1. simulates a nominal run of the BWIBot (no roscore) and collects its feature vectors, as collect mode;
2. learns a model from them, as learn mode;
3. starts a roscore and ``demo.launch`` (simulator with injected anomalies, its planner's ``cmd_vel``, a
   move_base-like goal status, a 15 Hz camera and a 10 Hz laser scan + the smart logger with a configuration:
   the motion classifier and a rule on aborted goals, ``DEMO_CONFIG``; it keeps IMU, camera and scan in its
   windows), live;
4. prints what was injected and the share of each anomaly's span kept (and by which trigger), the camera frames
   and scans kept around each, false windows, whether the demo passed (``score``), messages seen vs kept, raw vs
   stored bytes, and writes a PNG timeline.

Everything it starts is stopped when it ends, whatever way it ends.
"""
import argparse
import collections
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time

from cc_log.logger import collector
from cc_log.learning import learning
from cc_log.storage import log_format
from cc_log.base import msg_codec, safe_files
from cc_log.storage.directory import cc_log_home
from cc_log import sim

DEFAULT_OUT = 'demo'  # in cc_log's directory of ROS's home: directory.cc_log_home
DEFAULT_TRAIN_MINUTES = 8.0
DEFAULT_LIVE_MINUTES = 2.5
DEFAULT_ANOMALIES = 6
DEFAULT_SEED = 7
DEFAULT_WINDOW = '1s'     # bench/detection_sim_tuning.py: fewest false windows, smallest windows (tail <= 1 s)
DEFAULT_STRIDE = '10'
#: The demo passes when every event has at least this fraction of its span [start, end) in saved windows and no
#: window is false (overlaps no event).
MIN_COVERAGE = 0.95
MASTER_TIMEOUT = 30.0
#: A directory holding this file was made by the demo.
MARKER = '.cc_log_demo'
#: Everything the demo writes in its directory (``train`` removes the bag and its truth file again).
OUTPUTS = ('nominal.bag', sim.truth_path('nominal.bag'), 'features', 'model.json', 'windows', 'truth.json',
           'ros_log', 'roscore.log', 'roslaunch.log', 'timeline.png', 'demo.yaml')


def log(text):
    """A progress line on stderr."""
    sys.stderr.write('[demo] %s\n' % text)
    sys.stderr.flush()


def free_port():
    """A TCP port nobody listens on (for the demo's own roscore)."""
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


class Processes(object):
    """Child processes in their own process groups, all stopped on exit."""

    def __init__(self):
        self.children = []

    def start(self, args, env, log_path):
        stream = os.fdopen(safe_files.create(log_path), 'wb')
        child = subprocess.Popen(args, env=env, stdout=stream, stderr=subprocess.STDOUT,
                                 stdin=subprocess.DEVNULL, start_new_session=True)
        self.children.append((child, stream))
        return child

    def stop(self):
        for child, _ in reversed(self.children):
            if child.poll() is None:
                os.killpg(child.pid, signal.SIGINT)
        deadline = time.time() + 20.0
        for child, stream in reversed(self.children):
            try:
                child.wait(max(0.1, deadline - time.time()))
            except subprocess.TimeoutExpired:
                os.killpg(child.pid, signal.SIGKILL)
                child.wait()
            stream.close()
        self.children = []


def prepare_out(out):
    """Make ``out`` the demo's directory without deleting anything the demo did not create.

    A new or empty directory is created and marked as the demo's (``MARKER``); in one the demo marked before,
    the demo's own outputs (``OUTPUTS``) are removed and nothing else; any other directory is refused with a
    ValueError naming it, untouched."""
    try:
        safe_files.make_dirs(out)
        entries = os.listdir(out)
    except OSError as error:
        raise ValueError('--out %s: %s' % (out, error.strerror or error))
    if entries and MARKER not in entries:
        raise ValueError('--out %s: not empty and not made by the demo (no %s in it): give a new or empty '
                         'directory' % (out, MARKER))
    for name in OUTPUTS:
        path = os.path.join(out, name)
        if os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path)
        elif os.path.lexists(path):
            os.remove(path)
    if MARKER not in entries:  # created, never written through a link or over a file
        with os.fdopen(safe_files.create(os.path.join(out, MARKER)), 'w') as marker:
            marker.write('made by the cc_log demo; running it again here replaces: %s\n' % ', '.join(OUTPUTS))


def train(out, minutes, seed, window, stride):
    """Steps 1 and 2: a nominal simulated run, its feature vectors, a model. Returns the model path."""
    bag = os.path.join(out, 'nominal.bag')
    log('1/4 simulating %.0f minutes of nominal driving (no roscore) -> %s' % (minutes, bag))
    sim.simulate_to_bag(bag, sim.SimConfig(minutes=minutes, anomalies=0, seed=seed))
    features = os.path.join(out, 'features')
    log('2/4 collect: feature vectors (window %s, one every %s messages) -> %s/nominal/' % (window, stride, features))
    collected = collector.collect_bag(bag, sim.ODOM_TOPIC, features, window=window, stride=stride)
    log('    %d vectors' % collected['vectors'])
    vectors, config = learning.load_vectors(features)
    log('3/4 learn: one-class SVM on %d nominal vectors' % len(vectors['nominal']))
    model, info = learning.train(vectors['nominal'], None, config)
    path = os.path.join(out, 'model.json')
    model.save(path)
    figures = ', '.join('%s %s' % item for item in sorted(info.items()) if isinstance(item[1], (int, float, str)))
    log('    model -> %s (%s)' % (path, figures[:200]))
    os.remove(bag)
    os.remove(sim.truth_path(bag))
    return path


class LiveRecorder(object):
    """The demo's own ROS node: what the robot published (for the byte count and the plot)."""

    def __init__(self):
        import rospy
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import Image, Imu, LaserScan
        self.lock = threading.Lock()
        self.messages = 0
        self.raw_bytes = 0
        self.track = []  # (stamp, speed, yaw rate)
        rospy.init_node('cc_log_demo', anonymous=True, disable_signals=True)
        self.subscribers = [rospy.Subscriber('odom', Odometry, self._odom, queue_size=1000),
                            rospy.Subscriber('imu/data', Imu, self._count, queue_size=1000),
                            rospy.Subscriber('camera/image_raw', Image, self._count, queue_size=30),
                            rospy.Subscriber('scan', LaserScan, self._count, queue_size=30)]

    def _count(self, msg):
        with self.lock:
            self.messages += 1
            self.raw_bytes += msg_codec.row_json_bytes(msg)

    def _odom(self, msg):
        self._count(msg)
        with self.lock:
            self.track.append((msg.header.stamp.to_sec(), msg.twist.twist.linear.x, msg.twist.twist.angular.z))


DEMO_CONFIG = """# written by demo.py: the demo's smart logger (demo.launch sets the topics to keep)
# windows.pre is the most the logger holds before a trigger (the goal abort's); the classifier keeps less.
windows: {pre: 10s, post: %(post)s}
triggers:
  - {name: classifier, kind: classifier, model: '%(model)s', topics: [odom], retrigger: event, pre: 2s}
  # the failure happened before the abort: keep the 10 s before it
  - {name: goal_aborted, kind: rule, topic: move_base/status, type: actionlib_msgs/GoalStatusArray,
     when: 'status_list[0].status == 4', pre: 10s, post: 1s}
"""
#: Kept after the classifier's last fire. A collision is flagged for its first few tenths of a second; the
#: standstill after it (up to 6 s in all) looks nominal, so post must reach its end (bench/detection_sim_tuning.py
#: --config demo: 5 s kept 92-94 % of 5.7 s collisions, 6 s all of them).
DEMO_POST = '6s'


def config_text(model, post=DEMO_POST):
    """The smart logger's configuration of the demo (DEMO_CONFIG) with the model file ``model``."""
    return DEMO_CONFIG % {'model': model.replace("'", "''"), 'post': post}


def write_config(out, model):
    """The smart logger's configuration file (``config_text``); returns its path."""
    path = os.path.join(out, 'demo.yaml')
    with safe_files.AtomicFile(path, overwrite=True, text=True) as stream:
        stream.write(config_text(model))
    return path


def run_live(out, model, minutes, anomalies, seed, processes):
    """Step 3: roscore + demo.launch until the simulator finishes. Returns (windows dir, truth, recorder)."""
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI='http://127.0.0.1:%d' % port, ROS_HOSTNAME='127.0.0.1',
               ROS_LOG_DIR=os.path.join(out, 'ros_log'))
    os.environ.update(ROS_MASTER_URI=env['ROS_MASTER_URI'], ROS_HOSTNAME='127.0.0.1')
    log('4/4 live: roscore on port %d, simulator (%.1f min, %d anomalies) + smart logger' % (port, minutes, anomalies))
    processes.start(['roscore', '-p', str(port)], env, os.path.join(out, 'roscore.log'))
    wait_for_master(env['ROS_MASTER_URI'])
    recorder = LiveRecorder()
    windows = os.path.join(out, 'windows')
    truth_file = os.path.join(out, 'truth.json')
    launch = processes.start(
        ['roslaunch', 'cc_log', 'demo.launch', 'model:=%s' % model, 'config:=%s' % write_config(out, model),
         'directory:=%s' % windows,
         'minutes:=%g' % minutes, 'anomalies:=%d' % anomalies, 'seed:=%d' % seed, 'truth_file:=%s' % truth_file],
        env, os.path.join(out, 'roslaunch.log'))
    started = time.time()
    total = minutes * 60.0
    while launch.poll() is None:
        time.sleep(1.0)
        elapsed = time.time() - started
        if int(elapsed) % 15 == 0:
            saved = len(log_format.window_files(windows)) if os.path.isdir(windows) else 0
            log('    %3.0f / %.0f s simulated, %d messages seen, %d windows saved'
                % (min(elapsed, total), total, recorder.messages, saved))
        if elapsed > total + 90.0:
            raise RuntimeError('demo.launch did not finish %.0f s after the simulated run' % (elapsed - total))
    if launch.returncode != 0 or not os.path.exists(truth_file):
        raise RuntimeError('demo.launch failed (exit %d, no ground truth written): see %s'
                           % (launch.returncode, os.path.join(out, 'roslaunch.log')))
    return windows, sim.load_truth(truth_file), recorder


def wait_for_master(uri):
    import rosgraph
    master = rosgraph.Master('/cc_log_demo', master_uri=uri)
    deadline = time.time() + MASTER_TIMEOUT
    while time.time() < deadline:
        try:
            master.getPid()
            return
        except Exception:  # noqa: BLE001 (any connection error means: not up yet)
            time.sleep(0.3)
    raise RuntimeError('roscore did not come up within %.0f s' % MASTER_TIMEOUT)


def coverage(event, windows):
    """The fraction of ``event``'s span [start, end) inside the union of the ``windows``' spans [start, end]
    (0.0 to 1.0; an event of no length: 1.0 when a window holds its start)."""
    start, end = event['start'], event['end']
    if end <= start:
        return 1.0 if any(w['start'] <= start <= w['end'] for w in windows) else 0.0
    covered, reached = 0.0, start
    for low, high in sorted((max(start, w['start']), min(end, w['end'])) for w in windows):
        low = max(low, reached)
        if high > low:
            covered += high - low
            reached = high
    return covered / (end - start)


def score(windows, truth, min_coverage=MIN_COVERAGE):
    """The demo's verdict on the saved ``windows`` ({start, end, names}) against the ``truth`` ({type, start,
    end}): ``(events, false_windows, passed)``. ``events``: per true event, in order, ``(event, coverage,
    names of the triggers of the windows overlapping it)``; a false window overlaps no event; ``passed``:
    every event has at least ``min_coverage`` of its span kept and no window is false."""
    events = []
    for event in truth:
        names = set()
        for window in windows:
            if overlaps(window, event):
                names.update(window.get('names', ()))
        events.append((event, coverage(event, windows), names))
    false_windows = [w for w in windows if not any(overlaps(w, event) for event in truth)]
    passed = not false_windows and all(kept >= min_coverage for _, kept, _ in events)
    return events, false_windows, passed


def overlaps(window, event):
    """Whether a window [start, end] holds any of an event's span [start, end)."""
    return window['start'] < event['end'] and window['end'] >= event['start']


def read_windows(windows_dir):
    """The window files of ``windows_dir`` (any format, read by ``log_format.read_window``): dicts of path,
    start, end, count, bytes, names, and ``frames`` / ``scans``: how many camera images and laser scans it holds."""
    windows = []
    for path in log_format.window_files(windows_dir):
        meta, records = log_format.read_window(path)
        topics = collections.Counter(record.topic for record in records)
        windows.append({'path': path, 'start': meta['start'], 'end': meta['end'], 'count': meta['count'],
                        'bytes': os.path.getsize(path), 'names': meta.get('names', []),
                        'frames': topics[sim.CAMERA_TOPIC], 'scans': topics[sim.SCAN_TOPIC]})
    return windows


def kept_around(windows, truth):
    """``[(event, camera frames, scans)]``: what the windows overlapping each true anomaly (``overlaps``) hold."""
    kept = []
    for event in truth:
        near = [window for window in windows if overlaps(window, event)]
        kept.append((event, sum(w['frames'] for w in near), sum(w['scans'] for w in near)))
    return kept


def summarize(out, windows_dir, truth, recorder):
    """Print the summary and write the PNG; return whether the demo passed (``score``)."""
    windows = read_windows(windows_dir)
    events, false_windows, passed = score(windows, truth)
    stored = sum(window['bytes'] for window in windows)
    kept = sum(window['count'] for window in windows)
    start = min([event['start'] for event in truth] + [w['start'] for w in windows] or [0.0])
    lines = ['', 'cc_log demo: smart logger on a simulated BWIBot (100 Hz odometry + IMU, cmd_vel, goal status, '
             '15 Hz camera, 10 Hz scan)',
             '  anomalies injected, with the share of each one\'s span kept in windows (and by which triggers):']
    for event, share, names in events:
        by = '  (%s)' % ', '.join(sorted(names)) if names else '  missed'
        lines.append('    %-22s at %6.1f s, %4.1f s long: %5.1f%% kept%s' % (
            event['type'], event['start'] - start, event['end'] - event['start'], 100.0 * share, by))
    lines.append('    %-22s %d / %d caught, %d / %d with >= %.0f%% of the span kept' % (
        'all', sum(1 for _, share, _ in events if share > 0), len(events),
        sum(1 for _, share, _ in events if share >= MIN_COVERAGE), len(events), 100.0 * MIN_COVERAGE))
    lines.append('  false windows:          %d (windows overlapping no anomaly)' % len(false_windows))
    lines.append('  kept around each event: camera frames (320x240), laser scans')
    for event, frames, scans in kept_around(windows, truth):
        lines.append('    %-22s at %6.1f s  %4d frames, %4d scans' % (event['type'], event['start'] - start, frames,
                                                                      scans))
    lines.append('    %-22s             %4d frames, %4d scans' % (
        'in all windows', sum(w['frames'] for w in windows), sum(w['scans'] for w in windows)))
    lines.append('  result:                 %s' % ('PASS' if passed else 'FAIL (the demo passes with every anomaly '
                                                   '>= %.0f%% kept and no false window)' % (100.0 * MIN_COVERAGE)))
    share = 100.0 * kept / max(recorder.messages, 1)
    lines.append('  messages seen / kept:   %d / %d (%.1f%%)' % (recorder.messages, kept, share))
    lines.append('  raw row JSON / stored:  %s / %s  (%.0fx less)' % (
        human(recorder.raw_bytes), human(stored), recorder.raw_bytes / max(stored, 1)))
    lines.append('  windows (%d) in:         %s' % (len(windows), windows_dir))
    if windows:
        lines.append('  look at one:            rosrun cc_log cclog info %s' % windows[0]['path'])
        lines.append('                          %s' % (
            'rqt_bag %s' % windows[0]['path'] if windows[0]['path'].endswith('.bag')
            else 'rosrun cc_log cclog cat %s | head' % windows[0]['path']))
        lines.append('                          rosrun cc_log cclog export %s --to png --out %s' % (
            windows_dir, os.path.join(out, 'frames')))
    png = os.path.join(out, 'timeline.png')
    plot(png, recorder.track, truth, windows)
    lines.append('  timeline:               %s' % png)
    print('\n'.join(lines))
    return passed


def human(size):
    for unit in ('B', 'KB', 'MB', 'GB'):
        if size < 1000 or unit == 'GB':
            return '%.1f %s' % (size, unit) if unit != 'B' else '%d B' % size
        size /= 1000.0


def plot(png, track, truth, windows):
    """Speed and yaw rate over time, true anomalies shaded red, saved windows marked green."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    if not track:
        return
    t0 = track[0][0]
    figure, axes = plt.subplots(2, 1, sharex=True, figsize=(12, 5))
    for axis, column, label in ((axes[0], 1, 'speed (m/s)'), (axes[1], 2, 'yaw rate (rad/s)')):
        axis.plot([row[0] - t0 for row in track], [row[column] for row in track], lw=0.6, color='k')
        axis.set_ylabel(label)
        for event in truth:
            axis.axvspan(event['start'] - t0, event['end'] - t0, color='red', alpha=0.25)
        for window in windows:
            axis.axvspan(window['start'] - t0, window['end'] - t0, ymin=0.0, ymax=0.08, color='green', alpha=0.8)
    for event in truth:
        axes[0].annotate(event['type'], (event['start'] - t0, axes[0].get_ylim()[1]), fontsize=7, rotation=20,
                         va='top')
    axes[1].set_xlabel('time (s); red: injected anomalies, green bars: windows cc_log saved')
    figure.tight_layout()
    with safe_files.AtomicFile(png, overwrite=True) as stream:
        figure.savefig(stream, dpi=100, format='png')
    plt.close(figure)


def main(argv=None):
    parser = argparse.ArgumentParser(
        prog='demo.py', description=__doc__.split('\n\n')[0],
        epilog='example: rosrun cc_log demo.py --out /tmp/cc_log_demo --live-minutes 2')
    parser.add_argument('--out', default=cc_log_home(DEFAULT_OUT),
                        help='a new or empty directory, or one an earlier demo made (its outputs are replaced, '
                             'nothing else is touched; default: %(default)s)')
    parser.add_argument('--train-minutes', type=float, default=DEFAULT_TRAIN_MINUTES)
    parser.add_argument('--live-minutes', type=float, default=DEFAULT_LIVE_MINUTES)
    parser.add_argument('--anomalies', type=int, default=DEFAULT_ANOMALIES)
    parser.add_argument('--seed', type=int, default=DEFAULT_SEED)
    args = parser.parse_args(argv)
    out = os.path.abspath(args.out)
    processes = Processes()
    started = time.time()
    try:
        prepare_out(out)
        model = train(out, args.train_minutes, args.seed, DEFAULT_WINDOW, DEFAULT_STRIDE)
        windows, truth, recorder = run_live(out, model, args.live_minutes, args.anomalies, args.seed + 1, processes)
        passed = summarize(out, windows, truth, recorder)
    except (RuntimeError, ValueError, OSError) as error:
        sys.stderr.write('demo: %s\n' % error)
        return 1
    except KeyboardInterrupt:
        sys.stderr.write('demo: interrupted\n')
        return 130
    finally:
        try:
            import rospy
            rospy.signal_shutdown('demo finished')
        except ImportError:
            pass
        processes.stop()
    log('done in %.0f s' % (time.time() - started))
    return 0 if passed else 1
