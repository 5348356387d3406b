#!/usr/bin/env python3
"""Offline cost: smart-logger replay throughput vs a plain rosbag Python read of the same messages.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/cost_offline.py            # 3 alternating rounds per bag
    python3 bench/cost_offline.py --quick    # 1 round on the Husky bag (tests)

For each bag, in the same process and alternating (read, replay, read, replay, ...), so both see the same
machine load:
- read: ``rosbag.Bag.read_messages`` of the topics, touching each message (the baseline: what any Python
  tool pays to get the messages);
- replay: ``offline.replay.replay`` (what ``cclog replay`` runs: the detector's file loaded, ``bag_reader`` + the
  detector in batches, by default the envelope (``cclog replay --model envelope.json``; ``--detector classifier``: a
  one-class SVM) +
  windows written as json-xz, or ``--format bag-lz4``, by the background writer, waiting for every window to be
  written).
Throughput is messages / process CPU seconds (user + system, all threads) and messages / wall seconds;
the best round of each is kept. The ratio read-time / replay-time is "smart logger speed as % of read
speed" (target >= 100%: replay costs no more CPU than a plain deserializing read; replay reads the bag
with ``raw=True`` and decodes only what its triggers read and what it keeps). ``--profile N`` adds a
cProfile of one replay. ``--writer`` adds the json-xz writer alone on the windows the replay kept, their
records as serialized bytes (as the replay hands them over): the CPU per kept message of the text (decode +
document + JSON) read from the bytes now (``json_xz.decoded_records``), against every message decoded by genpy
and flattened into rows (the writer before), alternating in the same process, and of LZMA on the text; and the
bag-lz4 writer on the same windows with the bag written by rosbag (before) and by ``formats.bag_writer`` (now,
without rosbag's Python per message; the bags must be the same byte for byte).

Bags: ../shared/data/real/husky_outdoor_2015.bag (odometry driving + IMU side topic; envelope learned, or model
trained, on the first half, motion 2 s window) and a 10-minute simulated BWIBot bag (cc_log.sim seed 1, 100 Hz
odometry + IMU, 6 anomalies; envelope or model on a nominal run, seed 2, motion 500-message window).
"""
import argparse
import os
import shutil
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

import genpy  # noqa: E402
import rosbag  # noqa: E402

from cc_log.learning import learning  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.features import FeatureConfig  # noqa: E402
from cc_log.offline.replay import replay  # noqa: E402

TARGET = 0.9  # replay CPU / a plain deserializing read's CPU (issue 43)


def plain_read(path, topics):
    n = 0
    with rosbag.Bag(path) as bag:
        for _, msg, _ in bag.read_messages(topics=topics):
            n += 1
    return n


STAGES = (  # (stage, substrings of the file names whose functions' own time counts for it), first match wins
    ('bag read', ('/cc_log/storage/bag/bag_reader.py', '/cc_log/storage/bag/bagio.py')),
    ('features', ('/cc_log/features/',)),
    ('classifier', ('/cc_log/learning/model.py', '/cc_log/triggers/classifier.py', '/sklearn/', '/numpy/', '/scipy/')),
    ('window buffer, triggers', ('/cc_log/buffer/window_buffer.py', '/cc_log/logger/smart.py', '/cc_log/triggers/',
                                 '/cc_log/base/stamp_clock.py', '/cc_log/buffer/window_prep.py',
                                 '/cc_log/logger/trigger_topics.py', '/cc_log/logger/smart_events.py',
                                 '/cc_log/base/raw_json.py', '/cc_log/offline/replay.py')),
    ('writer (decode, json-xz, disk)', ('/cc_log/', 'lzma', 'json', '/genpy/', '_Odometry', '_Imu', 'dynamic')),
    ('bag read', ('/rosbag/', 'bz2', 'lz4', '/roslz4/')),
)


def stage_of(filename):
    for stage, parts in STAGES:
        if any(part in filename for part in parts):
            return stage
    return 'other (interpreter, I/O)'


def detector(kind, records, topic, config, tmp, name, stride=1):
    """``make() -> (model path or None, triggers)`` of a replay with the ``kind`` of detector learned on ``records``:
    ``'envelope'`` (the default of ``cclog replay --model``: ``cclog learn-envelope``'s 1 s windows every 250 ms,
    saved to its file, which ``make`` loads as ``cclog replay --model`` does) or ``'classifier'`` (``config``'s
    one-class SVM, a vector every ``stride`` messages; the replay loads its file)."""
    if kind == 'classifier':
        _, X = common.window_vectors(records, topic, config, stride=stride)
        model, _ = learning.train(X, config=config)
        path = model.save(os.path.join(tmp, '%s.model.json' % name))
        return lambda: (path, ())
    from cc_log.features.envelope import envelope_windows, odometry_samples
    from cc_log.learning import envelope
    from cc_log.triggers.envelope import EnvelopeTrigger
    samples = odometry_samples([record for record in records if record.topic == topic])
    path = os.path.join(tmp, '%s.envelope.json' % name)
    envelope.learn([envelope_windows(*samples, window=1.0, stride=0.25)[1]], topic, 1.0, 0.25,
                   float(samples[0].max() - samples[0].min())).save(path)
    return lambda: (None, [EnvelopeTrigger('envelope', envelope.Envelope.load(path), topic)])


