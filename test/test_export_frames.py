"""``cclog export --to png`` (export.to_frames): camera frames of windows as PNG/JPEG files, read back with Pillow."""
import io
import json
import os
import struct

import numpy
import pytest
from conftest import cclog
from PIL import Image as PILImage
from sensor_msgs.msg import CompressedImage, Image

from cc_log.offline import export
from cc_log.storage import log_format
from cc_log import sim
from cc_log.base.records import LogWindow, Record

CAMERA = sim.CAMERA_TOPIC


@pytest.fixture(scope='module')
def simulated():
    """Two seconds of the simulated BWIBot with its camera: records of odometry and 30 frames."""
    simulator = sim.Simulator(sim.SimConfig(minutes=2.0 / 60, anomalies=0, camera=True, seed=5))
    return [Record(stamp, topic, msg) for topic, stamp, msg in simulator.messages()]


def pixels_of(path):
    return numpy.asarray(PILImage.open(str(path)))


def image(encoding, array, big_endian=False, padding=0):
    """A sensor_msgs/Image of ``array`` (height x width [x channels]) with ``padding`` bytes after each row."""
    height, width = array.shape[:2]
    rows = array.astype(array.dtype.newbyteorder('>' if big_endian else '<')).reshape(height, -1).view('u1')
    data = numpy.hstack([rows, numpy.full((height, padding), 7, 'u1')]).tobytes()
    return Image(height=height, width=width, encoding=encoding, is_bigendian=int(big_endian),
                 step=rows.shape[1] + padding, data=data)


