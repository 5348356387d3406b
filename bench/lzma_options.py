#!/usr/bin/env python3
"""json-xz's LZMA2 options: bytes against CPU for the match finders and searches on real and simulated windows.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/lzma_options.py            # best of 5 per option set
    python3 bench/lzma_options.py --quick    # best of 1, Husky odometry only (tests)

The same JSON text (``json_xz.dumps(json_xz.document(...))``, what the writer compresses) is compressed with
``json_xz.compress(text, 6, options)`` for each option set below; the table gives the summed xz bytes as a
share of the row-per-message JSON of the same messages (``msg_codec.row_json_bytes``: the 4% target of
issue 14 is on the whole Husky odometry) and the CPU seconds of the compression alone (best of ``--rounds``,
the option sets alternating within each round). Cases:
- Husky odometry, whole topic as one window (3952 messages) and in windows of 300;
- Husky odometry + IMU (the replay's windows), whole, and in windows of 30 s;
- simulated BWIBot odometry, 1 minute at 100 Hz (cc_log.sim seed 1), as one window.
"""
import argparse
import lzma
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.base import msg_codec  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.storage.formats import json_xz  # noqa: E402

BASE = {'lc': 1, 'pb': 0}
OPTION_SETS = [  # (name, options on top of preset 6)
    ('preset 6 alone', {}),
    ('bt4 nice_len 48 depth 4', dict(BASE, nice_len=48, depth=4)),
    ('hc4 nice_len 48 depth 4', dict(BASE, mf=lzma.MF_HC4, nice_len=48, depth=4)),
    ('hc3 nice_len 48 depth 4', dict(BASE, mf=lzma.MF_HC3, nice_len=48, depth=4)),
    ('hc3 nice_len 48 depth 8', dict(BASE, mf=lzma.MF_HC3, nice_len=48, depth=8)),
    ('hc3 nice_len 96 depth 8', dict(BASE, mf=lzma.MF_HC3, nice_len=96, depth=8)),
    ('bt2 nice_len 48 depth 4', dict(BASE, mf=lzma.MF_BT2, nice_len=48, depth=4)),
    ('MODE_FAST hc4 nice_len 32', dict(BASE, mf=lzma.MF_HC4, mode=lzma.MODE_FAST, nice_len=32, depth=4)),
]
OPTIONS = dict(OPTION_SETS)


def in_windows(records, count=None, seconds=None):
    """``records`` cut into consecutive windows of ``count`` records or ``seconds`` of stamps (whole: neither)."""
    if count:
        return [records[i:i + count] for i in range(0, len(records), count)]
    if seconds:
        windows, start = [], None
        for record in records:
            if start is None or record.stamp >= start + seconds:
                windows.append([])
                start = record.stamp
            windows[-1].append(record)
        return windows
    return [records]


def measure(windows, rounds):
    """Row JSON bytes and, per option set, (xz bytes, best CPU seconds) of compressing every window's text."""
    raw = sum(msg_codec.row_json_bytes(record.msg) for window in windows for record in window)
    texts = [json_xz.dumps(json_xz.document(window, {'codec': 'json-xz'})).encode('utf-8') for window in windows]
    sizes, best = {}, {}
    for _ in range(rounds):
        for name, options in OPTION_SETS:
            with common.Timer() as timer:
                sizes[name] = sum(len(json_xz.compress(text, 6, options)) for text in texts)
            best[name] = min(best.get(name, float('inf')), timer.cpu)
    return raw, sum(map(len, texts)), [(name, sizes[name], best[name]) for name, _ in OPTION_SETS]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rounds', type=int, default=5)
    parser.add_argument('--quick', action='store_true', help='one round, Husky odometry only')
    args = parser.parse_args(argv)
    rounds = 1 if args.quick else args.rounds
    began = time.perf_counter()
    common.header('json-xz LZMA2 options: bytes and CPU', [common.describe_data(common.HUSKY_BAG)])
    odometry = common.husky_records((common.HUSKY_ODOM,))
    cases = [('Husky odometry, whole', in_windows(odometry))]
    if not args.quick:
        both = common.husky_records((common.HUSKY_ODOM, common.HUSKY_IMU))
        simulated, _ = common.sim_records(sim.SimConfig(rate=100.0, seed=1, minutes=1.0, anomalies=0))
        cases += [('Husky odometry, windows of 300', in_windows(odometry, count=300)),
                  ('Husky odometry + IMU, whole', in_windows(both)),
                  ('Husky odometry + IMU, windows of 30 s', in_windows(both, seconds=30.0)),
                  ('sim odometry 1 min, whole', in_windows(simulated))]
    for title, windows in cases:
        raw, text, results = measure(windows, rounds)
        reference = dict((name, (size, cpu)) for name, size, cpu in results)['bt4 nice_len 48 depth 4']
        common.table(
            ['options (preset 6 +)', 'xz bytes', '% of row JSON', 'bytes vs bt4/48/4', 'CPU s', 'CPU vs bt4/48/4'],
            [[name + (' (written)' if OPTIONS[name] == json_xz.FILTER_OPTIONS else ''), size,
              '%.3f%%' % (100.0 * size / raw), '%+.2f%%' % (100.0 * (size / reference[0] - 1)), '%.3f' % cpu,
              '%.0f%%' % (100.0 * cpu / reference[1])] for name, size, cpu in results],
            title='%s: %d window(s), %d messages, row JSON %d bytes, JSON text %d bytes, best of %d'
                  % (title, len(windows), sum(map(len, windows)), raw, text, rounds))
    print('total %.1f s' % (time.perf_counter() - began))
    return 0


if __name__ == '__main__':
    sys.exit(main())
