"""formats.bag_writer writes the bag rosbag writes for the same messages, byte for byte."""
import pytest
from conftest import real_data

from cc_log.storage.bag import bag_reader
from cc_log.base import raw_message
from cc_log.storage.formats import bag_lz4
from cc_log.storage.bag import bag_writer

rosbag = pytest.importorskip('rosbag')

HUSKY = 'husky_outdoor_2015.bag'
TOPICS = ['/husky_velocity_controller/odom', '/imu/data']


def rosbag_bytes(path, messages, headers, chunk_threshold=bag_writer.CHUNK_THRESHOLD, compression='lz4'):
    """What rosbag writes for ``messages`` (topic, secs, nsecs, bytes) with the connection ``headers``."""
    import genpy
    bag = rosbag.Bag(str(path), 'w', compression=compression, chunk_threshold=chunk_threshold)
    for topic, secs, nsecs, data in messages:
        header = headers[topic]
        bag.write(topic, (header['type'], data, header['md5sum'], raw_message.message_class(header)),
                  genpy.Time(secs, nsecs), raw=True, connection_header=header)
    bag.close()
    with open(str(path), 'rb') as stream:
        return stream.read()


@pytest.fixture(scope='module')
def husky_messages():
    """Every odometry and IMU message of the Husky bag: (topic, secs, nsecs, bytes), and the headers by topic."""
    messages, headers = [], {}
    for record in bag_reader.read_raw(real_data(HUSKY), TOPICS):
        headers.setdefault(record.topic, dict(record.connection, topic=record.topic))
        messages.append((record.topic,) + bag_lz4.bag_stamp(record.stamp) + (record.raw,))
    return messages, headers


def test_the_whole_husky_bag_as_rosbag_writes_it(husky_messages, tmp_path):
    messages, headers = husky_messages
    assert len(messages) == 15817
    ours = bag_writer.bag_bytes(messages, headers)
    assert ours == rosbag_bytes(tmp_path / 'rosbag.bag', messages, headers)
    with rosbag.Bag(str(tmp_path / 'rosbag.bag')) as bag:
        assert bag.get_message_count() == len(messages) and len(bag._chunks) > 1  # several chunks


@pytest.mark.parametrize('compression', ['bz2', 'none'])
def test_bz2_and_uncompressed_chunks_as_rosbag_writes_them(husky_messages, tmp_path, compression):
    messages, headers = husky_messages
    sample = messages[:3000]
    ours = bag_writer.bag_bytes(sample, headers, chunk_threshold=200000, compression=compression)
    assert ours == rosbag_bytes(tmp_path / 'rosbag.bag', sample, headers, 200000, compression)
    with rosbag.Bag(str(tmp_path / 'rosbag.bag')) as bag:
        assert len(bag._chunks) > 1 and bag.get_compression_info().compression == compression


def test_an_unknown_compression_is_refused(husky_messages):
    messages, headers = husky_messages
    with pytest.raises(ValueError, match="compression: 'zstd' is not one of: lz4, bz2, none"):
        bag_writer.bag_bytes(messages[:10], headers, compression='zstd')


@pytest.mark.parametrize('threshold', [0, 3000])
def test_out_of_order_and_equal_times_in_small_chunks(husky_messages, tmp_path, threshold):
    # rosbag keeps each chunk's index sorted by time, ties in write order; chunks close past the threshold
    messages, headers = husky_messages
    sample = list(reversed(messages[:300])) + messages[300:600]
    sample += [(topic, 100, 5, data) for topic, _, _, data in messages[600:640]]  # forty at one time
    sample += [(TOPICS[1], 0, 0, messages[1][3]), (TOPICS[0], 4294967295, 999999999, messages[0][3])]
    ours = bag_writer.bag_bytes(sample, headers, chunk_threshold=threshold)
    assert ours == rosbag_bytes(tmp_path / 'rosbag.bag', sample, headers, chunk_threshold=threshold)


