"""The json-xz writer reading fields in bulk from the serialized bytes writes the same window files as the
writer that decoded every message with genpy: the document text of every window (so the same .json.xz bytes)
is compared with sha256 digests of the text the writer at main's commit 2fe8544 made of the same records
(``window_text``: ``raw_message.decoded_records``, then ``document`` and ``dumps``), on real bags (Husky
odometry + IMU + /fix, F1/10, ICE-lab, the Pioneer laser + /tf, ALFA) and on crafted records (NaN, inf, -0.0,
float32 fields, changing frame ids, empty arrays, unicode and non-UTF-8 strings, repeated stamps, out-of-range
nanoseconds, truncated messages), lossless and with ``precision``."""
import hashlib
import lzma
import math
import os
import struct

import pytest

from cc_log.storage.bag import bag_reader
from cc_log.base.raw_message import serialized
from cc_log.storage import log_format
from cc_log.base import msg_codec, raw_message
from cc_log.storage.formats import json_deltas, json_xz
from cc_log.base.records import LogWindow, Record

REAL = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..', 'shared', 'data', 'real'))
HUSKY = ('husky_outdoor_2015.bag', ('/husky_velocity_controller/odom', '/imu/data', '/fix'))
BAGS = (HUSKY, ('f1tenth_DS1.bag', ('/odom',)), ('icelab_normal_plan.bag', ('/odom',)),
        ('socspioneer_trace0.bag', ('/base_scan', '/odom', '/tf')),
        ('alfa_carbonZ_engine_failure.bag',
         ('/failure_status/engines', '/mavros/imu/data', '/mavros/local_position/odom')))
WINDOW = 600  # records per window; three windows per bag: its start, middle and end
PRECISION = {'pose.pose.position.*': 1e-4, 'twist.twist.*': 1e-4, '*orientation*': 1e-5, '*velocity*': 1e-5,
             'range': 0.01, 'values': 0.5}
META = {'trigger': 'test', 'start': 0.0}


def window_text(module, records, metadata):
    """The document text ``log_format.write_window`` has ``module`` write of ``records`` (decoded as it does),
    without the topic sections' ``connection`` (the publishers' callerid and latching, added after 2fe8544)."""
    records, undecodable = getattr(module, 'decoded_records', raw_message.decoded_records)(records)
    meta = dict(metadata)
    if undecodable:
        meta['undecodable'] = undecodable
    doc = module.document(records, meta)
    for section in doc['topics']:
        section.pop('connection', None)
    return module.dumps(doc)


