#!/usr/bin/env python3
"""Speed of ``cclog info`` and ``cclog stats`` on a directory of many window files (windows a second).

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/info_speed.py                      # 10,000 windows
    python3 bench/info_speed.py --quick              # 200 windows (tests)
    python3 bench/info_speed.py --windows 2000 --format json-xz

Writes N window files (``log_format.write_window``, as the writer thread writes them) into a temporary
directory: each holds ``--messages`` simulated odometry and as many IMU messages (100 Hz, as bytes with their
connection headers, as the nodes hand them over; one in ten json-xz unless ``--format`` says one format). Then
times, in this process, ``cclog info DIR --json`` and ``cclog stats DIR --json`` (each window's figures from its
metadata: ``log_format.read_metadata``), and ``cclog info --full`` (every message read, decoded and measured) on
the first ``--full-windows`` files (at most N).
"""
import argparse
import contextlib
import io
import os
import shutil
import tempfile
import time

import common  # noqa: F401  (puts src/ on sys.path)
from common import Timer, header, table

from cc_log import sim
from cc_log.base.raw_message import class_header
from cc_log.base.records import LogWindow, Record, Trigger
from cc_log.offline import cli
from cc_log.storage import log_format


def make_windows(directory, count, messages, fmt):
    """Write ``count`` windows of ``messages`` odometry and IMU messages each; return the bytes written."""
    simulator = sim.Simulator(sim.SimConfig(minutes=messages / 100.0 / 60 + 0.01, anomalies=0, imu=True, seed=5))
    classes = {}
    template = []
    for topic, stamp, msg in simulator.messages():
        if topic not in (sim.ODOM_TOPIC, sim.IMU_TOPIC):
            continue
        connection = classes.setdefault(topic, dict(class_header(topic, type(msg)), callerid='/sim', latching='0'))
        template.append((stamp, topic, sim.serialized(msg), connection))
    per_topic = {}
    kept = []
    for item in template:  # the first ``messages`` of each topic
        if per_topic.get(item[1], 0) < messages:
            per_topic[item[1]] = per_topic.get(item[1], 0) + 1
            kept.append(item)
    first = kept[0][0]
    total = 0
    for number in range(count):
        shift = 3600.0 + 20.0 * number  # windows 20 s apart (the stamps of a window file are not checked here)
        records = [Record(stamp - first + shift + sim.DEFAULT_START_TIME, topic, None, 0, raw, connection)
                   for stamp, topic, raw, connection in kept]
        trigger = Trigger(records[len(records) // 2].stamp, 'classifier', -0.5, 'classifier')
        chosen = fmt or ('json-xz' if number % 10 == 0 else 'bag-lz4')
        _, size = log_format.write_window(LogWindow(records, [trigger]), directory, chosen,
                                          {'threshold': 0.0, 'pre': '2 s', 'post': '2 s'})
        total += size
    return total


def timed(argv):
    """Seconds of ``cli.main(argv)`` (its output discarded)."""
    with Timer() as timer, contextlib.redirect_stdout(io.StringIO()):
        code = cli.main(argv)
    if code != 0:
        raise SystemExit('cclog %s failed (%d)' % (' '.join(argv), code))
    return timer.wall


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='200 windows, --full on 20')
    parser.add_argument('--windows', type=int, default=None, help='window files (default 10,000)')
    parser.add_argument('--messages', type=int, default=100, help='odometry (and IMU) messages a window')
    parser.add_argument('--full-windows', type=int, default=None, help='files read by info --full (default 200)')
    parser.add_argument('--format', choices=log_format.Format.ALL, default=None,
                        help='one format (default: bag-lz4, one in ten json-xz)')
    args = parser.parse_args()
    count = args.windows or (200 if args.quick else 10000)
    full = min(count, args.full_windows or (20 if args.quick else 200))
    header('cclog info / stats on %d window files: windows a second' % count,
           ['data: %d simulated windows (cc_log.sim seed 5), %d odometry + %d IMU messages each (100 Hz, as bytes), '
            '%s' % (count, args.messages, args.messages, args.format or 'bag-lz4 with one in ten json-xz')])
    started = time.perf_counter()
    directory = tempfile.mkdtemp(prefix='cc_log_info_speed_')
    try:
        with Timer() as writing:
            stored = make_windows(directory, count, args.messages, args.format)
        sample = os.path.join(directory, 'full')
        os.mkdir(sample)
        for path in log_format.window_files(directory)[:full]:
            os.link(path, os.path.join(sample, os.path.basename(path)))
        rows = [['write_window (to make them)', count, writing.wall, count / writing.wall]]
        for label, argv, windows in (('cclog info --json', ['info', directory, '--json'], count),
                                     ('cclog stats --json', ['stats', directory, '--json'], count),
                                     ('cclog info --full --json', ['info', sample, '--full', '--json'], full)):
            seconds = timed(argv)
            rows.append([label, windows, seconds, windows / seconds])
        print('%d files, %.1f MB' % (count, stored / 1e6))
        table(['command', 'windows', 'seconds', 'windows/s'], rows)
    finally:
        shutil.rmtree(directory, ignore_errors=True)
    print('total %.1f s' % (time.perf_counter() - started))


if __name__ == '__main__':
    main()