def test_rosbag_reads_every_message_with_its_connection_header(husky_messages, tmp_path):
    messages, headers = husky_messages
    headers = dict(headers)
    headers[TOPICS[0]] = dict(headers[TOPICS[0]], callerid='/husky_node', latching='1')
    path = tmp_path / 'ours.bag'
    path.write_bytes(bag_writer.bag_bytes(messages[:2000], headers, chunk_threshold=50000))
    with rosbag.Bag(str(path)) as bag:
        read = [(topic, t.secs, t.nsecs, raw[1], conn) for topic, raw, t, conn in
                bag.read_messages(raw=True, return_connection_header=True)]
    expected = sorted(messages[:2000], key=lambda message: (message[1], message[2]))
    assert [item[:4] for item in read] == [tuple(message) for message in expected]
    assert all(conn == dict((key, value.encode()) for key, value in headers[topic].items())
               for topic, _, _, _, conn in read)


def test_bad_times_and_no_messages_are_refused(husky_messages):
    messages, headers = husky_messages
    topic, _, _, data = messages[0]
    with pytest.raises(ValueError, match='cannot be a bag time'):
        bag_writer.bag_bytes([(topic, 1 << 32, 0, data)], headers)
    with pytest.raises(ValueError, match='cannot be a bag time'):
        bag_writer.bag_bytes([(topic, 1, -1, data)], headers)
    with pytest.raises(ValueError, match='at least one message'):
        bag_writer.bag_bytes([], headers)


@pytest.fixture
def roslz4_calls(monkeypatch):
    """The sizes of the chunks roslz4 compresses (its ``compress``, counted and then called)."""
    import roslz4
    calls, compress = [], roslz4.compress

    def counted(data):
        calls.append(len(data))
        return compress(data)
    monkeypatch.setattr(roslz4, 'compress', counted)
    return calls


def test_heavy_chunks_are_lz4_frames_as_roslz4_writes_them_without_roslz4(husky_messages, tmp_path, roslz4_calls):
    # images and clouds: each ~0.9 MB message closes a chunk of its own; roslz4 compresses only the small last one
    pytest.importorskip('lz4.frame')
    import random
    messages, headers = husky_messages
    headers = dict(headers, **{'/camera': dict(headers[TOPICS[1]], topic='/camera')})
    rng = random.Random(43)
    sample = []
    for index, (topic, secs, nsecs, data) in enumerate(messages[:600]):
        sample.append((topic, secs, nsecs, data))
        if index % 50 == 0:  # a noisy image (LZ4 keeps it as it is) or a flat one (LZ4 shrinks it)
            image = rng.randbytes(921600) if index % 100 else bytes(921600)
            sample.append(('/camera', secs, nsecs, bytearray(image) if index % 150 == 0 else image))
    ours = bag_writer.bag_bytes(sample, headers)
    heavy = sum(1 for message in sample if message[0] == '/camera')
    assert len(roslz4_calls) == 1 and roslz4_calls[0] <= bag_writer.LZ4_FRAME_MIN  # the tail after the last image
    as_bytes = [message[:3] + (bytes(message[3]),) for message in sample]  # rosbag takes no bytearray
    assert ours == rosbag_bytes(tmp_path / 'rosbag.bag', as_bytes, headers)
    with rosbag.Bag(str(tmp_path / 'rosbag.bag')) as bag:
        assert len(bag._chunks) == heavy + 1
        assert [raw[1] for _, raw, _ in bag.read_messages(topics=['/camera'], raw=True)] == \
            [bytes(message[3]) for message in sample if message[0] == '/camera']


@pytest.mark.parametrize('size', [1, 65536, bag_writer.LZ4_FRAME_MIN, bag_writer.LZ4_FRAME_MIN + 1, 768 * 1024,
                                  1 << 20, (1 << 20) + 1, 3 * (1 << 20) + 7])
