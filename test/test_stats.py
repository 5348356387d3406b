"""cclog stats: distance, time moving/stopped, windows per hour, bytes vs rosbag record, on a simulated run."""
import json

import pytest

from cc_log.offline import cli, stats
from cc_log.storage import log_format
from cc_log import sim
from cc_log.storage.context_track import ContextTrack
from cc_log.base.records import LogWindow, Record, Trigger

MINUTES = 4.0


@pytest.fixture(scope='module')
def run(tmp_path_factory):
    """A 4-minute simulated run (perfect sensors: the odometry is the true path) into a context track at
    1 Hz, and two windows of full-rate odometry (the second in two parts): (directory, simulator)."""
    directory = tmp_path_factory.mktemp('stats')
    simulator = sim.Simulator(sim.SimConfig(minutes=MINUTES, anomalies=0, noise=0.0, seed=3))
    track = ContextTrack(directory, {sim.ODOM_TOPIC: 1.0}, rotate=60)
    odometry = []
    for topic, stamp, msg in simulator.messages():
        if topic == sim.ODOM_TOPIC:
            record = Record(stamp, topic, msg)
            track.add(record)
            odometry.append(record)
    track.close()
    first = odometry[3000:3500]
    trigger = Trigger(first[100].stamp, 'classifier', -1.0, 'classifier')
    log_format.write_window(LogWindow(first, [trigger]), str(directory), log_format.Format.JSON_XZ)
    rule = Trigger(odometry[9000].stamp, 'rule', None, 'bumper')
    log_format.write_window(LogWindow(odometry[9000:9300], [rule], part=1), str(directory), log_format.Format.BAG_LZ4)
    log_format.write_window(LogWindow(odometry[9300:9600], [rule], part=2), str(directory), log_format.Format.BAG_LZ4)
    return directory, simulator


def test_distance_is_the_simulators_true_distance_within_one_percent(run):
    directory, simulator = run
    result = stats.run_stats(directory)
    assert simulator.distance > 100.0  # the base did drive
    assert abs(result['distance_m'] - simulator.distance) <= 0.01 * simulator.distance
    assert result['odometry_topic'] == sim.ODOM_TOPIC and result['odometry_samples'] == int(MINUTES * 60)
    covered = result['moving_s'] + result['stopped_s'] + result['gap_s']
    assert covered == pytest.approx(MINUTES * 60 - 1, abs=1.0)
    assert result['stopped_s'] > 0 and result['moving_s'] > result['stopped_s']  # the base dwells at its goals


def test_windows_by_trigger_and_bytes_against_rosbag_record(run):
    directory, _ = run
    result = stats.run_stats(directory)
    assert result['windows'] == 2 and result['windows_by_trigger'] == {'classifier': 1, 'bumper': 1}
    hours = result['hours']
    assert hours == pytest.approx(MINUTES / 60.0, rel=0.01)
    assert result['windows_per_hour']['bumper'] == pytest.approx(1 / hours)
    odometry = result['topics'][sim.ODOM_TOPIC]
    assert odometry['rate_hz'] == pytest.approx(100.0, rel=0.01)  # measured inside the windows
    expected = 100.0 * MINUTES * 60 * (odometry['message_bytes'] + stats.ROSBAG_OVERHEAD)
    assert result['rosbag_record_bytes'] == pytest.approx(expected, rel=0.01)
    assert 0 < result['stored_bytes'] < 0.05 * result['rosbag_record_bytes']


def test_a_time_range_counts_only_what_lies_in_it(run):
    directory, simulator = run
    start = sim.DEFAULT_START_TIME
    result = stats.run_stats(directory, since=start, until=start + 60.5)
    assert result['odometry_samples'] == 61 and result['windows'] == 1  # the window at 30 s; not the one at 90 s
    whole = stats.run_stats(directory)
    assert 0 < result['distance_m'] < whole['distance_m']
    with pytest.raises(ValueError, match='no context track or window files in the time range'):
        stats.run_stats(directory, since=start + 10000)


def test_cli_stats_json_and_text(run, capsys):
    directory, simulator = run
    assert cli.main(['stats', str(directory), '--json']) == 0
    document = json.loads(capsys.readouterr().out)
    assert abs(document['distance_m'] - simulator.distance) <= 0.01 * simulator.distance
    assert cli.main(['stats', str(directory), '--since', '2020-09-13T12:26:40Z', '--until', '1600000060']) == 0
    text = capsys.readouterr().out
    assert 'distance' in text and 'rosbag record' in text and 'classifier 1' in text


def test_cli_stats_bad_input_is_one_line(tmp_path, capsys):
    assert cli.main(['stats', str(tmp_path / 'missing')]) != 0
    assert cli.main(['stats', str(tmp_path), '--since', 'yesterday']) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and 'missing' in err[0] and 'since' in err[1]


def test_odometry_summary_arcs_and_gaps():
    import math
    # a quarter circle of radius 2 sampled every 1 s in 4 steps: the arc length, not the chords
    samples = [(float(i), 2 * math.sin(i * math.pi / 8), 2 - 2 * math.cos(i * math.pi / 8), i * math.pi / 8)
               for i in range(5)]
    summary = stats.odometry_summary(samples + [(100.0, 0.0, 0.0, 0.0)])
    assert summary['distance_m'] == pytest.approx(math.pi, rel=1e-9)
    assert summary['gap_s'] == 96.0 and summary['moving_s'] == 4.0
