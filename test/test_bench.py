"""The bench/ scripts still run: each on tiny inputs (--quick), checking the shape of what they print.

Benchmarks are scripts, not timed tests: nothing here asserts on a time, a rate or a size.
"""
import os
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(ROOT, 'bench')


def run(script, *args, timeout=600):
    completed = subprocess.run([sys.executable, os.path.join(BENCH, script)] + list(args), cwd=ROOT,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True,
                               timeout=timeout)
    assert completed.returncode == 0, completed.stdout[-3000:]
    out = completed.stdout
    assert out.startswith('# '), out[:500]
    assert '\nmachine: ' in out and ' cores' in out
    assert '\ndata: ' in out
    assert 'total ' in out
    return out


def targets(out):
    return [line for line in out.splitlines() if line.startswith('target ')]


def test_detection_sim_quick():
    out = run('detection_sim.py', '--quick')
    assert 'Table 1' in out and '| TP ' in out and '| Precision ' in out
    assert 'paper features' in out and 'paper settings' in out and 'motion + progress' in out
    assert len(targets(out)) == 2


def test_learn_online_and_tune_choice_quick():
    out = run('learn_online.py', '--quick')
    assert 'false windows (4 min)' in out and 'refits' in out
    out = run('tune_choice.py', '--quick')
    assert 'Every setting tried' in out and '\nchosen: window ' in out


def test_storage_quick():
    out = run('storage.py', '--quick')
    assert out.count('Table 2, ') == 2
    assert 'cc_log json-xz' in out and 'cc_log bag-lz4' in out and 'LZMA-6' in out
    assert 'End to end' in out and 'rosbag --lz4 B' in out and 'BWI 1/100 bz2 B' in out
    assert 'cc_log json-xz precision' in out and out.count('largest error per field: ') == 2
    assert len(targets(out)) == 5


def test_format_layouts_quick():
    out = run('format_layouts.py', '--quick')
    assert '\nload: ' in out
    for layout in ('rows', 'columns-v1', 'columns', 'columns-alldiff', 'lossy-4/5', 'lossy-3/4', 'binary-floor'):
        assert '\n  %s ' % layout in out, layout
    assert 'lossy-4/5 largest error per field (all 3952 msgs): pose.pose.orientation.w' in out
    assert '\n  columns          6+opts ' in out


def test_lzma_options_quick():
    out = run('lzma_options.py', '--quick')
    assert 'Husky odometry, whole: 1 window(s), 3952 messages' in out
    assert out.count(' (written) ') == 1 and '| preset 6 alone ' in out


def test_injected_husky_quick():
    out = run('injected_husky.py', '--quick')
    assert 'Caught by type' in out and 'false windows/h' in out and 'kept/needed' in out
    assert len(targets(out)) == 3


def test_detection_runs_quick():
    out = run('detection_runs.py', '--runs', 'icelab_normal_plan', '--seeds', '0', '--settings', 'ours')
    assert 'icelab_normal_plan' in out and 'false/h' in out and 'kept/needed' in out and 'by type:' in out
    assert 'all runs: caught ' in out


def test_slowed_copies_keep_the_path_and_the_twist_lag():
    sys.path.insert(0, BENCH)
    import detection_runs
    import retime
    records = detection_runs.load('husky_outdoor_2015', '/husky_velocity_controller/odom', None)
    first, _ = detection_runs.split(records, 0.5)
    lag = retime.twist_lag([r.stamp for r in first], [retime.state(r.msg) for r in first])
    assert 0.4 <= lag <= 0.6  # the Husky's twist lags its pose by ~0.5 s (docs/RESULTS.md, real runs)
    copy = retime.slowed(first, seed=0, braking=1.0)
    assert len(copy) > len(first)  # the same path, slower
    speeds = [abs(r.msg.twist.twist.linear.x) for r in copy]
    assert max(speeds) <= max(abs(r.msg.twist.twist.linear.x) for r in first) + 1e-9
    assert speeds.count(0.0) > 10  # it stops
    copy_lag = retime.twist_lag([r.stamp for r in copy], [retime.state(r.msg) for r in copy])
    assert copy_lag == pytest.approx(lag, abs=0.11)
    steps = [b.stamp - a.stamp for a, b in zip(copy, copy[1:])]
    assert max(steps) - min(steps) < 1e-6
    out = run('detection_runs.py', '--runs', 'socspioneer_trace1', '--seeds', '0', '--settings', 'ours',
              '--slowed', '1', '--braking', '1')
    assert 'all runs: caught ' in out