def real_windows():
    """``[(name, records)]``: three windows of serialized records of each real bag (start, middle, end)."""
    windows = []
    for name, topics in BAGS:
        path = os.path.join(REAL, name)
        if not os.path.exists(path):
            pytest.fail('real data missing: %s (tests read ../shared/data/real/)' % path)
        records = list(bag_reader.read_raw(path, list(topics)))
        for part, start in (('start', 0), ('middle', len(records) // 2), ('end', max(0, len(records) - WINDOW))):
            windows.append(('%s %s' % (name, part), records[start:start + WINDOW]))
    return windows


def connection(cls):
    return {'type': cls._type, 'md5sum': cls._md5sum, 'message_definition': cls._full_text}


CUSTOM = 'cc_log_test/Fields'
CUSTOM_DEFINITION = '''Header header
time when
duration took
bool flag
bool[2] flags
byte small
char letter
int16[2] pair
uint8[4] code
float32 level
float32[3] gains
float64[2] span
string note
uint64 big
int64 signed
================================================================================
MSG: std_msgs/Header
uint32 seq
time stamp
string frame_id
'''


def crafted_windows():
    """``[(name, records)]`` of crafted messages, as serialized bytes (and some already decoded)."""
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Imu, LaserScan, Range
    from std_msgs.msg import Bool, ColorRGBA
    custom = msg_codec.generated_class(CUSTOM, CUSTOM_DEFINITION)
    specials = [float('nan'), float('inf'), float('-inf'), -0.0, 0.0, 5e-324, 1.7976931348623157e308, 0.1, 1e22]
    odometry, imu, ranges, custom_msgs, scans, bools, colors = [], [], [], [], [], [], []
    for i in range(120):
        msg = Odometry()
        msg.header.seq = i
        msg.header.stamp.secs, msg.header.stamp.nsecs = 100 + i // 10, (i % 10) * 100000000 + 7
        msg.header.frame_id = 'odom' if i < 60 else ('map' if i % 3 else 'ödom ☃')
        msg.child_frame_id = '' if i % 7 else 'base_link'
        msg.pose.pose.position.x = 1.0 + i * 0.01 if i % 40 else specials[i // 40 % len(specials)]
        msg.pose.pose.position.y = 0.1 * (i // 5)
        msg.pose.pose.position.z = -0.0 if i < 100 else 0.0
        msg.pose.pose.orientation.w = 1.0
        msg.twist.twist.linear.x = specials[i % len(specials)]
        msg.twist.twist.angular.z = math.sin(i) * 1e-3
        msg.pose.covariance = [float(k) for k in range(36)]
        if i in (3, 4):
            msg.pose.covariance = [float('nan')] * 36
        if i == 5:
            msg.twist.covariance = [-0.0] + [float('inf')] * 35
        odometry.append(msg)
        m = Imu()
        m.header.stamp.secs, m.header.stamp.nsecs = 100, i * 1000
        m.header.frame_id = 'imu'
        m.angular_velocity.x = i * 1e-5 + 1e-9
        m.linear_acceleration.z = 9.81 + (i % 3) * 1e-3
        m.orientation_covariance = [-1.0] + [0.0] * 8
        imu.append(m)
        r = Range()
        r.header.stamp.secs = 5
        r.header.frame_id = 'sonar'
        r.radiation_type = i % 2
        r.field_of_view, r.min_range, r.max_range = 0.1, 0.02, 4.0 + i * 0.1
        r.range = [float('nan'), float('inf'), 1.0 / 3, 0.3 + i * 0.01][i % 4]
        ranges.append(r)
        c = custom()
        c.header.stamp.secs, c.header.stamp.nsecs = 7, 999999999
        c.header.frame_id = 'x' * (i % 3)
        c.when.secs, c.when.nsecs = 1 << 31, i
        c.took.secs, c.took.nsecs = -5 + i, 10
        c.flag, c.flags = bool(i % 2), [True, bool(i % 3)]
        c.small, c.letter, c.pair, c.code = -i % 100 - 50, i % 256, [-i, i], bytes([i % 256, 0, 255, 1])
        c.level, c.gains = 0.1 + i, [0.1, float('nan'), 3.4028234663852886e38 if i % 2 else 1e-45]
        c.span = [1e300 * i, -0.0]
        c.note = ['', 'plain', 'ünïcödé ✓', '😀'][i % 4]
        c.big, c.signed = (1 << 64) - 1 - i, -(1 << 62) + i
        custom_msgs.append(c)
        s = LaserScan()
        s.header.frame_id = 'laser'
        s.ranges = [] if i % 2 else [1.0, float('inf'), 0.5]
        s.intensities = []
        scans.append(s)
        bools.append(Bool(data=bool(i % 5 == 0)))
        colors.append(ColorRGBA(r=0.2, g=0.4 + i, b=float('nan'), a=-0.0))
    records = []
    for i in range(120):
        for topic, msg, offset in (('/odom', odometry[i], 0.0), ('/imu', imu[i], 0.0), ('/range', ranges[i], 0.5),
                                   ('/custom', custom_msgs[i], 0.25), ('/scan', scans[i], 0.0),
                                   ('/flag', bools[i], 0.0), ('/color', colors[i], 0.0)):
            stamp = msg.header.stamp.to_sec() + offset if hasattr(msg, 'header') else 100.0 + i // 4
            records.append(Record(stamp, topic, None, 0, serialized(msg), connection(type(msg))))
    odom = [record for record in records if record.topic == '/odom']
    broken = []
    for i, record in enumerate(odom[:40]):
        raw = bytearray(record.raw)
        if i % 8 == 1:
            struct.pack_into('<I', raw, 8, 1500000000)  # nanoseconds beyond a second
        elif i % 8 == 2:
            raw = raw[:100]  # truncated: cannot be decoded
        elif i % 8 == 3:
            raw[16:20] = b'\xff\xfeod'  # frame_id not UTF-8 ('odom' -> 4 bytes, the same length)
        elif i % 8 == 4:
            raw += b'trailing'  # ignored as genpy does
        elif i % 8 == 5:
            raw = raw[:-4]  # the last covariance cut: cannot be decoded
        broken.append(record._replace(raw=bytes(raw)))
    decoded = [raw_message.decoded(record) if i % 3 == 0 else record for i, record in enumerate(odom[:30])]
    imu_records = [record for record in records if record.topic == '/imu']
    shuffled = imu_records[:10][::-1] + odom[:10]
    return [('crafted all', records), ('crafted broken odometry', broken),
            ('crafted half decoded', decoded), ('crafted out of order', shuffled),
            ('crafted one record', odom[:1]), ('crafted two records', imu_records[:2])]


def digests(module, windows):
    """``{(window, lossless or precision): sha256 of the text}``."""
    out = {}
    for name, records in windows:
        for mode, meta in (('lossless', META), ('precision', dict(META, precision=PRECISION))):
            text = window_text(module, records, meta)
            out['%s, %s' % (name, mode)] = hashlib.sha256(text.encode('utf-8')).hexdigest()[:16]
    return out


#: sha256 (first 16 hex digits) of the document text the writer at 2fe8544 made (``digests(<that module>, ...)``).
EXPECTED = {
    'husky_outdoor_2015.bag start, lossless': 'e19aea84af098b2d',
    'husky_outdoor_2015.bag start, precision': '3613614f3e02416b',
    'husky_outdoor_2015.bag middle, lossless': '0674270cf6979ccf',
    'husky_outdoor_2015.bag middle, precision': '5f99c07fc8ec9939',
    'husky_outdoor_2015.bag end, lossless': 'b2ae6eea56c1fb88',
    'husky_outdoor_2015.bag end, precision': 'e0788cfb16c331a5',
    'f1tenth_DS1.bag start, lossless': 'c73fa73a2017e433',
    'f1tenth_DS1.bag start, precision': '5f14821fcf2585d2',
    'f1tenth_DS1.bag middle, lossless': '3ffd061b03f579f4',
    'f1tenth_DS1.bag middle, precision': '12eae7cc5cfe8200',
    'f1tenth_DS1.bag end, lossless': '431899726dd6dffe',
    'f1tenth_DS1.bag end, precision': '7f22d445c291dcde',
    'icelab_normal_plan.bag start, lossless': '4207354f262dd822',
    'icelab_normal_plan.bag start, precision': '338e88cd05df4941',
    'icelab_normal_plan.bag middle, lossless': 'c55027e9d4b730d7',
    'icelab_normal_plan.bag middle, precision': 'c772d0900528beeb',
    'icelab_normal_plan.bag end, lossless': '58f70cea6582dda2',
    'icelab_normal_plan.bag end, precision': '9b6694475f3e45bb',
    'socspioneer_trace0.bag start, lossless': 'ce3e8dbbc105bc8b',
    'socspioneer_trace0.bag start, precision': 'ee2f028c9d08685d',
    'socspioneer_trace0.bag middle, lossless': '46527514b1e9f4ff',
    'socspioneer_trace0.bag middle, precision': '5b4f5d4877308ce9',
    'socspioneer_trace0.bag end, lossless': '4cb1b742c0231572',
    'socspioneer_trace0.bag end, precision': '38e13a727159dbad',
    'alfa_carbonZ_engine_failure.bag start, lossless': '4426c5c5495d55dd',
    'alfa_carbonZ_engine_failure.bag start, precision': '1db2f7a9092e38f2',
    'alfa_carbonZ_engine_failure.bag middle, lossless': 'b3f769e73a347e91',
    'alfa_carbonZ_engine_failure.bag middle, precision': '7b876317599b1cc2',
    'alfa_carbonZ_engine_failure.bag end, lossless': '65386ec8997900ad',
    'alfa_carbonZ_engine_failure.bag end, precision': '37ba93414d8978a3',
    'crafted all, lossless': '489e90e9d8b7735f',
    'crafted all, precision': 'bb31694790e39a8a',
    'crafted broken odometry, lossless': '90e446f4977fa0b2',
    'crafted broken odometry, precision': 'effb0a1b6596a8da',
    'crafted half decoded, lossless': '77b91a5c09d1dc4e',
    'crafted half decoded, precision': 'd85055bee92a0d7e',
    'crafted out of order, lossless': '08c37cc4d07dfc65',
    'crafted out of order, precision': '2a12d6cdc19f63b1',
    'crafted one record, lossless': '4f4ed9a6ca5d21c3',
    'crafted one record, precision': '3e2af6ddeb4df319',
    'crafted two records, lossless': '0500f18226cae362',
    'crafted two records, precision': '7bf9b1773f37a2e8',
}


@pytest.fixture(scope='module')
def windows():
    return real_windows() + crafted_windows()


def test_same_text_as_before(windows):
    got = digests(json_xz, windows)
    assert set(got) == set(EXPECTED)
    assert [key for key in EXPECTED if got[key] != EXPECTED[key]] == []


def test_sections_keep_the_publishers_callerid_and_latching(windows):
    """Of records with connection headers, each section keeps what its first record's says of the publisher."""
    for name, records in windows:
        doc = json_xz.document(json_xz.decoded_records(records)[0], META)
        for section in doc['topics']:
            first = next(record for record in records if record.topic == section['topic'])
            assert section.get('connection', {}) == raw_message.publisher_keys(first.connection), name
    pioneer = dict(windows)['socspioneer_trace0.bag start']
    assert {record.connection.get('callerid') for record in pioneer} - {None}  # a bag that names its publishers


def test_bytes_read_in_bulk(windows):
    """The real windows' Odometry, Imu and NavSatFix records are read from their bytes, not decoded."""
    for name, records in windows[:3]:
        kept, undecodable = json_xz.decoded_records(records)
        assert undecodable == 0
        assert sum(record.msg is None for record in kept) == len(records), name


def test_undecodable_counted():
    broken = dict(crafted_windows())['crafted broken odometry']
    kept, undecodable = json_xz.decoded_records(broken)
    assert undecodable == 10  # 5 truncated, 5 cut short
    assert len(kept) == 30
    assert sum(record.msg is not None for record in kept) == 5  # out-of-range nanoseconds: genpy (canon)


def test_window_file_is_the_text(windows, tmp_path):
    """The file ``log_format.write_window`` writes is xz of the same text, and it reads back losslessly."""
    name, records = windows[0]
    path, _ = log_format.write_window(LogWindow(records, []), str(tmp_path), 'json-xz', {'note': 'x'})
    with open(path, 'rb') as stream:
        data = stream.read()
    text = lzma.decompress(data).decode('utf-8')
    assert data == json_xz.compress(text.encode('utf-8'))
    meta, back = log_format.read_window(path)
    assert [record.stamp for record in back] == [record.stamp for record in records]
    decoded = [raw_message.decoded(record).msg for record in records]
    assert [serialized(record.msg) for record in back] == [serialized(msg) for msg in decoded] \
        == [record.raw for record in records]


def test_bulk_digits_and_texts():
    """The difference choice's bulk helpers give what the per-value definitions give (plain and scientific
    texts, zeros, negative zero, exponents of both cases)."""
    import decimal
    import random
    rng = random.Random(5)
    floats = [0.0, 1.0, 100.0, 0.1, 1e-05, 1.5e-07, 1e16, 1.2345678901234567e+20, 5e-324, 1.7976931348623157e308,
              -0.00012, 12345.678, -3.0]
    floats += [rng.gauss(0, 1) * 10 ** rng.randint(-9, 18) for _ in range(400)]
    texts = list(map(repr, floats))
    decimals = [decimal.Decimal(text) for text in texts]
    wide = decimal.Context(prec=2000)
    decimals += [wide.subtract(b, a) for a, b in zip(decimals, decimals[1:])]
    decimals += [decimal.Decimal(text) for text in ('-0', '0E+5', '-0E-3', '1E+2', '1.2E+5', '12E+10', '9E+1')]
    decimals = [value for value in decimals if len(value.as_tuple().digits) <= 400]  # what differences holds
    for start in range(0, len(texts), 7):
        part = texts[start:start + rng.randint(1, 30)]
        assert json_deltas._digit_sum(part) == sum(map(json_deltas._digits, part)), part
    for start in range(0, len(decimals), 7):
        part = decimals[start:start + rng.randint(1, 30)]
        made = json_deltas.decimal_texts(part)
        assert made == list(map(json_xz.decimal_text, part)), part
        assert json_deltas._digit_sum(made) == sum(map(json_deltas._digits, made)), made
