"""demo.py --out DIR never deletes anything it did not create (a robot's ~/.ros/cc_log stays as it is)."""
import os
import subprocess
import sys

from cc_log import demo

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))


def tree(top):
    """{relative path: file bytes or 'dir' or 'link -> target'} of everything below top."""
    found = {}
    for directory, dirs, files in os.walk(str(top)):
        for name in dirs + files:
            path = os.path.join(directory, name)
            key = os.path.relpath(path, str(top))
            if os.path.islink(path):
                found[key] = 'link -> %s' % os.readlink(path)
            elif os.path.isdir(path):
                found[key] = 'dir'
            else:
                with open(path, 'rb') as stream:
                    found[key] = stream.read()
    return found


def robot_directory(top):
    """What a robot's logging directory holds: windows, feature vectors (collect mode), a model."""
    (top / 'features' / 'nominal').mkdir(parents=True)
    (top / 'features' / 'nominal' / '1432235498.000000.json').write_text('{"vector": [1.0]}')
    (top / 'cc_log_20150521T191138.027Z_classifier.json.xz').write_bytes(b'\xfd7zXZ\x00window')
    (top / 'model.json').write_text('{"format": 1}')
    (top / 'windows').mkdir()
    (top / 'windows' / 'cc_log_20150521T191200.000Z_manual.bag').write_bytes(b'#ROSBAG V2.0\n')
    return top


def run_demo(out):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.path.join(ROOT, 'src'), os.environ.get('PYTHONPATH', '')]))
    return subprocess.run([sys.executable, os.path.join(ROOT, 'scripts', 'demo.py'), '--out', str(out)], env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, timeout=120)


def test_a_directory_the_demo_did_not_make_is_refused_untouched(tmp_path):
    robot = robot_directory(tmp_path / 'cc_log')
    before = tree(robot)
    result = run_demo(robot)
    assert result.returncode == 1
    assert result.stderr.strip().splitlines() == [
        'demo: --out %s: not empty and not made by the demo (no .cc_log_demo in it): give a new or empty directory'
        % robot]
    assert tree(robot) == before


def test_a_new_or_empty_directory_is_made_the_demos(tmp_path):
    for out in (tmp_path / 'new' / 'demo', tmp_path / 'empty'):
        if out.name == 'empty':
            out.mkdir()
        demo.prepare_out(str(out))
        assert sorted(os.listdir(str(out))) == [demo.MARKER]


def test_a_directory_of_an_earlier_demo_loses_only_the_demos_outputs(tmp_path):
    out = tmp_path / 'demo'
    demo.prepare_out(str(out))
    for name in ('windows', 'features', 'ros_log'):
        (out / name / 'sub').mkdir(parents=True)
        (out / name / 'sub' / 'file').write_text('demo output')
    for name in ('model.json', 'truth.json', 'roscore.log', 'roslaunch.log', 'timeline.png', 'nominal.bag'):
        (out / name).write_text('demo output')
    (out / 'notes.txt').write_text('mine')
    (out / 'kept').mkdir()
    (out / 'kept' / 'model.json').write_text('mine too')
    elsewhere = robot_directory(tmp_path / 'robot')
    before = tree(elsewhere)
    (out / 'windows').rename(out / 'old_windows')
    (out / 'windows').symlink_to(elsewhere)  # a link at an output name: the link goes, never what it points to

    demo.prepare_out(str(out))

    assert tree(out) == {demo.MARKER: (out / demo.MARKER).read_bytes(), 'notes.txt': b'mine', 'kept': 'dir',
                         'kept/model.json': b'mine too', 'old_windows': 'dir', 'old_windows/sub': 'dir',
                         'old_windows/sub/file': b'demo output'}
    assert tree(elsewhere) == before


def test_an_unusable_out_is_one_line(tmp_path):
    blocker = tmp_path / 'file'
    blocker.write_text('x')
    result = run_demo(blocker / 'demo')
    assert result.returncode == 1 and result.stderr.strip().count('\n') == 0
    assert result.stderr.startswith('demo: --out %s: ' % (blocker / 'demo'))
    assert blocker.read_text() == 'x'


def test_the_summary_counts_the_frames_and_scans_kept_around_each_event_in_either_format(tmp_path):
    from cc_log import log_format, sim
    from cc_log.window_buffer import LogWindow, Record
    simulator = sim.Simulator(sim.SimConfig(minutes=4.0 / 60, anomalies=0, camera=True, scan=True))
    records = [Record(stamp, topic, msg) for topic, stamp, msg in simulator.messages()]
    first, second = records[:len(records) // 3], records[2 * len(records) // 3:]    # a gap between them
    log_format.write_window(LogWindow(first, []), str(tmp_path), 'json-xz')
    log_format.write_window(LogWindow(second, []), str(tmp_path), 'bag-lz4')
    windows = demo.read_windows(str(tmp_path))
    assert sorted(w['path'].rsplit('.', 1)[-1] for w in windows) == ['bag', 'xz']
    counted = lambda part, topic: sum(1 for record in part if record.topic == topic)  # noqa: E731
    start = sim.DEFAULT_START_TIME
    truth = [{'type': 'collision', 'start': start + 0.5, 'end': start + 0.8},        # inside the first window
             {'type': 'wheels_slipping', 'start': start + 3.5, 'end': start + 3.6},  # inside the second
             {'type': 'localization_jump', 'start': start + 1.5, 'end': start + 2.0}]  # in the gap, no slack
    kept = demo.kept_around(windows, truth, slack=0.0)
    assert [(frames, scans) for _, frames, scans in kept] == [
        (counted(first, sim.CAMERA_TOPIC), counted(first, sim.SCAN_TOPIC)),
        (counted(second, sim.CAMERA_TOPIC), counted(second, sim.SCAN_TOPIC)), (0, 0)]
    assert kept[0][1] == 20 and kept[0][2] == 14
