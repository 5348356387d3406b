"""demo.py --out DIR never deletes anything it did not create (a robot's ~/.ros/cc_log stays as it is)."""
import os
import subprocess
import sys

from cc_log.offline import demo

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
    from cc_log.storage import log_format
    from cc_log import sim
    from cc_log.base.records import LogWindow, Record
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
             {'type': 'localization_jump', 'start': start + 1.5, 'end': start + 2.0}]  # in the gap
    kept = demo.kept_around(windows, truth)
    assert [(frames, scans) for _, frames, scans in kept] == [
        (counted(first, sim.CAMERA_TOPIC), counted(first, sim.SCAN_TOPIC)),
        (counted(second, sim.CAMERA_TOPIC), counted(second, sim.SCAN_TOPIC)), (0, 0)]
    assert kept[0][1] == 20 and kept[0][2] == 14


# -- the demo's verdict: the share of each event's span kept ------------------------------------------------

def test_coverage_is_the_share_of_an_events_span_inside_the_windows():
    event = {'type': 'collision', 'start': 10.0, 'end': 14.0}
    assert demo.coverage(event, []) == 0.0
    assert demo.coverage(event, [{'start': 9.0, 'end': 11.0}]) == 0.25  # only the onset: what onset windows kept
    assert demo.coverage(event, [{'start': 9.0, 'end': 11.0}, {'start': 10.5, 'end': 12.0},
                                 {'start': 13.0, 'end': 20.0}]) == 0.75  # overlapping windows counted once
    assert demo.coverage(event, [{'start': 5.0, 'end': 20.0}]) == 1.0
    assert demo.coverage({'start': 3.0, 'end': 3.0}, [{'start': 2.0, 'end': 4.0}]) == 1.0


def test_the_demo_passes_only_with_every_event_kept_whole_and_no_false_window():
    truth = [{'type': 'collision', 'start': 10.0, 'end': 14.0}, {'type': 'wheels_slipping', 'start': 30.0, 'end': 33.0}]
    whole = [{'start': 9.0, 'end': 14.0, 'names': ['classifier']},
             {'start': 29.0, 'end': 34.0, 'names': ['classifier', 'goal_aborted']}]
    events, false_windows, passed = demo.score(whole, truth)
    assert passed and false_windows == []
    assert [(share, names) for _, share, names in events] == [(1.0, {'classifier'}),
                                                              (1.0, {'classifier', 'goal_aborted'})]
    onsets = [{'start': 9.0, 'end': 11.0, 'names': ['classifier']}, dict(whole[1])]
    events, false_windows, passed = demo.score(onsets, truth)
    assert not passed and events[0][1] == 0.25  # caught (it overlaps) but not kept whole
    stray = whole + [{'start': 20.0, 'end': 22.0, 'names': ['classifier']}]
    events, false_windows, passed = demo.score(stray, truth)
    assert not passed and false_windows == [stray[2]]
    # a window starting right after an event's end overlaps nothing: false, and it catches nothing
    late = [{'start': 14.0, 'end': 16.0}, dict(whole[1])]
    assert demo.score(late, truth)[0][0][1] == 0.0 and demo.score(late, truth)[1] == [late[0]]


def test_the_demos_configuration_keeps_every_event_of_its_run_whole(tmp_path):
    """The demo offline: its model (demo.train) and configuration (demo.config_text) replayed on its live
    run (the simulator as demo.launch runs it: seed 8, 2.5 min, 6 anomalies, gap 10 s) through SmartLogger;
    demo.score passes (with retrigger onset and 1 s + 1 s, the old demo, a collision kept about a third)."""
    import yaml
    from cc_log.logger import config
    from cc_log.learning import learning
    from cc_log.base import raw_message
    from cc_log import sim
    from cc_log.logger.smart import SmartLogger
    from cc_log.offline.replay import replay_records
    from cc_log.base.records import Record
    demo.prepare_out(str(tmp_path))
    model_path = demo.train(str(tmp_path), demo.DEFAULT_TRAIN_MINUTES, demo.DEFAULT_SEED, demo.DEFAULT_WINDOW,
                            demo.DEFAULT_STRIDE)
    run = sim.Simulator(sim.SimConfig(rate=100.0, seed=8, minutes=demo.DEFAULT_LIVE_MINUTES,
                                      anomalies=demo.DEFAULT_ANOMALIES, gap=10.0, imu=True, jitter=0.0, commands=True))
    records = [Record(stamp, topic, msg) for topic, stamp, msg in run.messages() if topic != sim.TRUTH_TOPIC]
    cfg = config.Config.from_dict(yaml.safe_load(demo.config_text(model_path)), 'demo.yaml')
    triggers = cfg.build_triggers(learning.AnomalyModel.load, raw_message.installed_class)
    options = dict(cfg.logger_options(triggers), side_topics=[sim.IMU_TOPIC])
    logger = SmartLogger(None, str(tmp_path / 'windows'), background=False, **options)
    saved = replay_records(logger, records)['windows']
    events, false_windows, passed = demo.score(saved, run.truth)
    assert len(events) == 6 and false_windows == []
    assert passed, [(event['type'], round(share, 3)) for event, share, _ in events]
