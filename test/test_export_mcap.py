"""``cclog export --to mcap`` (export.to_mcap) and ``--to bag`` of windows of either format, read back with the MCAP
reader (mcap + mcap-ros1-support, installed by ``dev.sh setup``) and with rosbag."""
import json
import os
import sys

import pytest
from conftest import cclog, real_data
from sensor_msgs.msg import LaserScan

from cc_log.storage.bag import bag_reader
from cc_log.offline import export
from cc_log.storage import log_format
from cc_log import sim
from cc_log.storage.formats import bag_lz4
from cc_log.base.records import LogWindow, Record, Trigger

HUSKY = 'husky_outdoor_2015.bag'
ODOM, IMU = '/husky_velocity_controller/odom', '/imu/data'


@pytest.fixture(scope='module')
def originals():
    """Serialized records in stamp order: 2 s of the simulated BWIBot with camera and scan, and the Husky's
    odometry and IMU (whose publisher latches) after them."""
    simulator = sim.Simulator(sim.SimConfig(minutes=2.0 / 60, anomalies=0, camera=True, scan=True, seed=2))
    records = [Record(stamp, topic, msg, 0, sim.serialized(msg)) for topic, stamp, msg in simulator.messages()]
    husky = list(bag_reader.read_raw(real_data(HUSKY), [ODOM, IMU]))[:200]
    latched = dict(next(r for r in husky if r.topic == IMU).connection, latching='1', callerid='/imu_node')
    shift = records[-1].stamp + 1.0 - husky[0].stamp
    return records + [r._replace(stamp=r.stamp + shift, connection=latched if r.topic == IMU else r.connection)
                      for r in husky]


def window_dir(records, directory, fmt):
    """The records as two window files of ``fmt`` in ``directory``."""
    half = len(records) // 2
    for part in (records[:half], records[half:]):
        log_format.write_window(LogWindow(part, []), str(directory), fmt)
    return directory


def read_mcap(path):
    """(schemas by channel topic, channel metadata by topic, [(topic, log_time, data, decoded message)])."""
    from mcap.reader import make_reader
    from mcap_ros1.decoder import DecoderFactory
    with open(str(path), 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        messages = [(channel.topic, message.log_time, message.data, decoded)
                    for schema, channel, message, decoded in reader.iter_decoded_messages()]
    schemas = {channel.topic: summary.schemas[channel.schema_id] for channel in summary.channels.values()}
    metadata = {channel.topic: dict(channel.metadata) for channel in summary.channels.values()}
    assert summary.statistics.message_count == len(messages)
    return schemas, metadata, messages


@pytest.mark.parametrize('fmt', ['json-xz', 'bag-lz4'])
def test_an_exported_mcap_holds_every_message_with_its_bytes(originals, tmp_path, fmt):
    windows = window_dir(originals, tmp_path / 'windows', fmt)
    out = tmp_path / 'all.mcap'
    result = cclog('export', windows, '--to', 'mcap', '--out', out, '--compression', 'lz4', '--json')
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)['messages'] == len(originals)
    schemas, metadata, messages = read_mcap(out)
    assert [(topic, data) for topic, _, data, _ in messages] == [(r.topic, r.raw) for r in originals]
    assert [t for _, t, _, _ in messages] == [secs * 10 ** 9 + nsecs for secs, nsecs in
                                              (bag_lz4.bag_stamp(r.stamp) for r in originals)]   # as the bag's times
    camera = next(decoded for topic, _, _, decoded in messages if topic == sim.CAMERA_TOPIC)
    first = next(r.msg for r in originals if r.topic == sim.CAMERA_TOPIC)
    assert (camera.width, camera.height, camera.encoding, bytes(camera.data)) == (320, 240, 'rgb8', bytes(first.data))
    assert schemas[sim.CAMERA_TOPIC].name == 'sensor_msgs/Image' and schemas[sim.CAMERA_TOPIC].encoding == 'ros1msg'
    assert schemas[ODOM].name == 'nav_msgs/Odometry' and schemas[ODOM].id == schemas[sim.ODOM_TOPIC].id  # one each
    assert 'uint8[] data' in schemas[sim.CAMERA_TOPIC].data.decode()          # the full definition, with Header's
    assert 'MSG: std_msgs/Header' in schemas[sim.CAMERA_TOPIC].data.decode()
    assert 'MSG: geometry_msgs/PoseWithCovariance' in schemas[ODOM].data.decode()
    assert metadata[IMU]['latching'] == 'true' and metadata[IMU]['callerid'] == '/imu_node'
    assert metadata[sim.SCAN_TOPIC]['md5sum'] == LaserScan._md5sum and 'latching' not in metadata[sim.SCAN_TOPIC]


