#!/usr/bin/env python3
"""Storage: the paper's Table 2 and the end-to-end bytes cc_log stores vs the recorders in use today.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/storage.py            # full (a few minutes)
    python3 bench/storage.py --quick    # tiny run (tests)

Part 1, Table 2: the plain row-per-message JSON log (msg_codec.row_json, one line per message: the paper's
"JSON log") of (a) the Husky odometry (../shared/data/real/husky_outdoor_2015.bag,
/husky_velocity_controller/odom, all 3952 messages) and (b) one minute of simulated BWIBot odometry
(cc_log.sim, 100 Hz, 6000 messages) compressed with every codec of codecs.codec_table, plus cc_log's own
window formats holding the same messages (log_format.write_window of one window: json-xz and bag-lz4),
checked lossless by reading the file back (every message's row JSON and stamp equal), and json-xz with the
opt-in precision (PRECISION: 1e-4 m and m/s, 1e-5 for orientation and rad/s; lossy: the largest error per
field is printed).

Part 2, end to end: every message of a run goes through the smart logger (SmartLogger, json-xz, pre/post
100 messages, as `cclog replay` does); we compare the raw row-JSON bytes of all messages with the bytes
cc_log stored, and with what `rosbag record --lz4` would store (all messages written with
rosbag.Bag(compression='lz4')) and what BWI's bwi_logging stores (every 100th message of each topic,
bz2 bag). Runs:
- sim: a 10-minute simulated BWIBot run, 100 Hz odometry + 100 Hz IMU (side topic), 6 anomalies (one of
  each type), seed 1; model: motion features, 500-message window, trained on a separate nominal 10-minute
  run (seed 2);
- husky: the Husky bag's second half (odometry + IMU) with one anomaly of every simulator type injected
  (sim.inject_anomalies, seed 0); model: motion features, 2 s window, trained on the first half.
"""
import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.storage import codecs, log_format  # noqa: E402
from cc_log.learning import learning  # noqa: E402
from cc_log.base import msg_codec  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.features import FeatureConfig  # noqa: E402
from cc_log.base.records import LogWindow  # noqa: E402

SIM_RUN_SEED = 1
SIM_TRAIN_SEED = 2
#: json-xz precision of the lossy row: the odometry's resolution (docs/FORMAT.md).
PRECISION = {'pose.pose.position.*': 1e-4, 'pose.pose.orientation.*': 1e-5, 'twist.twist.linear.*': 1e-4,
             'twist.twist.angular.*': 1e-5}


def row_json_log(records):
    return b''.join((msg_codec.row_json(r.msg) + '\n').encode('utf-8') for r in records)


def cc_log_format_size(records, fmt, directory):
    """Bytes of one cc_log window file of ``records`` in ``fmt``; verified lossless by reading it back."""
    path, nbytes = log_format.write_window(LogWindow(list(records), []), directory, fmt, {})
    _, back = log_format.read_window(path)
    if len(back) != len(records):
        raise AssertionError('%s: %d records back, %d written' % (path, len(back), len(records)))
    for a, b in zip(records, back):
        if (a.topic != b.topic or msg_codec.row_json(a.msg) != msg_codec.row_json(b.msg)
                or abs(a.stamp - b.stamp) > 1e-9):
            raise AssertionError('%s: a record differs after reading back (%s at %.9f)' % (path, a.topic, a.stamp))
    os.unlink(path)
    return nbytes


def lossy_size(records, directory):
    """Bytes of one json-xz window of ``records`` with PRECISION and the largest error per field read back."""
    from cc_log.storage.formats import json_xz
    path, nbytes = log_format.write_window(LogWindow(list(records), []), directory, 'json-xz',
                                           {'precision': PRECISION})
    _, back = log_format.read_window(path)
    os.unlink(path)
    errors = {}
    for fields in json_xz.max_errors(records, back).values():
        for key, error in fields.items():
            errors[key] = max(errors.get(key, 0.0), error)
    return nbytes, dict((key, error) for key, error in errors.items() if error)


