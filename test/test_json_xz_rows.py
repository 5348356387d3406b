"""json-xz writer speed-ups write the same bytes: rows by compiled getters (``json_xz.flat_row``) equal the
``msg_codec.to_dict`` rows, and whole documents are the same text, on real bags (Husky odometry, IMU and GPS,
F1/10, ICE-lab), lossless and with ``precision``."""
import lzma
import shutil
import subprocess

import pytest
import rosbag
from geometry_msgs.msg import PoseArray, Pose
from nav_msgs.msg import Odometry
from std_msgs.msg import Empty, Float32MultiArray, Header

from cc_log.base import msg_codec
from cc_log.storage.formats import json_rows, json_xz
from cc_log.base.records import Record

BAGS = ('husky_outdoor_2015.bag', 'f1tenth_DS1.bag', 'icelab_normal_plan.bag', 'alfa_carbonZ_engine_failure.bag')
PRECISION = {'pose.pose.position.*': 1e-4, 'twist.twist.*': 1e-4, '*orientation*': 1e-5, '*velocity*': 1e-5}


def genpy_row(msg):
    """The row as the writer made it before ``flat_row``."""
    return json_rows.flatten(msg_codec.to_dict(msg, short_float32=True), '', {})


def same_row(a, b):
    return list(a) == list(b) and repr(list(a.values())) == repr(list(b.values()))


def bag_records(path, limit=1500):
    records = []
    with rosbag.Bag(path) as bag:
        for topic, msg, t in bag.read_messages():
            stamp = msg.header.stamp.to_sec() if hasattr(msg, 'header') else t.to_sec()
            records.append(Record(stamp, topic, msg))
            if len(records) == limit:
                break
    return records


@pytest.mark.parametrize('name', BAGS)
def test_rows_and_documents_are_the_same_as_the_genpy_path_on_real_bags(real_bag, name, monkeypatch):
    records = bag_records(real_bag(name))
    assert all(same_row(json_xz.flat_row(r.msg), genpy_row(r.msg)) for r in records)
    for metadata in ({}, {'precision': PRECISION}):
        fast = json_xz.dumps(json_xz.document(records, metadata))
        with monkeypatch.context() as patch:
            patch.setattr(json_rows, 'flat_row', genpy_row)
            slow = json_xz.dumps(json_xz.document(records, metadata))
        assert fast == slow


def test_rows_keep_non_finite_floats_empty_messages_and_nested_arrays():
    odom = Odometry()
    odom.pose.covariance = [float('nan'), float('inf'), -0.0] + [1.5] * 33
    odom.twist.twist.linear.x = float('-inf')
    floats = Float32MultiArray(data=[0.1, float('nan'), 3.0])
    poses = PoseArray(header=Header(seq=3, frame_id='map'), poses=[Pose(), Pose()])
    for msg in (odom, floats, poses, Empty()):
        assert same_row(json_xz.flat_row(msg), genpy_row(msg)), msg._type
    assert json_xz.flat_row(odom)['pose.covariance'][:3] == ['NaN', 'Infinity', -0.0]


def test_compressed_windows_read_back_with_any_xz_decoder():
    data = b'{"columns":[1.25,1.5,1.75]}' * 500
    packed = json_xz.compress(data)
    assert lzma.decompress(packed) == data
    assert packed != json_xz.compress(data, options={})  # the options are applied
    if shutil.which('xz'):
        assert subprocess.run(['xz', '-dc'], input=packed, stdout=subprocess.PIPE, check=True).stdout == data