def test_detection_sim_tuning_quick_with_a_progress_classifier():
    out = run('detection_sim_tuning.py', '--quick', '--retrigger', 'event', '--progress', '500')
    assert 'beside motion a progress classifier over 500' in out
    rows = [line for line in out.splitlines() if line.startswith('| 1s ')]
    assert len(rows) == 1 and '| demo ' in rows[0] and '| event ' in rows[0]
    assert re.search(r'\| \d/6 +\| plan\d coll\d accel\d twist\d loc\d slip\d', rows[0]), rows[0]


def test_detection_sim_tuning_quick_with_the_demos_configuration():
    out = run('detection_sim_tuning.py', '--quick', '--config', 'demo', '--post', '1s,6s')
    assert "the demo's configuration (demo.config_text), post 1s,6s" in out
    rows = [line for line in out.splitlines() if line.startswith('| 1s ')]
    assert [row.split('|')[7].strip() for row in rows] == ['post 1s', 'post 6s']
    for row in rows:  # span kept (least), >= 95 %, by anomaly, windows overlapping none, kept/ideal
        assert re.search(r'\| \d+\.\d% +\| \d/6 +\| (\w+\d+ ?){6} +\| \d+ +\| \d\.\d\dx +\|$', row), row


def test_detection_ranker_quick():
    out = run('detection_ranker.py', '--runs', 'icelab_normal_plan', '--seeds', '0', '--train-on', 'self')
    row = next(line for line in out.splitlines() if line.startswith('| icelab_normal_plan '))
    cells = [cell.strip() for cell in row.split('|')[1:-1]]
    caught = re.compile(r'^\d+/6 \(\d+\)$')  # one injection of each of the six types
    assert caught.match(cells[2]) and caught.match(cells[4]), row
    assert int(cells[5]) > 0 and int(cells[6]) > 0  # the ranker saw nominal and anomalous vectors


def test_detection_runs_robot_scale_calibrated():
    out = run('detection_runs.py', '--runs', 'icelab_window_plan', '--seeds', '0', '--settings', 'ours',
              '--injection', 'robot', '--threshold', 'calibrated')
    assert 'icelab_window_plan envelope: max_speed ' in out and 'all runs: caught ' in out
    assert 'icelab_window_plan calibrated threshold at depth ' in out


def test_detection_runs_trained_on_the_robots_other_runs():
    args = ('detection_runs.py', '--runs', 'socspioneer_trace1', '--seeds', '0', '--settings', 'ours')
    seconds = []
    for extra in ((), ('--train-on', 'robot')):
        out = run(*(args + extra))
        row = next(line for line in out.splitlines() if line.startswith('| socspioneer_trace1 '))
        seconds.append(float(row.split('|')[3]))       # 'train s': the nominal driving the model saw
        assert 'kept/needed over the ' in out and 'all runs: caught ' in out
    # its own first half (~45 s), then also trace0 in full (~96 s); the replayed half is the same
    assert 40 < seconds[0] < 50 and seconds[1] - seconds[0] > 90


def test_cost_offline_quick():
    out = run('cost_offline.py', '--quick', '--writer')
    assert 'replay/read (CPU)' in out and 'husky_outdoor_2015' in out
    assert len(targets(out)) == 1
    writer = out.split('Writers alone on the kept windows')[1].splitlines()[3].split('|')
    assert int(writer[3]) > 0 and float(writer[8]) > 0  # kept messages were encoded both ways
    assert float(writer[10]) > 0 and float(writer[11]) > 0  # and written as bags by rosbag and by bag_writer


def test_training_quick():
    out = run('training.py', '--quick')
    assert 'exact OCSVM' in out and 'nystroem-sgd' in out and 'paper case' in out
    assert len(targets(out)) == 2