def test_lz4_frame_is_roslz4s_frame_byte_for_byte(size, monkeypatch):
    import os
    import roslz4
    for data in (os.urandom(size), bytes(size), b'cc_log' * (size // 6) + os.urandom(size % 6)):
        frame = bag_writer.lz4_frame(data)
        assert frame == roslz4.compress(data) and roslz4.decompress(frame) == data
        assert bag_writer.lz4_frame(memoryview(data)) == frame
        monkeypatch.setattr(bag_writer, '_lz4_frame', None)  # as without python3-lz4: roslz4
        assert bag_writer.lz4_frame(data) == frame
        monkeypatch.undo()


def heavy_window(tmp_path, count=6):
    """A bag-lz4 window of ``count`` 0.9 MB noisy blobs written a part at a time: (path, records)."""
    import os
    from std_msgs.msg import UInt8MultiArray
    from cc_log.base.records import Record
    connection = raw_message.class_header('/blob', UInt8MultiArray)
    blobs = [raw_message.serialized(UInt8MultiArray(data=os.urandom(900000))) for _ in range(count)]
    records = [Record(100.0 + index / 10.0, '/blob', None, 0, blob, connection) for index, blob in enumerate(blobs)]
    path = tmp_path / 'window.bag'
    with open(str(path), 'w+b') as stream:
        window = bag_lz4.WindowStream(stream)
        window.append(records[:count // 2], {'codec': bag_lz4.CODEC})
        window.append(records[count // 2:], {'codec': bag_lz4.CODEC})
        window.finish({'codec': bag_lz4.CODEC})
    return path, records


def test_a_window_reads_each_payload_once_to_compress_it_not_again_for_its_crc(tmp_path, monkeypatch):
    # the records' crc32 covers their topics, stamps and lengths; their bytes are covered by the LZ4 frame of
    # their chunk (its XXH32 content checksum), which roslz4 checks as rosbag reads the chunk
    import types
    import zlib
    payload_crcs = []

    def crc32(data, value=0):
        if len(data) > 100000:
            payload_crcs.append(len(data))
        return zlib.crc32(data, value)
    monkeypatch.setattr(bag_lz4, 'zlib', types.SimpleNamespace(crc32=crc32))
    path, records = heavy_window(tmp_path)
    assert payload_crcs == []
    monkeypatch.undo()
    metadata, back = bag_lz4.read(str(path))  # the crc32 of every record checked
    assert metadata['layout'] == 4
    assert [(record.stamp, bytes(record.raw)) for record in back] == [(record.stamp, record.raw) for record in records]


def test_a_flipped_bit_in_a_payload_on_disk_is_refused_by_its_chunks_lz4_checksum(tmp_path):
    path, records = heavy_window(tmp_path)
    data = bytearray(path.read_bytes())
    at = data.find(records[4].raw[500000:500064])  # noise: LZ4 keeps it as literals
    assert at > 0
    data[at + 10] ^= 0x10
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match='corrupt or truncated bag') as error:
        bag_lz4.read(str(path))
    assert str(path) in str(error.value)


def test_the_records_crc_of_layout_3_still_covers_the_payloads():
    headers = {'/a': {'type': 't/T', 'md5sum': '0' * 32, 'message_definition': 'uint8[] data\n'}}
    records = [('/a', 1.5, b'\x01\x00\x00\x00\x07')]
    changed = [('/a', 1.5, b'\x01\x00\x00\x00\x08')]
    assert bag_lz4.records_crc(['/a'], headers, records, 3) != bag_lz4.records_crc(['/a'], headers, changed, 3)
    assert bag_lz4.records_crc(['/a'], headers, records, 4) == bag_lz4.records_crc(['/a'], headers, changed, 4)
    moved = [('/a', 1.25, b'\x01\x00\x00\x00\x07')]
    assert bag_lz4.records_crc(['/a'], headers, records, 4) != bag_lz4.records_crc(['/a'], headers, moved, 4)