def profile(path, topics, make, out, name, top, fmt='json-xz'):
    """cProfile of one replay with the writer (``fmt``) in the same thread: the share of each stage (own time of
    functions grouped by file) and the ``top`` functions by own time."""
    import cProfile
    import pstats
    from cc_log.learning.model import AnomalyModel
    from cc_log.logger.smart import SmartLogger
    from cc_log.offline.replay import replay_into
    model_path, triggers = make()
    logger = SmartLogger(model_path and AnomalyModel.load(model_path), out, fmt=fmt, driving_topic=topics[0],
                         side_topics=tuple(topics[1:]), background=False, triggers=triggers)
    profiler = cProfile.Profile()
    profiler.enable()
    replay_into(logger, path)
    profiler.disable()
    stats = pstats.Stats(profiler)
    total = sum(entry[2] for entry in stats.stats.values())  # own time of every function
    stages = {}
    for (filename, _, _), entry in stats.stats.items():
        stage = stage_of(filename)
        stages[stage] = stages.get(stage, 0.0) + entry[2]
    print()
    common.table(['stage', 'own s', 'share'],
                 [[stage, '%.3f' % seconds, '%.1f%%' % (100 * seconds / total)]
                  for stage, seconds in sorted(stages.items(), key=lambda item: -item[1])],
                 'cProfile of one replay of %s (writer inline), %.2f s own time, by stage:' % (name, total))
    rows = sorted(stats.stats.items(), key=lambda item: -item[1][2])[:top]
    print()
    common.table(['function', 'calls', 'own s', 'share'],
                 [['%s:%d %s' % (os.path.basename(f), line, fn), calls, '%.3f' % own, '%.1f%%' % (100 * own / total)]
                  for (f, line, fn), (_, calls, own, _, _) in rows], 'Costliest functions:')


def as_bytes(windows):
    """``windows`` (``[(metadata, records)]`` of decoded messages) with each record as the replay hands it to
    the writer: serialized bytes and their connection header, no message."""
    import io
    out = []
    for metadata, records in windows:
        raw = []
        for record in records:
            buff = io.BytesIO()
            record.msg.serialize(buff)
            cls = type(record.msg)
            raw.append(record._replace(msg=None, raw=buff.getvalue(), connection={
                'type': cls._type, 'md5sum': cls._md5sum, 'message_definition': cls._full_text}))
        out.append((metadata, raw))
    return out


def writer_cost(windows, rounds):
    """``{'now': CPU s, 'earlier': CPU s, 'lzma': CPU s, 'bytes': total}``: best of ``rounds`` alternating runs
    over ``windows`` (``[(metadata, records of serialized bytes)]``) of the json-xz writer's text (decode +
    document + JSON) now (``json_xz.decoded_records``: fields read from the bytes) and earlier (every message
    decoded by genpy, ``raw_message.decoded_records``, then rows), and of LZMA on that text. Both texts must be
    the same."""
    from cc_log.base import raw_message
    from cc_log.storage.formats import json_xz
    times = {'now': [], 'earlier': [], 'lzma': []}
    texts = {}
    for _ in range(rounds):
        for name, decode in (('now', json_xz.decoded_records), ('earlier', raw_message.decoded_records)):
            with common.Timer() as timer:
                texts[name] = [json_xz.dumps(json_xz.document(decode(records)[0], metadata)).encode('utf-8')
                               for metadata, records in windows]
            times[name].append(timer.cpu)
        with common.Timer() as timer:
            size = sum(len(json_xz.compress(text)) for text in texts['now'])
        times['lzma'].append(timer.cpu)
    if texts['now'] != texts['earlier']:
        raise SystemExit('json-xz writer: the text read from the bytes differs from the decoded messages\' text')
    return dict((name, min(values)) for name, values in times.items()), size


class BagTime(genpy.Time):
    """The time class bag-lz4 handed rosbag before ``formats.bag_writer``: a genpy.Time that compares as the
    tuple (secs, nsecs) (genpy's comparisons were a fifth of rosbag's writer CPU on Husky windows)."""
    __slots__ = ()
    __hash__ = genpy.Time.__hash__

    def __eq__(self, other):
        return isinstance(other, genpy.Time) and (self.secs, self.nsecs) == (other.secs, other.nsecs)

    def __lt__(self, other):
        return (self.secs, self.nsecs) < (other.secs, other.nsecs)

    def __le__(self, other):
        return (self.secs, self.nsecs) <= (other.secs, other.nsecs)

    def __gt__(self, other):
        return (self.secs, self.nsecs) > (other.secs, other.nsecs)

    def __ge__(self, other):
        return (self.secs, self.nsecs) >= (other.secs, other.nsecs)