def test_cost_live_quick():
    for command in ('roscore', 'rosrun', 'rospack'):  # package.xml declares them (roslaunch, rosbash)
        assert shutil.which(command), '%s not found: install what package.xml declares (./dev.sh setup)' % command
    if subprocess.run(['rospack', 'find', 'cc_log'], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode:
        pytest.skip('cc_log is not on ROS_PACKAGE_PATH: source .catkin_ws/devel/setup.bash first')
    out = run('cost_live.py', '--quick')
    assert 'rosbag record' in out and 'node / record' in out
    assert len(targets(out)) == 2


@pytest.mark.skipif(shutil.which('roscore') is None or shutil.which('rosrun') is None,
                    reason='needs roscore and rosrun (a sourced ROS workspace)')
def test_memory_live_quick():
    out = run('memory_live.py', '--quick')
    assert 'window open throughout' in out and 'peak RSS MB' in out and 'max buffered MB' in out
    assert len(targets(out)) == 1


def test_context_track_quick():
    out = run('context_track.py', '--quick')
    assert '| sensor noise ' in out and 'cclog stats m' in out and out.count('%') >= 2


def test_imu_collision_quick():
    out = run('imu_collision.py', '--quick')
    row = next(line for line in out.splitlines() if line.startswith('| soft_collision '))
    assert [cell.split()[0] for cell in row.split('|')[2:-1]] == ['0/1', '1/1', '1/1', '1/1', '0/1']
    assert 'Husky (real, nominal only)' in out and 'Sequor (real): 19 wall crashes' in out
    assert len(targets(out)) == 3


def test_progress_bars_quick():
    out = run('progress_bars.py', '--quick')
    assert 'microseconds per update()' in out and '| disabled ' in out and '| enabled, drawn ' in out


def test_heavy_workload_has_the_stated_sizes(tmp_path):
    pytest.importorskip('roslz4', reason='needs a sourced ROS workspace (rosbag, roslz4)')
    import rosbag
    sys.path.insert(0, BENCH)
    import heavy_workload
    one = heavy_workload.Workload(cameras=1, seconds=1.0)
    path, info = heavy_workload.workload_bag(one, str(tmp_path))
    assert heavy_workload.workload_bag(one, str(tmp_path))[1] == info  # cached, not rebuilt
    with rosbag.Bag(path) as bag:
        counts = {topic: i.message_count for topic, i in bag.get_type_and_topic_info().topics.items()}
        assert bag.get_compression_info().compression == 'none'
        frames = [msg for _, msg, _ in bag.read_messages(topics=['/camera/image_raw'])]
        scan = next(msg for _, msg, _ in bag.read_messages(topics=['/velodyne_points']))
    assert counts == {'/camera/image_raw': 30, '/velodyne_points': 10, '/odom': 100, '/imu/data': 100}
    assert (frames[0].width, frames[0].height, frames[0].encoding, frames[0].step) == (640, 480, 'rgb8', 1920)
    assert len(frames[0].data) == 921600 and len(set(frame.data for frame in frames)) == 30  # every frame differs
    assert (scan.width * scan.height, scan.point_step, len(scan.data)) == (28800, 32, 28800 * 32)
    assert [field.name for field in scan.fields] == ['x', 'y', 'z', 'intensity', 'ring', 'time']
    assert 36.5e6 <= sum(info['bytes'].values()) <= 37.5e6  # bytes in 1 s: ~37 MB/s
    assert info['ratios']['/camera/image_raw']['lz4'] > 0.95  # LZ4 does not make the frames free
    two = heavy_workload.Workload(cameras=2, seconds=1.0)
    _, info = heavy_workload.workload_bag(two, str(tmp_path))
    assert sorted(info['bytes']) == sorted(['/camera/image_raw', '/camera2/image_raw', '/velodyne_points', '/odom',
                                            '/imu/data'])
    assert info['message_bytes']['/velodyne_points'] - 131072 * 32 < 200  # 128 x 1024 points
    assert 95e6 <= sum(info['bytes'].values()) <= 100e6


@pytest.mark.skipif(shutil.which('roscore') is None or shutil.which('rosrun') is None,
                    reason='needs roscore and rosrun (a sourced ROS workspace)')
def test_heavy_sensors_quick(tmp_path):
    out = run('heavy_sensors.py', '--quick', '--out', str(tmp_path))
    assert 'workload: 37.0 MB/s for 6 s' in out and 'node / record --lz4 CPU' in out
    row = next(line for line in out.splitlines() if line.startswith('| one ') and 'bag-lz4' in line)
    cells = [cell.strip() for cell in row.split('|')[1:-1]]
    assert cells[7].endswith(' / 120')  # the 4 s window spans 120 frames of the 30 Hz camera
    detail = next(line for line in out.splitlines() if line.startswith('| one ') and '/camera/image_raw' in line)
    played, recorded, recorded_lz4 = (cell.strip() for cell in detail.split('|')[4:7])
    assert played == '180' and recorded.isdigit() and recorded_lz4.isdigit()


@pytest.mark.skipif(shutil.which('roscore') is None or shutil.which('rosrun') is None,
                    reason='needs roscore and rosrun (a sourced ROS workspace)')
def test_heavy_sensors_quick_on_wall_time_keeps_every_image_of_its_window(tmp_path):
    """--wall-clock: no /clock, /use_sim_time false; the bench's plan follows the played odometry's header stamps
    and the node's window lands where the bench expects it: every image of the 4 s window kept."""
    out = run('heavy_sensors.py', '--quick', '--wall-clock', '--out', str(tmp_path))
    assert '\nclock: wall time (/use_sim_time false, rosbag play without --clock' in out
    row = next(line for line in out.splitlines() if line.startswith('| one ') and 'bag-lz4' in line)
    cells = [cell.strip() for cell in row.split('|')[1:-1]]
    assert cells[7] == '120 / 120' and cells[8] == '1 / 1'  # one file, every frame of the 4 s window
    detail = next(line for line in out.splitlines() if line.startswith('| one ') and '/camera/image_raw' in line)
    played, recorded, recorded_lz4 = (cell.strip() for cell in detail.split('|')[4:7])
    assert played == '180' and recorded.isdigit() and recorded_lz4.isdigit()


def test_cost_passes_wall_clock_to_the_heavy_sensors_bench_and_names_its_rows(monkeypatch):
    """``cost.py --wall-clock``: keepall runs ``heavy_sensors.py ... --wall-clock`` and its rows say so; without
    it the bench runs as before (sim time), the rows named as before."""
    sys.path.insert(0, BENCH)
    import cost
    calls = []
    table = ('| scenario | format | node / record CPU | node / record --lz4 CPU | images kept / expected |\n'
             '|---|---|---|---|---|\n| one | bag-lz4 | 0.91 | 0.70 | 120 / 120 |\n'
             '| all | bag-lz4 | 1.40 | 1.20 | 900 / 900 |\n\ntotal 1 s\n')
    monkeypatch.setattr(cost, 'bench', lambda script, *args: calls.append((script,) + args) or table)
    assert cost.keepall(37, wall_clock=True) == {
        ('one window ~37 MB/s on wall time: node / rosbag record', 0.8): 0.91,
        ('keep-all ~37 MB/s on wall time: node / rosbag record --lz4', 1.1): 1.2}
    assert calls[-1] == ('heavy_sensors.py', '--scenarios', 'one,all', '--format', 'bag-lz4', '--wall-clock')
    assert sorted(cost.keepall(100)) == [('keep-all ~100 MB/s: node / rosbag record --lz4', 1.1),
                                         ('one window ~100 MB/s: node / rosbag record', 0.8)]
    assert calls[-1] == ('heavy_sensors.py', '--scenarios', 'one,all', '--format', 'bag-lz4', '--rate', '100')


def test_detectors_quick_prints_every_detector_and_the_curve(tmp_path):
    out = run('detectors.py', '--quick', '--out', str(tmp_path))
    for name in ('envelope', 'knn-mean', 'knn-max', 'lof', 'iforest', 'ocsvm', 'mahalanobis', 'ecod', 'copod',
                 'cclog'):
        assert re.search(r'\n\| %s +\| \d+/6 +\| \d +\| \d+/\d+ +\| \d+ +\|' % name, out), name
    assert re.search(r'\n## husky: [\d.]+ Hz, trained on 3.3 min \(\d+ windows\), held out 3.3 min nominal', out)
    assert 'recall per anomaly type' in out and 'per threshold level (the curve)' in out
    assert (tmp_path / 'detectors_curve.png').stat().st_size > 1000
    assert len(targets(out)) == 3  # false windows, dominance, dominance by more than chance


def test_a_combination_flags_exactly_what_one_of_its_parts_flags_at_its_base_level():
    """``Either`` (the candidates of cc_log's default): at level 2 a window is flagged when a part would be at its
    own base level, at other levels each part's level scales with it."""
    sys.path.insert(0, BENCH)
    import detectors
    from cc_log.features.envelope import ENVELOPE_COLUMNS
    rng = np.random.RandomState(1)
    train = np.abs(rng.normal(1.0, 0.3, size=(400, len(ENVELOPE_COLUMNS))))
    windows = np.abs(rng.normal(1.0, 0.9, size=(3000, len(ENVELOPE_COLUMNS))))
    found = detectors.make_detectors(candidates=True)
    env, maha, either = found['envelope'], found['mahalanobis'], found['env2|maha4']
    for detector in (env, maha, either):
        detector.fit(train)
    for level in (1.0, 2.0, 3.0):
        parts = (env.score(windows) < env.threshold(level)) | (maha.score(windows) < maha.threshold(2 * level))
        flagged = either.score(windows) < either.threshold(level)
        assert flagged.any() and not flagged.all()
        assert np.array_equal(flagged, parts), level


def test_a_third_part_joins_the_combination_at_its_own_level():
    """A candidate of three parts (``env2|maha4|lof6``) flags exactly what the envelope at 2x, the robust distance
    at level 4 or LOF at level 6 flags."""
    sys.path.insert(0, BENCH)
    import detectors
    from cc_log.features.envelope import ENVELOPE_COLUMNS
    rng = np.random.RandomState(2)
    train = np.abs(rng.normal(1.0, 0.3, size=(400, len(ENVELOPE_COLUMNS))))
    windows = np.abs(rng.normal(1.0, 1.2, size=(2000, len(ENVELOPE_COLUMNS))))
    found = detectors.make_detectors(candidates=True)
    for name in ('envelope', 'mahalanobis', 'lof'):
        found[name].fit(train)
    either = found['env2|maha4|lof6'].fit(train)
    parts = ((found['envelope'].score(windows) < found['envelope'].threshold(2.0)) |
             (found['mahalanobis'].score(windows) < found['mahalanobis'].threshold(4.0)) |
             (found['lof'].score(windows) < found['lof'].threshold(6.0)))
    flagged = either.score(windows) < either.threshold(2.0)
    assert flagged.any() and not flagged.all()
    assert np.array_equal(flagged, parts)


def test_the_candidates_table_names_where_a_standard_detector_dominates_each(capsys):
    """Per candidate the robots where a standard detector at level 2 dominates it (as many caught with fewer false
    windows, or more with as few) and where it falls short of the envelope at 2x; cclog's own "dominating" column
    counts the standard detectors only, never a candidate."""
    sys.path.insert(0, BENCH)
    import detectors

    def robot(name, cells):
        stats = {}
        for detector in detectors.STANDARD + ('env2|maha4|lof6', 'cclog'):
            caught, false = cells.get(detector, (0, 0))
            tally = detectors.tally()
            tally.update(caught=[True] * caught + [False] * (10 - caught), false=false)
            stats[detector] = {None if detector == 'cclog' else 2.0: tally}
        return {'robot': name, 'hours': 0.5, 'events': [{'type': 'collision', 'extreme': 1.0}] * 10, 'stats': stats}

    quiet = robot('quiet', {'envelope': (5, 1), 'lof': (7, 0), 'env2|maha4|lof6': (8, 1), 'cclog': (5, 1)})
    busy = robot('busy', {'envelope': (6, 0), 'knn-max': (6, 0), 'env2|maha4|lof6': (6, 1), 'cclog': (6, 0)})
    assert detectors.dominating(quiet, 2.0) == [('lof', 2.0)]   # not the candidate, which catches more
    assert detectors.dominating(busy, 2.0) == []
    results = [quiet, busy]
    detectors.detector_candidates.report(results, detectors.pooled(results), 2.0, detectors.cell_of,
                                         detectors.STANDARD, detectors.common.table)
    out = capsys.readouterr().out
    rows = {line.split(' | ')[0].strip('| '): [cell.strip(' |') for cell in line.split(' | ')[1:]]
            for line in out.splitlines() if line.startswith('| ')}
    assert rows['env2|maha4|lof6'] == ['14/20', '2', '2.00', 'busy (envelope, knn-max)', '-', 'busy']
    assert rows['cclog'] == ['11/20', '1', '1.00', 'quiet (lof)', '-', '-']
    assert 'meeting all three (dominated nowhere, >= envelope 2x on every robot, <= 5 false/h pooled): none' in out


def test_detectors_flag_what_lies_beyond_the_training_windows():
    """Every window detector, fitted on synthetic nominal windows, flags a window with every feature far beyond
    them at the table's level, and the typical window never; a window with one feature 5x its training maximum is
    flagged by all but the isolation forest (its random splits seldom cut the one feature among 19) and ECOD and
    COPOD (one feature's tail adds at most log(n + 1) to a sum over 19). The Poisson bound and the message count
    are exact."""
    sys.path.insert(0, BENCH)
    import detectors
    rng = np.random.RandomState(0)
    from cc_log.features.envelope import ENVELOPE_COLUMNS, ENVELOPE_FLOORS
    floors = np.array([ENVELOPE_FLOORS[name] for name in ENVELOPE_COLUMNS])
    train = np.abs(rng.normal(1.0, 0.2, size=(600, len(ENVELOPE_COLUMNS)))) * floors * 2
    typical = np.median(train, axis=0, keepdims=True)
    one = typical.copy()
    one[0, 3] = train[:, 3].max() * 5
    every = train.max(axis=0, keepdims=True) * 5
    for name, detector in detectors.make_detectors().items():
        detector.fit(train)
        threshold = detector.threshold(2.0)
        assert detector.score(every)[0] < threshold, name
        assert (detector.score(one)[0] < threshold) == (name not in ('iforest', 'ecod', 'copod')), name
        assert detector.score(typical)[0] > threshold, name
    assert detectors.upper95(0, 2.0) == pytest.approx(1.5)
    assert detectors.upper95(4, 1.0) == pytest.approx(10.2416, abs=1e-3)  # chi2.ppf(0.975, 10) / 2: Garwood
    stamps = np.arange(0.0, 10.0, 0.5)
    assert detectors.count_inside(stamps, [(1.0, 2.0), (1.5, 3.0), (8.9, 9.1)]) == 6  # 1.0-3.0 once, and 9.0


def test_a_difference_of_one_event_or_one_window_is_not_significant_and_a_large_one_is():
    """bench/significance.py: McNemar's exact test on the discordant events, the conditional binomial test on two
    false-window counts over the same hours; a detector dominates significantly only when its better side is."""
    sys.path.insert(0, BENCH)
    import significance
    assert significance.catches_p([1] * 7 + [0] * 5, [0] * 12) == pytest.approx(2 * 0.5 ** 7)
    assert significance.catches_p([1, 0, 1], [1, 0, 1]) == 1.0  # no event tells them apart
    assert significance.catches_p([1] * 12 + [0] * 5, [0] * 12 + [1] * 5) == pytest.approx(0.1435, abs=1e-4)
    assert significance.false_windows_p(0, 1) == 1.0 and significance.false_windows_p(0, 0) == 1.0
    assert significance.false_windows_p(0, 6) == pytest.approx(2 * 0.5 ** 6)
    reference = ([1] * 5 + [0] * 14, 1)  # 5 of 19 events caught, 1 false window
    candidates = {'one more caught': ([1] * 6 + [0] * 13, 1), 'one fewer window': ([1] * 5 + [0] * 14, 0),
                  'seven more caught': ([1] * 12 + [0] * 7, 1), 'fewer caught': ([1] * 4 + [0] * 15, 0)}
    found = significance.significantly_dominating(candidates, reference)
    assert [name for name, _, _ in found] == ['seven more caught']
    assert found[0][1] == pytest.approx(2 * 0.5 ** 7) and found[0][2] == 1.0


def strong_bound():
    sys.path.insert(0, BENCH)
    import strong_bound as module
    return module


def bumpy_run(bumps, base=0.5, length=100.0):
    """A synthetic nominal run for bench/strong_bound.py: window ends every 0.25 s, each window at level ``base``
    but at the times of ``bumps`` ({time: level})."""
    ends = np.arange(0.0, length, 0.25)
    levels = np.full(len(ends), base)
    for at, level in bumps.items():
        levels[np.argmin(np.abs(ends - at))] = level
    return ends, levels


def test_the_strong_bound_picks_the_strictest_level_that_catches_every_strong_event():
    """Catching every strong event with the labels: the level just below the least of their levels, no stricter
    (one event would be missed) and no looser (a nominal bump of 1.2 would open one more window); its false windows
    are the episodes detectors.py counts there. One level for all robots against a level each: each robot's own
    is as strict as its own events allow."""
    sb = strong_bound()
    from cc_log.offline.tuning import windows_of
    nominal = [bumpy_run({20.0: 1.8, 50.0: 1.2, 80.0: 0.9})]
    level, false, kept = sb.catch_all(nominal, [2.5, 1.6, 1.3])
    assert 1.2 < level < 1.3 and np.nextafter(level, np.inf) == 1.3
    assert false == 1 == len(windows_of(nominal[0][0][nominal[0][1] > level], 2.0, 2.0))
    assert kept == pytest.approx(4.0 / 100.0, abs=0.01)                  # one window of [fire - 2 s, fire + 2 s]
    assert sb.catch_all(nominal, [2.5, 1.6, 1.1])[1] == 2                 # the bump of 1.2 too
    assert sb.catch_all(nominal, []) == (np.inf, 0, 0.0)
    other = [bumpy_run({10.0: 3.0})]
    steps = [sb.false_steps(n) for n in (nominal, other)]
    hours = [100.0 / 3600.0] * 2
    found = sb.bound([nominal, other], hours, steps, [[1.3], [3.5]])
    assert found['false'] == 2                   # one level, just below 1.3, for both: the 3.0 bump opens one
    assert found['robot_false'] == 1             # each its own: the other robot's level just below 3.5 opens none
    assert found['population'] == 2


def test_an_event_no_threshold_separates_from_nominal_costs_the_false_windows_of_catching_it():
    """An event below every nominal window is caught only where every window is flagged: the false windows of that
    level are counted (one long window per run, all of the driving kept) and beside them the most any stricter level
    opens (the three bumps apart); an event no window reaches is caught at no level."""
    sb = strong_bound()
    nominal = [bumpy_run({20.0: 1.8, 50.0: 1.2, 80.0: 0.9}), bumpy_run({30.0: 2.0})]
    level, false, kept = sb.catch_all(nominal, [3.0, 0.4])
    assert level < 0.4 and false == 2 and kept == pytest.approx(1.0)
    steps = sb.false_steps(nominal)
    assert sb.at_levels(steps, level)[1][0] == 4                           # 3 bumps + 1 before all merge
    assert sb.catch_all(nominal, [3.0, -np.inf])[1] is None
    ends = np.arange(0.0, 30.0, 0.25)
    lv = np.full(len(ends), 0.3)
    lv[(ends >= 12.0) & (ends <= 13.0)] = 2.5
    caught, fast, target = sb.event_levels(ends, lv, {'start': 12.0, 'end': 14.0})
    assert caught == fast == 2.5 and target == 2.5                        # its windows keep all of its 2 s
    assert sb.event_levels(ends, lv, {'start': 12.2, 'end': 20.0})[2] == pytest.approx(0.3)   # span: flag all


def test_the_strong_bound_counts_as_the_detectors_bench_does():
    """On random windows, at any level: the false-window steps give the episodes windows_of opens (and their running
    most), an event's three levels give detectors.add_events' caught, within 0.5 s and span kept."""
    sb = strong_bound()
    import detectors
    from cc_log.offline.tuning import windows_of
    rng = np.random.RandomState(3)
    nominal = [(np.arange(0.0, length, 0.25), rng.gamma(1.0, 0.4, int(length / 0.25))) for length in (60.0, 90.0)]
    steps = sb.false_steps(nominal)
    grid = np.linspace(0.0, 3.0, 61)
    counts = [sb.false_windows(nominal, level) for level in grid]
    false, most = sb.at_levels(steps, grid)
    assert list(false) == counts and min(counts) < max(counts)
    assert list(most) == [max(sb.false_windows(nominal, lv) for lv in [level] + list(steps[0][steps[0] > level]))
                          for level in grid]
    ends, lv = nominal[1]
    truth = [{'start': at, 'end': at + span} for at, span in ((10.0, 3.0), (40.0, 0.5), (70.0, 8.0))]
    need = [sb.event_levels(ends, lv, entry) for entry in truth]
    for level in grid:
        tally = detectors.tally()
        fires = ends[lv > level]
        detectors.add_events(tally, fires, windows_of(fires, 2.0, 2.0), truth, 1.0, ends)
        assert tally['caught'] == [n[0] > level for n in need], level
        assert tally['fast'] == [n[1] > level for n in need], level
        assert [f and s for f, s in zip(tally['fast'], tally['spans'])] == [n[2] > level for n in need], level


def test_the_budget_goes_where_it_buys_the_most_events():
    """At <= 5/h a level per robot shares the pooled budget for the most events; one level for all stops where the
    pooled false windows first exceed it."""
    sb = strong_bound()
    assert sb.share_budget([[(0, 0, None), (1, 2, None), (3, 5, None)], [(0, 0, None), (2, 4, None)]], 3) == 6
    assert sb.share_budget([[(0, 0, None), (1, 2, None), (3, 5, None)], [(0, 0, None), (2, 4, None)]], 2) == 4
    nominal = [bumpy_run({20.0: 1.8, 50.0: 1.2, 80.0: 0.9})]
    steps = [sb.false_steps(nominal)]
    caught, level, false = sb.common_level(steps, [[2.5, 1.6, 1.3, 1.0]], 1)
    assert (caught, false) == (3, 1) and 1.2 < level < 1.3


def test_the_verdict_says_met_only_when_a_detector_catches_every_strong_event_at_the_rate():
    sb = strong_bound()

    def bound(at_rate, worst):
        return {'robot_caught_at_rate': at_rate, 'robot_worst': worst}

    line = sb.met_line({'a': bound(10, 40), 'b': bound(12, 30), 'c': bound(3, None)}, 12, 4.0)
    assert line == ('target strong events at <= 5/h: met by any detector (best: b, 12/12 at <= 5/h; all 12 cost '
                    '7.5/h (b))')
    line = sb.met_line({'a': bound(10, 40), 'b': bound(11, 30), 'c': bound(3, 20)}, 12, 4.0)
    assert line == ('target strong events at <= 5/h: not met by any detector (best: b, 11/12 at <= 5/h; all 12 '
                    'cost 5.0/h (c))')


def test_strong_bound_quick():
    out = run('strong_bound.py', '--quick')
    assert re.search(r'\n## husky: trained on 3.3 min, held out 3.3 min of nominal driving, 6 events', out)
    assert 'held-out nominal driving beyond 1.5x its training maximum: ' in out
    for name in ('envelope', 'mahalanobis', 'env2|maha4|lof6'):
        assert re.search(r'\n\| %s +\| [\d.e+-]+ +\| [\d.]+ \([\d.]+\) +\|' % re.escape(name), out), name
    assert re.search(r'\ntarget strong events at <= 5/h: (met|not met) by any detector \(best: \S+, \d+/\d+ at <= '
                     r'5/h; all \d+ cost ', out)


def test_a_drift_gated_candidate_changes_its_rule_only_once_its_monitor_has_stated_drift_for_a_span():
    """``DriftGated`` (the default's rule until drift has been stated for a whole span, then the envelope confirmed
    by the robust distance at level 1 or the robust distance at level 2): on windows like training it flags exactly
    what the default's rule flags; on a run whose every window passes a training maximum by 1.5x (coverage: drift
    stated 1 min in), exactly that until drift has lasted 2 min (3 min in), then the drifted rule; a window's score
    depends on it and the windows before only."""
    sys.path.insert(0, BENCH)
    import detectors
    from cc_log.features.envelope import ENVELOPE_COLUMNS
    rng = np.random.RandomState(3)
    train = np.abs(rng.normal(1.0, 0.3, size=(800, len(ENVELOPE_COLUMNS))))
    train[:4, 5:] *= 10.0   # a few odd training windows: the farthest robust distance is far (the real robots')
    found = detectors.make_detectors(candidates=True)
    for name in ('envelope', 'mahalanobis', 'lof'):
        found[name].fit(train)
    default = found['env2|maha4|lof6'].fit(train)
    name = 'env2|maha4|lof6/sustained:env2&maha1|maha2'
    gated = found[name].fit(train)
    drifted = gated.drifted
    ends = 1000.0 + 0.25 * np.arange(1, 1201)            # 5 min of windows
    like = np.abs(rng.normal(1.0, 0.3, size=(len(ends), len(ENVELOPE_COLUMNS))))
    like[:, 5:] = np.minimum(like[:, 5:], 1.0)
    like[::97, 0] *= 3.0                                 # now and then a feature beyond 2x
    assert np.array_equal(gated.score_at(like, ends), default.score(like))
    assert (default.score(like) < default.threshold(2.0)).any() and gated.state.log[-1] == (len(ends), 0, 0)
    rough = like.copy()
    rough[:, 1] = 1.5 * train[:, 1].max()                # always past the training maximum, never 2x
    rough[::37, 2] = 2.5 * train[:, 2].max()             # and beyond 2x now and then
    sustained = ends >= ends[0] + 60.0 + 120.0           # settled after 1 min (from the first window), then 2 min
    scores = gated.score_at(rough, ends)
    assert np.array_equal(scores[~sustained], default.score(rough)[~sustained])
    assert np.array_equal(scores[sustained], drifted.score(rough)[sustained])
    threshold = gated.threshold(2.0)
    unconfirmed = (default.score(rough) < threshold) & ~(scores < threshold)
    assert unconfirmed[sustained].any() and not unconfirmed[~sustained].any()
    half = len(ends) // 2
    assert np.array_equal(gated.score_at(rough[:half], ends[:half]), scores[:half])   # causal
    assert gated.state.log[-1] == (half, int((ends[:half] >= ends[0] + 60.0).sum()),
                                   int(sustained[:half].sum()))
