"""Bags built to hurt (issue 29): chunks that claim huge sizes, a topic carrying two message types. Every
reader (``cclog collect``, ``codecs``, ``plot --bag``, replay's reader) answers with one line naming the file,
or reads the topic's type and says what it skipped; never a traceback, never gigabytes."""
import os
import subprocess
import sys

import pytest

rosbag = pytest.importorskip('rosbag')
from cc_log.storage.bag import bag_reader, bagio  # noqa: E402
from cc_log.storage.bag.bag_salvage import MAX_CHUNK_BYTES  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SMALL = 'sequor_N2_anomalous_jerky_driving.bag'  # 486 kB, 271 messages on each of 5 topics
OTHER = '/odoX'  # a topic name as long as /odom: renamed to /odom in the bytes


def cclog(*args):
    return subprocess.run([sys.executable, os.path.join(ROOT, 'scripts', 'cclog')] + [str(a) for a in args],
                          capture_output=True, text=True, timeout=600)


def copy_bag(source, path, compression, rename=None):
    """``source`` written again to ``path`` with ``compression``; ``rename``: {topic: topic written instead}."""
    with rosbag.Bag(source) as bag_in, rosbag.Bag(str(path), 'w', compression=compression) as bag_out:
        for topic, raw, stamp, header in bag_in.read_messages(raw=True, return_connection_header=True):
            topic = (rename or {}).get(topic, topic)
            bag_out.write(topic, raw, stamp, raw=True, connection_header=dict(header, topic=topic))
    return str(path)


def claim_sizes(path, claimed):
    """Rewrite the ``size`` field of every LZ4 chunk header of the bag at ``path`` to ``claimed``."""
    data = bytearray(open(path, 'rb').read())
    at, count = 0, 0
    while True:
        at = data.find(b'compression=lz4', at)
        if at < 0:
            break
        field = data.find(b'\x09\x00\x00\x00size=', at)
        assert 0 < field - at < 64
        data[field + 9:field + 13] = int(claimed).to_bytes(4, 'little')
        at, count = field, count + 1
    assert count >= 1
    open(path, 'wb').write(bytes(data))
    return path


@pytest.fixture
def lz4_bag(real_bag, tmp_path):
    return copy_bag(real_bag(SMALL), tmp_path / 'small.bag', 'lz4')


def windows_of(real_bag, tmp_path, *options):
    """A directory of window files of the small bag (what ``cclog plot`` draws over a run)."""
    config = tmp_path / 'fast.yaml'
    config.write_text("triggers: [{name: fast, kind: rule, topic: /odom, type: nav_msgs/Odometry, "
                      "when: 'twist.twist.linear.x > 0.3'}]\n")
    windows = tmp_path / 'windows'
    result = cclog('replay', real_bag(SMALL), '--config', config, '--out', windows, '--pre', '1s', '--post', '1s',
                   *options)
    assert result.returncode == 0 and os.listdir(str(windows)), result.stderr[-2000:]
    return windows


def one_line_naming(result, path):
    assert result.returncode != 0 and 'Traceback' not in result.stderr, result.stderr[-2000:]
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and path in lines[0], result.stderr[-2000:]
    return lines[0]


@pytest.mark.parametrize('claimed', [MAX_CHUNK_BYTES + 1, 3 << 30, 100 << 20], ids=['cap', '3GB', 'ratio'])
def test_chunks_claiming_huge_sizes_are_refused_by_every_reader(real_bag, lz4_bag, tmp_path, claimed):
    assert list(bagio.read_messages(lz4_bag, ['/odom']))  # the bag as written reads
    hostile = claim_sizes(lz4_bag, claimed)
    for read in (lambda: list(bagio.read_messages(hostile, ['/odom'])),
                 lambda: list(bag_reader.read_raw(hostile, ['/odom'])),
                 lambda: list(bagio.read_raw(hostile, ['/odom']))):
        with pytest.raises(ValueError) as error:
            read()
        text = str(error.value)
        assert text.startswith(hostile + ': bag is truncated or damaged (chunk at byte ')
        assert 'declares %d bytes, more than ' % claimed in text and 'lz4, ' in text
        assert '\n' not in text
    out = tmp_path / 'vectors'
    one_line_naming(cclog('collect', hostile, '--topic', '/odom', '--out', out, '--window', '1s'), hostile)
    one_line_naming(cclog('codecs', hostile, '--topic', '/odom'), hostile)
    windows = windows_of(real_bag, tmp_path)
    one_line_naming(cclog('plot', windows, '--out', tmp_path / 'plot.png', '--bag', hostile, '--topic', '/odom'),
                    hostile)