def test_mcap_export_refuses_bz2_and_names_the_missing_library(originals, tmp_path, monkeypatch):
    records = originals[:50]
    with pytest.raises(ValueError, match='^compression: MCAP chunks are zstd, lz4, none, not bz2$'):
        export.to_mcap(records, str(tmp_path / 'x.mcap'), 'bz2')
    monkeypatch.setitem(sys.modules, 'mcap.writer', None)    # as if the optional package were not installed
    with pytest.raises(ValueError) as error:
        export.to_mcap(records, str(tmp_path / 'x.mcap'))
    assert str(error.value) == export.MCAP_MISSING and '\n' not in str(error.value)
    assert 'pip install --break-system-packages mcap' in str(error.value)
    assert not (tmp_path / 'x.mcap').exists()


def test_bag_export_of_json_xz_windows_opens_in_rosbag_with_every_message(originals, tmp_path):
    import rosbag
    windows = window_dir(originals, tmp_path / 'windows', 'json-xz')
    out = tmp_path / 'all.bag'
    result = cclog('export', windows, '--to', 'bag', '--out', out)
    assert result.returncode == 0, result.stderr
    with rosbag.Bag(str(out)) as bag:
        assert bag.get_message_count() == len(originals)
        read = [(topic, raw[1]) for topic, raw, _ in bag.read_messages(raw=True)]
    assert read == [(r.topic, r.raw) for r in originals]


@pytest.mark.parametrize('compression', ['zstd', 'lz4', None])
def test_an_exported_mcap_says_each_window_metadata_and_compresses_as_asked(originals, tmp_path, compression):
    from mcap.reader import make_reader
    if compression != 'lz4':
        pytest.importorskip('zstandard')  # an optional extra that dev.sh setup installs (python3-zstandard)
    windows = tmp_path / 'windows'
    half = len(originals) // 2
    triggers = ([Trigger(originals[10].stamp, 'wheel slip', -0.25, 'motion')],
                [Trigger(originals[half + 5].stamp, 'pressed', None, 'bumper'),
                 Trigger(originals[half + 9].stamp, 'too fast', 1.75, 'speed')])
    paths = [log_format.write_window(LogWindow(part, said), str(windows), 'bag-lz4')[0]
             for part, said in zip((originals[:half], originals[half:]), triggers)]
    out = tmp_path / 'all.mcap'
    asked = ['--compression', compression] if compression else []
    result = cclog('export', windows, '--to', 'mcap', '--out', out, *asked)
    assert result.returncode == 0, result.stderr
    with open(str(out), 'rb') as stream:
        reader = make_reader(stream)
        metadata = [(record.name, dict(record.metadata)) for record in reader.iter_metadata()]
        attachments = [(a.name, a.media_type, json.loads(a.data.decode())) for a in reader.iter_attachments()]
        chunks = {chunk.compression for chunk in reader.get_summary().chunk_indexes}
    assert chunks == {compression or 'zstd'}  # zstd by default when zstandard imports
    assert [name for name, _ in metadata] == ['cc_log.window'] * 2
    parts = (originals[:half], originals[half:])
    for (_, said), path, part, window_triggers in zip(metadata, paths, parts, triggers):
        assert said['file'] == os.path.basename(path)
        assert abs(float(said['start']) - part[0].stamp) < 1e-6 and abs(float(said['end']) - part[-1].stamp) < 1e-6
        assert json.loads(said['reasons']) == [t.reason for t in window_triggers]
        assert json.loads(said['scores']) == [t.score for t in window_triggers]
        assert [(t['name'], t['reason']) for t in json.loads(said['triggers'])] == [
            (t.name, t.reason) for t in window_triggers]
    assert [(name, media) for name, media, _ in attachments] == [
        (os.path.basename(path) + '.json', 'application/json') for path in paths]
    assert [t['reason'] for t in attachments[1][2]['triggers']] == ['pressed', 'too fast']


def test_without_zstandard_mcap_chunks_are_lz4_and_zstd_is_refused_in_one_line(originals, tmp_path, monkeypatch):
    from mcap.reader import make_reader
    monkeypatch.setitem(sys.modules, 'zstandard', None)  # as if python3-zstandard were not installed
    assert export.default_mcap_compression() == 'lz4'
    out = str(tmp_path / 'x.mcap')
    export.to_mcap(originals[:50], out)
    with open(out, 'rb') as stream:
        assert {chunk.compression for chunk in make_reader(stream).get_summary().chunk_indexes} == {'lz4'}
    with pytest.raises(ValueError, match='^compression: zstd needs the Python package zstandard'):
        export.to_mcap(originals[:50], str(tmp_path / 'y.mcap'), 'zstd')