def table2(name, records, tmp):
    data = row_json_log(records)
    rows = codecs.codec_table(data)
    out = []
    for row in rows:
        if row['codec'] == 'none':
            out.append([row['codec'], row['size'], '100.00%', '-', 'yes'])
        elif row['available']:
            out.append([row['codec'], row['size'], '%.2f%%' % row['ratio'], '%.1f' % row['mb_s'], 'yes'])
        else:
            out.append([row['codec'], '-', '-', '-', row['note']])
    for fmt in ('json-xz', 'bag-lz4'):
        started = time.perf_counter()
        size = cc_log_format_size(records, fmt, tmp)
        seconds = time.perf_counter() - started
        out.append(['cc_log %s' % fmt, size, '%.2f%%' % (100.0 * size / len(data)),
                    '%.1f (write+verify)' % (len(data) / 1e6 / seconds), 'yes (read back, compared)'])
    started = time.perf_counter()
    size, errors = lossy_size(records, tmp)
    seconds = time.perf_counter() - started
    out.append(['cc_log json-xz precision', size, '%.2f%%' % (100.0 * size / len(data)),
                '%.1f (write+read)' % (len(data) / 1e6 / seconds), 'no: within half a step'])
    paper = {'none': '100%', 'LZ4': '13.0%', 'LZFSE': '10.4%', 'ZIP': '10.1%', 'gzip': '10.1%', 'LZMA-6': '7.2%'}
    for row in out:
        row.insert(3, paper.get(row[0], ''))
    common.table(['codec', 'bytes', '% of row JSON', 'paper %', 'MB/s', 'lossless'], out,
                 'Table 2, %s: %d messages, row JSON %d bytes' % (name, len(records), len(data)))
    print('json-xz precision %s: largest error per field: %s' % (
        ', '.join('%s %g' % item for item in PRECISION.items()),
        ', '.join('%s %.3g' % item for item in sorted(errors.items())) or 'none'))
    return len(data), out


def thin(records, every=100):
    """bwi_logging's thinning: every ``every``-th message of each topic."""
    counts, out = {}, []
    for record in records:
        n = counts.get(record.topic, 0)
        counts[record.topic] = n + 1
        if n % every == 0:
            out.append(record)
    return out


def end_to_end(name, records, truth, model, driving_topic, side_topics, reach, tmp):
    """One row of the end-to-end table and the per-anomaly matches."""
    out_dir = os.path.join(tmp, 'windows_' + name)
    started = time.perf_counter()
    result = common.smart_replay(model, records, driving_topic, out_dir, side_topics)
    seconds = time.perf_counter() - started
    stats = result['stats']
    matches, false = common.match_anomalies(truth, result['windows'], reach)
    raw = stats['raw_json_bytes']
    if raw != sum(msg_codec.row_json_bytes(r.msg) for r in records):
        raise AssertionError('raw_json_bytes differs from the row JSON of the records')
    lz4 = common.write_bag(os.path.join(tmp, name + '_lz4.bag'), records, 'lz4')
    bwi_records = thin(records)
    bwi = common.write_bag(os.path.join(tmp, name + '_bwi.bag'), bwi_records, 'bz2')
    duration = records[-1].stamp - records[0].stamp
    caught = sum(m['caught'] for m in matches)
    kept = sum(m['kept'] for m in matches)
    return {'name': name, 'messages': len(records), 'seconds': duration, 'raw': raw,
            'stored': stats['stored_bytes'], 'kept_messages': stats['messages_kept'],
            'windows': len(result['windows']), 'false': false, 'caught': caught, 'kept': kept,
            'anomalies': len(truth), 'lz4': lz4, 'bwi': bwi, 'bwi_messages': len(bwi_records),
            'replay_s': seconds, 'matches': matches}


def sim_model(minutes, tmp_quick=False):
    config = FeatureConfig('motion', '500')
    records, _ = common.sim_records(sim.SimConfig(seed=SIM_TRAIN_SEED, minutes=minutes, anomalies=0))
    _, X = common.window_vectors(records, sim.ODOM_TOPIC, config, stride=10)
    model, info = learning.train(X, config=config)
    return model, info, len(X)