@pytest.fixture
def two_types_bag(real_bag, tmp_path):
    """The small bag with /lin_acc's AccelStamped messages also on /odom (a second connection)."""
    path = copy_bag(real_bag(SMALL), tmp_path / 'two_types.bag', 'none', {'/lin_acc': OTHER})
    data = open(path, 'rb').read()
    assert OTHER.encode() in data
    open(path, 'wb').write(data.replace(OTHER.encode(), b'/odom'))
    with rosbag.Bag(path) as bag:
        assert sorted(c.datatype for c in bag._connections.values() if c.topic == '/odom') == [
            'geometry_msgs/AccelStamped', 'nav_msgs/Odometry']
    return path


def test_a_topic_of_two_types_is_read_as_its_first_type(real_bag, two_types_bag, tmp_path, capfd):
    records = list(bagio.read_messages(two_types_bag, ['/odom']))
    assert len(records) == 271 and all(r.msg._type == 'nav_msgs/Odometry' for r in records)
    warning = capfd.readouterr().err.strip().splitlines()
    assert warning == ['warning: %s: read as /odom nav_msgs/Odometry; skipped 271 geometry_msgs/AccelStamped on /odom'
                       % two_types_bag]
    out = tmp_path / 'vectors'
    result = cclog('collect', two_types_bag, '--topic', '/odom', '--out', out, '--window', '1s')
    assert result.returncode == 0 and 'Traceback' not in result.stderr, result.stderr[-2000:]
    assert 'skipped 271 geometry_msgs/AccelStamped on /odom' in result.stderr
    assert os.listdir(str(out / 'nominal'))
    result = cclog('codecs', two_types_bag, '--topic', '/odom')
    assert result.returncode == 0 and 'Traceback' not in result.stderr, result.stderr[-2000:]
    assert result.stdout.startswith('271 messages')
    windows = windows_of(real_bag, tmp_path)
    result = cclog('plot', windows, '--out', tmp_path / 'plot.png', '--bag', two_types_bag, '--topic', '/odom')
    assert result.returncode == 0 and 'Traceback' not in result.stderr, result.stderr[-2000:]
    assert os.path.getsize(str(tmp_path / 'plot.png')) > 0


def test_a_damaged_lz4_chunk_is_one_line_naming_the_file(lz4_bag, tmp_path):
    data = bytearray(open(lz4_bag, 'rb').read())
    at = data.find(b'compression=lz4') + 200
    data[at:at + 2000] = b'\xff' * 2000
    damaged = str(tmp_path / 'damaged.bag')
    open(damaged, 'wb').write(bytes(data))
    with pytest.raises(ValueError) as error:
        list(bagio.read_messages(damaged, ['/odom']))
    assert str(error.value).startswith(damaged + ': bag is truncated or damaged (chunk at byte ')
    one_line_naming(cclog('codecs', damaged, '--topic', '/odom'), damaged)


def test_a_bag_lz4_window_file_claiming_huge_chunks_is_refused(real_bag, tmp_path):
    windows = windows_of(real_bag, tmp_path, '--format', 'bag-lz4')
    window = str(windows / sorted(os.listdir(str(windows)))[0])
    claim_sizes(window, 3 << 30)
    line = one_line_naming(cclog('info', window), window)
    assert 'bag is truncated or damaged (chunk at byte ' in line and 'declares %d bytes' % (3 << 30) in line


ZEROS = 45000000  # bytes of zeros per bz2 stream of the bomb (one stream: 50 bytes)
BOMB_STREAMS = 48  # 2.16 GB once inflated, 2.4 kB stored


