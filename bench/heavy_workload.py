#!/usr/bin/env python3
"""The workload of bench/heavy_sensors.py: a bag of cameras, a lidar, odometry and IMU at ~37 or ~100 MB/s.

Workload (built once, cached in --out as heavy_<N>cam_<S>s.bag and .json; written by cc_log.storage.bag.bag_writer,
uncompressed chunks; header stamps = bag times, from 1600000000):
- /camera/image_raw (and /camera2/image_raw with --cameras 2 or --rate 100): sensor_msgs/Image 640x480 rgb8 at
  30 Hz, 921,600 bytes of pixels: a diagonal gradient moving 4 px a frame plus uniform noise 0-31 on every byte
  (5 random bits a byte: LZ4 saves nothing, LZMA a quarter; real frames compress better; the ratios are printed);
- /velodyne_points: sensor_msgs/PointCloud2 at 10 Hz, 32 rings x 900 columns = 28,800 points of 32 bytes (x, y,
  z, intensity float32, ring uint16, time float32); with two cameras 128 x 1,024 = 131,072 points (an Ouster
  OS1-128 at 1024x10) so that the whole is ~100 MB/s; ranges of a smooth scene + 2 cm noise;
- /odom and /imu/data: nav_msgs/Odometry and sensor_msgs/Imu at 100 Hz from cc_log.sim (seed 3, nominal).
"""
import heapq
import json
import os

WORKLOAD_VERSION = 1        # bump when the bag's content changes: cached bags of another version are rebuilt
START = 1600000000.0        # bag time of the first message (cc_log.sim's default start)
CAMERA_RATE, LIDAR_RATE, ODOM_RATE = 30.0, 10.0, 100.0
WIDTH, HEIGHT = 640, 480
POINT_STEP = 32
LIDAR_TOPIC = '/velodyne_points'


class Workload(object):
    """What is played: ``cameras`` cameras, a lidar, odometry and IMU for ``seconds`` seconds."""

    def __init__(self, cameras=1, seconds=30.0):
        self.cameras, self.seconds = int(cameras), float(seconds)
        self.rings, self.columns = (32, 900) if self.cameras < 2 else (128, 1024)
        self.camera_topics = ['/camera/image_raw'] + ['/camera%d/image_raw' % n for n in range(2, self.cameras + 1)]
        self.topics = self.camera_topics + [LIDAR_TOPIC, '/odom', '/imu/data']
        self.name = 'heavy_%dcam_%gs' % (self.cameras, self.seconds)

    def spec(self):
        return {'version': WORKLOAD_VERSION, 'cameras': self.cameras, 'seconds': self.seconds,
                'rings': self.rings, 'columns': self.columns}

    def node_topics(self):
        """The node's ``_topics`` (relative names, as a user writes them): every topic but the driving one."""
        return ' '.join(t.lstrip('/') for t in self.topics if t != '/odom')

    def streams(self):
        """One generator per topic of (stamp, topic, genpy message), each in time order."""
        from cc_log import sim
        simulated = sim.Simulator(sim.SimConfig(rate=ODOM_RATE, seed=3, minutes=self.seconds / 60.0, anomalies=0,
                                                imu=True, start_time=START))
        streams = [((stamp, topic, msg) for topic, stamp, msg in simulated.messages()
                    if topic in (sim.ODOM_TOPIC, sim.IMU_TOPIC))]
        for number, topic in enumerate(self.camera_topics):
            streams.append(camera_frames(topic, number, int(self.seconds * CAMERA_RATE)))
        streams.append(lidar_scans(int(self.seconds * LIDAR_RATE), self.rings, self.columns))
        return streams


def _header(msg, seq, stamp, frame):
    import genpy
    msg.header.seq, msg.header.stamp, msg.header.frame_id = seq, genpy.Time.from_sec(stamp), frame
    return msg


def camera_frames(topic, number, count):
    """``count`` rgb8 frames on ``topic`` at CAMERA_RATE: a gradient moving 4 px a frame + noise 0-31."""
    import numpy as np
    from sensor_msgs.msg import Image
    rng = np.random.default_rng(100 + number)
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
    base = ((x[:, :, None] + 2 * y[:, :, None] + np.array([0, 85, 170]) + 40 * number) & 255).astype(np.uint8)
    for k in range(count):
        stamp = START + 0.005 + 0.002 * number + k / CAMERA_RATE
        pixels = base + np.uint8((4 * k) & 255) + rng.integers(0, 32, base.shape, dtype=np.uint8)
        msg = Image(height=HEIGHT, width=WIDTH, encoding='rgb8', is_bigendian=0, step=3 * WIDTH,
                    data=pixels.tobytes())
        yield stamp, topic, _header(msg, k, stamp, 'camera%d' % (number + 1))


