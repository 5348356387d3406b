"""``cclog info``: each window's serialized bytes per topic (MB in the text, bytes in --json), for both formats."""
import json

import pytest
from conftest import cclog

from cc_log.storage import log_format
from cc_log import sim
from cc_log.base.records import LogWindow, Record


def ok(*args):
    result = cclog(*args)
    assert result.returncode == 0, result.stderr
    return result.stdout


@pytest.mark.parametrize('fmt', ['json-xz', 'bag-lz4'])
def test_info_gives_the_serialized_bytes_of_each_topic(tmp_path, fmt):
    simulator = sim.Simulator(sim.SimConfig(minutes=1.0 / 60, anomalies=0, camera=True, scan=True, imu=True))
    items = list(simulator.messages())
    path, _ = log_format.write_window(LogWindow([Record(stamp, topic, msg) for topic, stamp, msg in items], []),
                                      str(tmp_path), fmt)
    expected = {}
    for topic, _, msg in items:
        expected[topic] = expected.get(topic, 0) + len(sim.serialized(msg))
    (window,) = json.loads(ok('info', path, '--json'))['windows']
    assert window['topic_bytes'] == expected
    assert expected[sim.CAMERA_TOPIC] == 15 * (320 * 240 * 3 + 52)    # 15 frames: pixels + Image's other fields
    lines = ok('info', path).splitlines()
    assert lines[lines.index(next(line for line in lines if line.startswith('  messages'))) + 1] == (
        '  topic MB   /camera/image_raw 3.46, %s (serialized)' % ', '.join(
            '%s %.2f' % (topic, expected[topic] / 1e6) for topic in (sim.ODOM_TOPIC, sim.IMU_TOPIC, sim.SCAN_TOPIC)))