def bz2_bomb(source, path):
    """``source`` (a bag) written again to ``path`` in bz2 chunks, each followed by bz2 streams of 2.16 GB of zeros
    (its declared size, its index and its records as they were: ``bz2.decompress`` inflates the streams too)."""
    import bz2
    import types
    from cc_log.storage.bag import bag_writer
    bomb = bz2.compress(bytes(ZEROS)) * BOMB_STREAMS
    real = types.SimpleNamespace(compress=lambda data: bz2.compress(data) + bomb)
    with rosbag.Bag(source) as bag_in, open(str(path), 'wb') as out:
        writer = bag_writer.BagStream(out, compression='bz2')
        original, bag_writer.bz2 = bag_writer.bz2, real
        try:
            for topic, raw, stamp, header in bag_in.read_messages(raw=True, return_connection_header=True):
                writer.write(topic, stamp.secs, stamp.nsecs, raw[1], header)
            writer.close()
        finally:
            bag_writer.bz2 = original
    return str(path)


def measured(*args):
    """``cclog *args`` run in a child of a child: (result, the grandchild's peak RSS in MB, seconds). Its address
    space is capped at 4 GB so that an unbounded reader fails rather than takes the machine."""
    import json
    import time
    probe = ('import json, resource, subprocess, sys\n'
             'resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))\n'
             'r = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n'
             'print(json.dumps([r.returncode, r.stdout[-4000:], r.stderr[-4000:], '
             'resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0]))\n')
    start = time.monotonic()
    outer = subprocess.run([sys.executable, '-c', probe, sys.executable, os.path.join(ROOT, 'scripts', 'cclog')]
                           + [str(a) for a in args], capture_output=True, text=True, timeout=600)
    seconds = time.monotonic() - start
    code, out, err, peak_mb = json.loads(outer.stdout)
    return subprocess.CompletedProcess(args, code, out, err), peak_mb, seconds


def test_a_bz2_chunk_inflating_to_gigabytes_is_refused_in_bounded_memory_and_time(real_bag, tmp_path):
    windows = windows_of(real_bag, tmp_path, '--format', 'bag-lz4')
    window = str(windows / sorted(os.listdir(str(windows)))[0])
    (tmp_path / 'hostile').mkdir()
    hostile = bz2_bomb(window, tmp_path / 'hostile' / os.path.basename(window))  # the window's name, bz2 bombs
    assert os.path.getsize(hostile) < 2 * os.path.getsize(window) + 100000
    export = ('export', hostile, '--to', 'csv', '--out', tmp_path / 'out.csv')
    for args in (('cat', hostile), ('codecs', hostile, '--topic', '/odom'), export, ('stats', tmp_path / 'hostile')):
        result, peak_mb, seconds = measured(*args)
        if args[0] != 'stats':  # stats reads the metadata's chunk only (bag_reader: inflated up to its size)
            line = one_line_naming(result, hostile)
            assert 'inflates to more' in line, line
        assert peak_mb < 600 and seconds < 30, (args, peak_mb, seconds)


def test_a_json_xz_window_declaring_millions_of_messages_is_refused_in_bounded_memory_and_time(real_bag, tmp_path):
    import json
    import lzma
    windows = windows_of(real_bag, tmp_path, '--format', 'json-xz')
    window = str(windows / sorted(os.listdir(str(windows)))[0])
    doc = json.loads(lzma.decompress(open(window, 'rb').read()))
    # one section of constant fields declaring 5 M messages (its header stamps: no stamps list to pay for them)
    section = next(section for section in doc['topics'] if section['stamps'] == 'header.stamp')
    section['constant'].update((key, values[0]) for key, values in section.pop('columns').items())
    section.update(columns={}, delta=[], count=5000000)
    doc['topics'] = [section]
    doc.pop('order', None)
    (tmp_path / 'hostile').mkdir()
    hostile = str(tmp_path / 'hostile' / os.path.basename(window))
    open(hostile, 'wb').write(lzma.compress(json.dumps(doc).encode()))
    assert os.path.getsize(hostile) < 20000
    for args in (('info', hostile), ('info', '--full', hostile), ('cat', hostile)):
        result, peak_mb, seconds = measured(*args)
        line = one_line_naming(result, hostile)
        assert 'declare 5000000 messages, more than' in line, line
        assert peak_mb < 600 and seconds < 30, (args, peak_mb, seconds)