def husky_case(types):
    records = common.husky_records((common.HUSKY_ODOM, common.HUSKY_IMU))
    first, second = common.split_half(records, common.HUSKY_ODOM)
    config = FeatureConfig('motion', '2s')
    _, X = common.window_vectors(first, common.HUSKY_ODOM, config)
    model, info = learning.train(X, config=config)
    injected, truth = sim.inject_anomalies(second, types, seed=0, topic=common.HUSKY_ODOM)
    return model, info, len(X), injected, truth


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--quick', action='store_true', help='tiny run: 2-minute simulation, 2 anomalies')
    args = parser.parse_args(argv)
    started = time.time()
    minutes, anomalies = (2.0, 2) if args.quick else (10.0, 6)
    types = sim.ANOMALY_TYPES[:3] if args.quick else sim.ANOMALY_TYPES
    common.header('Storage', [common.describe_data(common.HUSKY_BAG),
                              'data: cc_log.sim BWIBot, 100 Hz odometry + IMU, %g min, %d anomalies, seed %d '
                              '(model trained on a nominal %g-min run, seed %d)'
                              % (minutes, anomalies, SIM_RUN_SEED, minutes, SIM_TRAIN_SEED)])
    with tempfile.TemporaryDirectory(prefix='cc_log_bench_') as tmp:
        husky_odom = common.husky_records((common.HUSKY_ODOM,))
        if args.quick:
            husky_odom = husky_odom[:500]
        targets = []
        raw, rows = table2('husky_outdoor_2015 %s' % common.HUSKY_ODOM, husky_odom, tmp)
        xz = next(r for r in rows if r[0] == 'cc_log json-xz')
        targets.append(('husky odometry', 100.0 * xz[1] / raw))
        lossy = next(r for r in rows if r[0] == 'cc_log json-xz precision')
        print('target json-xz with precision <= 2%% of row JSON, husky odometry: %.2f%% -> %s' % (
            100.0 * lossy[1] / raw, 'met' if lossy[1] <= 0.02 * raw else 'NOT met'))
        sim_run, truth = common.sim_records(sim.SimConfig(seed=SIM_RUN_SEED, minutes=minutes, anomalies=anomalies,
                                                          imu=True))
        sim_run = [r for r in sim_run if r.topic in (sim.ODOM_TOPIC, sim.IMU_TOPIC)]  # not the ground truth
        sim_odom = [r for r in sim_run if r.topic == sim.ODOM_TOPIC][:600 if args.quick else 6000]
        raw, rows = table2('simulated BWIBot /odom, first %d messages of the run' % len(sim_odom), sim_odom, tmp)
        xz = next(r for r in rows if r[0] == 'cc_log json-xz')
        targets.append(('simulator odometry', 100.0 * xz[1] / raw))
        for label, percent in targets:
            print('target json-xz <= 4%% of row JSON, lossless, %s: %.2f%% -> %s' % (
                label, percent, 'met' if percent <= 4.0 else 'NOT met'))
        print()

        model, info, n = sim_model(minutes)
        print('sim model: motion 500-message window, %d training vectors, %s, nu=%g, gamma=%.3g, threshold %.4g'
              % (n, info['method'], info['nu'], info['gamma'], info['threshold']))
        cases = [end_to_end('sim', sim_run, truth, model, sim.ODOM_TOPIC, (sim.IMU_TOPIC,), 5.0, tmp)]
        model, info, n, injected, htruth = husky_case(types)
        print('husky model: motion 2 s window, %d training vectors (first half), %s, nu=%g, gamma=%.3g, '
              'threshold %.4g' % (n, info['method'], info['nu'], info['gamma'], info['threshold']))
        print()
        cases.append(end_to_end('husky+injected', injected, htruth, model, common.HUSKY_ODOM, (common.HUSKY_IMU,),
                                2.0, tmp))
    rows = []
    for c in cases:
        rows.append([c['name'], c['messages'], '%.0f' % c['seconds'], c['raw'], c['stored'],
                     '%.0fx' % (c['raw'] / max(1, c['stored'])), '%d/%d' % (c['caught'], c['anomalies']),
                     '%d/%d' % (c['kept'], c['anomalies']), c['windows'], c['false'],
                     c['lz4'], '%.1fx' % (c['raw'] / c['lz4']), c['bwi'], '%.0fx' % (c['raw'] / c['bwi'])])
    common.table(['run', 'messages', 'seconds', 'row JSON B', 'cc_log B', 'cc_log less', 'caught', 'kept whole',
                  'windows', 'false windows', 'rosbag --lz4 B', 'lz4 less', 'BWI 1/100 bz2 B', 'BWI less'], rows,
                 'End to end (cc_log: smart logger, json-xz, pre/post 100 messages):')
    match_rows = []
    for c in cases:
        for m in c['matches']:
            match_rows.append([c['name'], m['type'], '%.1f' % (m['end'] - m['start']), 'yes' if m['caught'] else 'NO',
                               'yes' if m['kept'] else 'NO', '%.2f' % m['delay']])
    common.table(['run', 'anomaly', 'length s', 'caught', 'kept whole', 'first trigger after onset s'], match_rows,
                 'Anomalies (caught: a classifier trigger between onset and end + window; kept: all its messages '
                 'in a saved window):')
    for c in cases:
        ratio = c['raw'] / max(1, c['stored'])
        print('target >= 100x less with every anomaly caught, %s: %.0fx, caught %d/%d -> %s' % (
            c['name'], ratio, c['caught'], c['anomalies'],
            'met' if ratio >= 100 and c['caught'] == c['anomalies'] else 'NOT met'))
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