def rosbag_write(path, messages, headers):
    """``messages`` and ``headers`` (``bag_lz4.bag_messages``) written by rosbag, as bag-lz4 wrote them before
    ``formats.bag_writer`` (raw, with the connection headers, ``BagTime``)."""
    from cc_log.base import raw_message
    classes = dict((topic, raw_message.message_class(header)) for topic, header in headers.items())
    bag = rosbag.Bag(path, 'w', compression=rosbag.Compression.LZ4)
    for topic, secs, nsecs, data in messages:
        header = headers[topic]
        bag.write(topic, (header['type'], data, header['md5sum'], classes[topic]),
                  BagTime(secs, nsecs), raw=True, connection_header=header)
    bag.close()


def bag_writer_cost(windows, rounds, tmp):
    """``{'rosbag': CPU s, 'bag_writer': CPU s}``: best of ``rounds`` alternating runs over ``windows`` of the
    bag-lz4 writer (``bag_lz4.bag_messages``, then the file) with the bag written by rosbag (as before) and by
    ``formats.bag_writer`` (now); the files must be the same, byte for byte."""
    from cc_log.storage.formats import bag_lz4
    from cc_log.storage.bag import bag_writer
    times = {'rosbag': [], 'bag_writer': []}
    files = {}
    for k in range(rounds):
        for name in ('rosbag', 'bag_writer'):
            paths = [os.path.join(tmp, 'bag_writer_%s_%d_%d.bag' % (name, k, n)) for n in range(len(windows))]
            with common.Timer() as timer:
                for target, (metadata, records) in zip(paths, windows):
                    messages, headers = bag_lz4.bag_messages(records, metadata)
                    if name == 'rosbag':
                        rosbag_write(target, messages, headers)
                    else:
                        with open(target, 'wb') as stream:
                            stream.write(bag_writer.bag_bytes(messages, headers))
            times[name].append(timer.cpu)
            files[name] = []
            for target in paths:
                with open(target, 'rb') as stream:
                    files[name].append(stream.read())
                os.remove(target)
    if files['rosbag'] != files['bag_writer']:
        raise SystemExit('bag-lz4 writer: the bags written by rosbag and by formats.bag_writer differ')
    return dict((name, min(values)) for name, values in times.items())


def kept_windows(path, topics, make, tmp):
    """``[(metadata, records)]`` of the json-xz windows a replay of ``path`` writes, read back."""
    from cc_log.storage import log_format
    out = os.path.join(tmp, 'kept')
    model_path, triggers = make()
    replay(path, topics[0], model_path, out, side_topics=topics[1:], fmt='json-xz', triggers=triggers)
    windows = [log_format.read_window(os.path.join(out, name)) for name in sorted(os.listdir(out))
               if name.endswith('.json.xz')]
    shutil.rmtree(out, ignore_errors=True)
    return windows