def lidar_scans(count, rings, columns):
    """``count`` PointCloud2 scans of rings x columns points at LIDAR_RATE: a smooth scene + 2 cm noise."""
    import numpy as np
    from sensor_msgs.msg import PointCloud2, PointField
    rng = np.random.default_rng(7)
    names = ('x', 'y', 'z', 'intensity', 'ring', 'time')
    offsets, kinds = (0, 4, 8, 16, 20, 24), ('<f4', '<f4', '<f4', '<f4', '<u2', '<f4')
    dtype = np.dtype({'names': names, 'formats': kinds, 'offsets': offsets, 'itemsize': POINT_STEP})
    fields = [PointField(name=n, offset=o, datatype=PointField.UINT16 if k == '<u2' else PointField.FLOAT32,
                         count=1) for n, o, k in zip(names, offsets, kinds)]
    elevation = np.radians(np.linspace(-25.0, 15.0, rings))[:, None]
    azimuth = 2 * np.pi * np.arange(columns)[None, :] / columns
    for k in range(count):
        stamp = START + 0.013 + k / LIDAR_RATE
        ranges = (8.0 + 4.0 * np.sin(3 * azimuth + 0.3 * k) + 1.5 * np.cos(7 * elevation)
                  + rng.normal(0.0, 0.02, (rings, columns)))
        cloud = np.zeros(rings * columns, dtype)
        cloud['x'] = (ranges * np.cos(elevation) * np.cos(azimuth)).ravel()
        cloud['y'] = (ranges * np.cos(elevation) * np.sin(azimuth)).ravel()
        cloud['z'] = (ranges * np.sin(elevation)).ravel()
        cloud['intensity'] = (20.0 * ranges + rng.normal(0.0, 1.0, ranges.shape)).ravel()
        cloud['ring'] = np.repeat(np.arange(rings), columns)
        cloud['time'] = np.tile(np.arange(columns) / (columns * LIDAR_RATE), rings)
        msg = PointCloud2(height=1, width=rings * columns, fields=fields, is_bigendian=False,
                          point_step=POINT_STEP, row_step=POINT_STEP * rings * columns, data=cloud.tobytes(),
                          is_dense=True)
        yield stamp, LIDAR_TOPIC, _header(msg, k, stamp, 'velodyne')


def serialized(msg):
    import io
    buffer = io.BytesIO()
    msg.serialize(buffer)
    return buffer.getvalue()


def compression_ratios(data):
    """Compressed / raw of ``data`` with LZ4 (roslz4, as rosbag --lz4 and bag-lz4) and LZMA presets 0 and 6."""
    import lzma
    import roslz4
    size = float(len(data))
    return {'lz4': len(roslz4.compress(data)) / size, 'xz-0': len(lzma.compress(data, preset=0)) / size,
            'xz-6': len(lzma.compress(data, preset=6)) / size}


def build(workload, path):
    """Write the workload bag at ``path`` (uncompressed chunks); return its description (also in path.json)."""
    from cc_log.base import raw_message
    from cc_log.storage.bag import bag_writer
    from cc_log.base.safe_files import AtomicFile
    stamps = {topic: [] for topic in workload.topics}
    sizes = dict.fromkeys(workload.topics, 0)
    headers, samples = {}, {}

    def messages():
        for stamp, topic, msg in heapq.merge(*workload.streams(), key=lambda item: item[0]):
            if topic not in headers:
                headers[topic] = raw_message.class_header(topic, type(msg))
            data = serialized(msg)
            samples.setdefault(topic, data)
            stamps[topic].append(stamp)
            sizes[topic] += len(data)
            yield topic, msg.header.stamp.secs, msg.header.stamp.nsecs, data
    with AtomicFile(path, overwrite=True) as stream:
        bag_writer.write_bag(stream, messages(), headers, compression='none')
    info = {'spec': workload.spec(), 'bag_bytes': os.path.getsize(path), 'stamps': stamps, 'bytes': sizes,
            'message_bytes': {topic: len(data) for topic, data in samples.items()},
            'ratios': {topic: compression_ratios(samples[topic])
                       for topic in (workload.camera_topics[0], LIDAR_TOPIC)}}
    with AtomicFile(path + '.json', overwrite=True, text=True) as stream:
        json.dump(info, stream)
    return info


def workload_bag(workload, out):
    """(path, description) of the workload bag in ``out``, built unless a bag of the same spec is there."""
    path = os.path.join(out, workload.name + '.bag')
    try:
        with open(path + '.json') as stream:
            info = json.load(stream)
        if info['spec'] == workload.spec() and os.path.getsize(path) == info['bag_bytes']:
            return path, info
    except (OSError, ValueError, KeyError):
        pass
    return path, build(workload, path)


def describe_workload(workload, info):
    mb = {topic: info['bytes'][topic] / workload.seconds / 1e6 for topic in workload.topics}
    parts = ['%s %s x %d B = %.2f MB/s' % (topic, '%g Hz' % (len(info['stamps'][topic]) / workload.seconds),
                                           info['message_bytes'][topic], mb[topic]) for topic in workload.topics]
    ratios = '; '.join('%s %s' % (topic, ', '.join('%s %.3f' % (codec, value) for codec, value in sorted(r.items())))
                       for topic, r in sorted(info['ratios'].items()))
    return ['workload: %.1f MB/s for %g s (%s)' % (sum(mb.values()), workload.seconds, '; '.join(parts)),
            'compressed / raw of one message: ' + ratios]