@pytest.mark.parametrize('fmt', ['json-xz', 'bag-lz4'])
def test_every_frame_of_the_windows_is_a_png_of_its_pixels(simulated, tmp_path, fmt):
    paths = [log_format.write_window(LogWindow(part, []), str(tmp_path / 'windows'), fmt)[0]
             for part in (simulated[:len(simulated) // 2], simulated[len(simulated) // 2:])]
    records = sorted((r for path in paths for r in log_format.read_window(path)[1]), key=lambda r: r.stamp)
    files = export.to_frames(records, str(tmp_path / 'frames'))
    frames = [record for record in simulated if record.topic == CAMERA]
    assert len(files) == len(frames) == 30
    for path, record in zip(files, frames):
        assert os.path.basename(path) == 'camera_image_raw_%.6f.png' % record.stamp
        expected = numpy.frombuffer(record.msg.data, numpy.uint8).reshape(240, 320, 3)
        assert numpy.array_equal(pixels_of(path), expected)


def test_each_encoding_keeps_its_values():
    rng = numpy.random.default_rng(1)
    rgb = rng.integers(0, 256, (5, 7, 3), dtype=numpy.uint8)
    depth = rng.integers(0, 65536, (5, 7), dtype=numpy.uint16)
    cases = [(image('rgb8', rgb, padding=3), rgb), (image('bgr8', rgb[:, :, ::-1].copy()), rgb),
             (image('mono8', rgb[:, :, 0].copy()), rgb[:, :, 0]),
             (image('rgba8', numpy.dstack([rgb, rgb[:, :, :1]])), numpy.dstack([rgb, rgb[:, :, :1]])),
             (image('16UC1', depth), depth), (image('16UC1', depth, big_endian=True, padding=2), depth),
             (image('mono16', depth), depth)]
    for msg, expected in cases:
        data, extension = export.frame_file(msg)
        assert extension == 'png' and data.startswith(export.PNG_MAGIC)
        read = numpy.asarray(PILImage.open(io.BytesIO(data)))
        assert data[24] == 8 * expected.dtype.itemsize, msg.encoding             # IHDR bit depth
        assert numpy.array_equal(read, expected), msg.encoding
    metres = numpy.array([[0.5, 1.25, float('nan')], [-1.0, 70.0, 0.0015]], dtype=numpy.float32)
    read = numpy.asarray(PILImage.open(io.BytesIO(export.frame_file(image('32FC1', metres))[0])))
    assert read.tolist() == [[500, 1250, 0], [0, 65535, 2]]                  # 16-bit millimetres


def test_a_compressed_image_is_written_as_its_own_bytes(tmp_path):
    buffer = io.BytesIO()
    PILImage.fromarray(numpy.full((8, 8, 3), 90, numpy.uint8)).save(buffer, format='JPEG')
    jpeg = buffer.getvalue()
    png = export.png_file(numpy.arange(12, dtype=numpy.uint16).reshape(3, 4))
    depth_header = struct.pack('<i2f', 0, 1.0, 2.0)   # compressed_depth_image_transport's 12-byte header
    records = [Record(1.0, '/cam/compressed', CompressedImage(format='jpeg', data=jpeg)),
               Record(2.0, '/depth/compressedDepth', CompressedImage(format='16UC1; compressedDepth png',
                                                                     data=depth_header + png)),
               Record(3.0, '/cam/compressed', CompressedImage(format='h264', data=b'\x00\x00\x00\x01'))]
    skipped = {}
    files = export.to_frames(records, str(tmp_path), skipped)
    assert [os.path.basename(path) for path in files] == ['cam_compressed_1.000000.jpg',
                                                          'depth_compressedDepth_2.000000.png']
    assert open(files[0], 'rb').read() == jpeg and open(files[1], 'rb').read() == png
    assert skipped == {'compressed format h264 is neither JPEG nor PNG': 1}
    with pytest.raises(ValueError, match=r'^/cam/compressed at 3.000000: compressed format h264 is neither'):
        export.to_frames(records[2:], str(tmp_path))


def test_names_never_carry_a_path_and_never_overwrite(tmp_path):
    msg = image('mono8', numpy.zeros((2, 2), numpy.uint8))
    records = [Record(5.0, '/../../etc/passwd', msg), Record(5.0, '/../../etc/passwd', msg),
               Record(6.0, '/', msg), Record(7.0, '/a b/c:d', msg)]
    (tmp_path / 'etc_passwd_5.000000.png').write_bytes(b'mine')
    files = export.to_frames(records, str(tmp_path))
    assert [os.path.basename(path) for path in files] == [
        'etc_passwd_5.000000-2.png', 'etc_passwd_5.000000-3.png', 'topic_6.000000.png', 'a_b_c_d_7.000000.png']
    assert all(os.path.dirname(path) == str(tmp_path) for path in files)
    assert (tmp_path / 'etc_passwd_5.000000.png').read_bytes() == b'mine'


def test_bad_frames_are_counted_not_fatal(tmp_path):
    good = image('rgb8', numpy.zeros((2, 2, 3), numpy.uint8))
    short = Image(height=4, width=4, encoding='rgb8', step=12, data=b'\x00' * 10)
    yuv = Image(height=1, width=1, encoding='yuv422', step=2, data=b'\x00\x00')
    records = [Record(1.0, '/c', good), Record(2.0, '/c', yuv), Record(3.0, '/c', short)]
    skipped = {}
    assert len(export.to_frames(records, str(tmp_path), skipped)) == 1
    assert skipped == {'encoding yuv422 is not supported': 1,
                       '4x4 rgb8 with step 12 does not fit 10 bytes of data': 1}


def test_cclog_export_to_png_prints_encodings_and_topics_with_their_terminal_escapes_shown(tmp_path):
    """Issue 42 item 20: an image's encoding and its topic, read from a window file, reach the terminal through
    safe_input.printable (in the skipped frames' reasons and the summary), never raw."""
    hostile = '\x1b]0;owned\x07\x1b[2J\u202e'
    good = image('rgb8', numpy.zeros((2, 2, 3), numpy.uint8))
    odd = Image(height=1, width=1, encoding='yuv' + hostile, step=2, data=b'\x00\x00')
    log_format.write_window(LogWindow([Record(1.0, '/c' + hostile, good), Record(2.0, '/c' + hostile, odd)], []),
                            str(tmp_path / 'windows'), 'json-xz')
    result = cclog('export', tmp_path / 'windows', '--to', 'png', '--out', tmp_path / 'frames')
    assert result.returncode == 0, result.stderr
    assert not any(char in result.stdout for char in '\x1b\x07\u202e'), repr(result.stdout)
    shown = '\\x1b]0;owned\\x07\\x1b[2J\\u202e'
    assert '1 frame(s) of /c%s -> ' % shown in result.stdout, result.stdout
    assert 'skipped 1 frame(s): encoding yuv%s is not supported' % shown in result.stdout, result.stdout


def test_cclog_export_to_png(simulated, tmp_path):
    log_format.write_window(LogWindow(simulated, []), str(tmp_path / 'windows'), 'json-xz')
    result = cclog('export', tmp_path / 'windows', '--to', 'png', '--out', tmp_path / 'frames', '--json')
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary['frames'] == 30 and summary['topics'] == [CAMERA] and summary['skipped'] == {}
    assert sorted(os.listdir(str(tmp_path / 'frames'))) == sorted(os.path.basename(f) for f in summary['files'])
    odom_only = cclog('export', tmp_path / 'windows', '--to', 'png', '--out', tmp_path / 'none', '--topic', '/odom')
    assert odom_only.returncode == 1 and odom_only.stderr.strip().count('\n') == 0
    assert 'no sensor_msgs/Image or CompressedImage messages' in odom_only.stderr


def test_frames_are_written_by_pillow_no_larger_than_its_own_png(simulated):
    frames = [r.msg for r in simulated if r.topic == CAMERA][:5]
    depth = numpy.random.default_rng(2).integers(400, 5000, (48, 64), dtype=numpy.uint16)
    for msg in frames + [image('16UC1', depth)]:
        data, extension = export.frame_file(msg)
        pixels = export.image_pixels(msg)
        own = io.BytesIO()
        PILImage.fromarray(pixels).save(own, format='PNG')
        assert extension == 'png' and numpy.array_equal(numpy.asarray(PILImage.open(io.BytesIO(data))), pixels)
        assert len(data) <= len(own.getvalue()), (msg.encoding, len(data), len(own.getvalue()))