def measure(path, topics, make, rounds, tmp, fmt='json-xz'):
    reads, replays = [], []
    summary = None
    for k in range(rounds):
        with common.Timer() as timer:
            n = plain_read(path, topics)
        reads.append((timer.cpu, timer.wall, n))
        out = os.path.join(tmp, 'replay_%d' % k)
        with common.Timer() as timer:   # the detector's file loaded, as cclog replay does
            model_path, triggers = make()
            summary = replay(path, topics[0], model_path, out, side_topics=topics[1:], fmt=fmt, triggers=triggers)
        replays.append((timer.cpu, timer.wall, summary['input_messages']))
        shutil.rmtree(out, ignore_errors=True)
    read_cpu, read_wall = min(r[0] for r in reads), min(r[1] for r in reads)
    rep_cpu, rep_wall = min(r[0] for r in replays), min(r[1] for r in replays)
    return {'messages': reads[0][2], 'replayed': replays[0][2], 'read_cpu': read_cpu, 'read_wall': read_wall,
            'replay_cpu': rep_cpu, 'replay_wall': rep_wall, 'windows': len(summary['windows'])}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--format', default='json-xz', choices=('json-xz', 'bag-lz4'), help='of the replay\'s windows')
    parser.add_argument('--detector', default='envelope', choices=('envelope', 'classifier'),
                        help="of the replay: the envelope (cclog replay's default) or a one-class SVM")
    parser.add_argument('--profile', type=int, default=0, metavar='N',
                        help='then profile one replay of the last bag (cProfile) and print its N costliest functions')
    parser.add_argument('--writer', action='store_true',
                        help='then time the writers alone on the kept windows: json-xz now against the earlier '
                        'writer, bag-lz4 by rosbag and by formats.bag_writer')
    args = parser.parse_args(argv)
    started = time.time()
    with tempfile.TemporaryDirectory(prefix='cc_log_bench_') as tmp:
        cases = []
        # Husky: model on the first half of the odometry
        records = common.husky_records((common.HUSKY_ODOM,))
        first, _ = common.split_half(records, common.HUSKY_ODOM)
        husky = detector(args.detector, first, common.HUSKY_ODOM, FeatureConfig('motion', '2s'), tmp, 'husky')
        cases.append(('husky_outdoor_2015', common.HUSKY_BAG, [common.HUSKY_ODOM, common.HUSKY_IMU], husky))
        data = [common.describe_data(common.HUSKY_BAG)]
        if not args.quick:
            sim_bag = os.path.join(tmp, 'sim.bag')
            sim.simulate_to_bag(sim_bag, sim.SimConfig(seed=1, minutes=10, anomalies=6, imu=True))
            nominal, _ = common.sim_records(sim.SimConfig(seed=2, minutes=10, anomalies=0))
            simulated = detector(args.detector, nominal, sim.ODOM_TOPIC, FeatureConfig('motion', '500'), tmp, 'sim',
                                 stride=10)
            cases.append(('sim 10 min, 6 anomalies', sim_bag, [sim.ODOM_TOPIC, sim.IMU_TOPIC], simulated))
            data.append('data: cc_log.sim BWIBot 10 min, 100 Hz odometry + IMU, 6 anomalies, seed 1, '
                        'lz4 bag (%d bytes)' % os.path.getsize(sim_bag))
        rounds = 1 if args.quick else args.rounds
        common.header('Offline replay cost', data + ['rounds: %d, alternating read / replay; best of each; windows: '
                                                     '%s; detector: %s' % (rounds, args.format, args.detector)])
        rows = []
        for name, path, topics, make in cases:
            r = measure(path, topics, make, rounds, tmp, args.format)
            ratio_cpu = r['read_cpu'] / r['replay_cpu']
            ratio_wall = r['read_wall'] / r['replay_wall']
            rows.append([name, r['messages'], '%.0f' % (r['messages'] / r['read_cpu']),
                         '%.0f' % (r['replayed'] / r['replay_cpu']), '%.0f%%' % (100 * ratio_cpu),
                         '%.0f' % (r['messages'] / r['read_wall']), '%.0f' % (r['replayed'] / r['replay_wall']),
                         '%.0f%%' % (100 * ratio_wall), r['windows']])
            print('target replay CPU <= %.1fx read CPU (replay speed >= %.0f%% of read speed), %s: %.0f%% (CPU time), '
                  '%.0f%% (wall) -> %s' % (TARGET, 100 / TARGET, name, 100 * ratio_cpu, 100 * ratio_wall,
                                           'met' if ratio_cpu >= 1 / TARGET else 'NOT met'))
        print()
        common.table(['bag', 'messages', 'read msg/CPU s', 'replay msg/CPU s', 'replay/read (CPU)',
                      'read msg/s wall', 'replay msg/s wall', 'replay/read (wall)', 'windows'], rows,
                     'Offline throughput (replay = bag read + features + %s + %s windows):'
                     % (args.detector, args.format))
        if args.writer:
            rows = []
            for name, path, topics, make in cases:
                windows = as_bytes(kept_windows(path, topics, make, tmp))
                kept = sum(len(records) for _, records in windows)
                cpu, size = writer_cost(windows, max(rounds, 3))
                cpu.update(bag_writer_cost(windows, max(rounds, 3), tmp))
                per = dict((key, '%.1f' % (1e6 * seconds / kept)) for key, seconds in cpu.items())
                rows.append([name, len(windows), kept, per['earlier'], per['now'],
                             '%.1f' % (cpu['earlier'] / cpu['now']), per['lzma'],
                             '%.1f' % (1e6 * (cpu['now'] + cpu['lzma']) / kept), size, per['rosbag'],
                             per['bag_writer']])
            print()
            common.table(['bag', 'windows', 'kept msgs', 'text earlier us/msg', 'text now us/msg', 'speed-up',
                          'LZMA us/msg', 'writer now us/msg', 'bytes', 'bag-lz4 by rosbag us/msg',
                          'bag-lz4 by bag_writer us/msg'], rows,
                         'Writers alone on the kept windows (records as serialized bytes; json-xz text = decode + '
                         'document + JSON; bag-lz4 written by rosbag and by formats.bag_writer; best of '
                         'alternating rounds; same text, same bags checked):')
        if args.profile:
            name, path, topics, make = cases[-1]
            profile(path, topics, make, os.path.join(tmp, 'profiled'), name, args.profile, args.format)
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
