#!/usr/bin/env python3
"""The cost table in one command: every cost target of the node and of replay, each ratio from one run with both
sides alive in the same run, each run repeated, every run given.

    cd <tree> && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/cost.py                                # every part, 3 runs each (~40 min)
    python3 bench/cost.py --parts light,replay --runs 1  # some parts, once
    python3 bench/cost.py --parts keepall --wall-clock   # keepall on wall time, as a robot runs (no /clock)

Parts (each runs the bench that measures it, whose full output is printed first):
- light: ``cost_live.py --seconds 30 --rates 100,1000``: node CPU / ``rosbag record`` CPU of the same odometry
  and IMU, 100 + 100 Hz and 1000 + 1000 Hz (target <= 0.7);
- keepall: ``heavy_sensors.py --scenarios one,all --format bag-lz4`` at ~37 MB/s: a window open all the time,
  node / ``rosbag record --lz4`` (target <= 1.1); one 4 s window, node / ``rosbag record`` (target <= 0.8);
- keepall100: the same at ~100 MB/s (``--rate 100``);
  with --wall-clock both on wall time (``heavy_sensors.py --wall-clock``: no /clock, /use_sim_time false), the
  rows named so; without it, as the figures in docs/COST.md were made (``rosbag play --clock``, sim time);
- replay: ``cost_offline.py --rounds 3`` with bag-lz4 and json-xz windows: replay CPU / a plain deserializing
  rosbag read of the same topics, Husky and the 10-minute simulated bag (target <= 0.9; the best of 3
  alternating rounds of each).
The table: one row per measured ratio, its target, the ratio of each run, and whether every run met it.
"""
import argparse
import os
import re
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
PARTS = ('light', 'keepall', 'keepall100', 'replay')
LIGHT = re.compile(r'^target node CPU <= .* at (\d+) \+ \d+ Hz: ([0-9.]+)x')
REPLAY = re.compile(r'^target replay CPU .*?, (.+): (\d+)% \(CPU time\)')


def bench(script, *args):
    """The stdout of ``bench/<script> <args>`` (printed as it is), or of its failure."""
    command = [sys.executable, os.path.join(HERE, script)] + list(args)
    print('$ ' + ' '.join(['python3', 'bench/' + script] + list(args)))
    sys.stdout.flush()
    done = subprocess.run(command, stdout=subprocess.PIPE, universal_newlines=True)
    print(done.stdout)
    if done.returncode:
        print('(exit status %d)' % done.returncode)
    sys.stdout.flush()
    return done.stdout


def table_rows(text, first_header):
    """The rows (dicts by header) of the markdown table in ``text`` whose first header is ``first_header``."""
    rows, headers = [], None
    for line in text.splitlines():
        cells = [cell.strip() for cell in line.strip().strip('|').split('|')] if line.startswith('|') else None
        if cells is None:
            headers = None if rows else headers
            if rows:
                break
        elif headers is None and cells[0] == first_header:
            headers = cells
        elif headers is not None and not set(cells[0]) <= set('-'):
            rows.append(dict(zip(headers, cells)))
    return rows


def light():
    """{(workload, target): ratio} of a cost_live run."""
    found = {}
    for line in bench('cost_live.py', '--seconds', '30', '--rates', '100,1000').splitlines():
        match = LIGHT.match(line)
        if match:
            found[('light %s + %s Hz: node / rosbag record' % (match.group(1), match.group(1)), 0.7)] = \
                float(match.group(2))
    return found


class Lossy(float):
    """A ratio of a run in which the node kept fewer images than its windows span (it did less work)."""

    def __str__(self):
        return '%.2f (node kept %s images)' % (self, self.kept)


def keepall(rate, wall_clock=False):
    """{(workload, target): ratio} of a heavy_sensors run at ~``rate`` MB/s (one window, keep-all), on wall time
    when ``wall_clock``; a ratio of a run that kept fewer images than expected is ``Lossy``."""
    found = {}
    args = ['--scenarios', 'one,all', '--format', 'bag-lz4'] + (['--rate', '100'] if rate == 100 else []) \
        + (['--wall-clock'] if wall_clock else [])
    clock = ' on wall time' if wall_clock else ''
    names = {'all': ('keep-all ~%d MB/s%s: node / rosbag record --lz4' % (rate, clock), 1.1, 'node / record --lz4 CPU'),
             'one': ('one window ~%d MB/s%s: node / rosbag record' % (rate, clock), 0.8, 'node / record CPU')}
    for row in table_rows(bench('heavy_sensors.py', *args), 'scenario'):
        if row.get('scenario') not in names:
            continue
        name, target, column = names[row['scenario']]
        try:
            ratio = float(row[column])
            kept, expected = (int(n) for n in row['images kept / expected'].split('/'))
        except (KeyError, ValueError):
            continue
        if kept < expected:
            ratio = Lossy(ratio)
            ratio.kept = row['images kept / expected'].replace(' ', '')
        found[(name, target)] = ratio
    return found


def replay():
    """{(workload, target): ratio} of cost_offline runs (bag-lz4 and json-xz windows)."""
    found = {}
    for fmt in ('bag-lz4', 'json-xz'):
        for line in bench('cost_offline.py', '--rounds', '3', '--format', fmt).splitlines():
            match = REPLAY.match(line)
            if match:
                found[('replay %s, %s windows: replay / read' % (match.group(1), fmt), 0.9)] = \
                    100.0 / float(match.group(2))
    return found


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--parts', default=','.join(PARTS), help='comma-separated, of: %s' % ', '.join(PARTS))
    parser.add_argument('--runs', type=int, default=3, help='runs of each part (default 3)')
    parser.add_argument('--wall-clock', action='store_true',
                        help='keepall and keepall100 on wall time (heavy_sensors.py --wall-clock; default sim time)')
    args = parser.parse_args(argv)
    parts = [part.strip() for part in args.parts.split(',') if part.strip()]
    if not parts or any(part not in PARTS for part in parts) or args.runs < 1:
        parser.error('--parts: expected some of %s; --runs: at least 1' % ', '.join(PARTS))
    started = time.time()
    common.header('The cost table', ['parts: %s, %d run(s) each; every ratio from one run, both sides alive '
                                     'in it%s' % (', '.join(parts), args.runs,
                                                  '; keepall on wall time' if args.wall_clock else '')])
    measure = {'light': light, 'keepall': lambda: keepall(37, args.wall_clock),
               'keepall100': lambda: keepall(100, args.wall_clock), 'replay': replay}
    ratios = {}  # (workload, target) -> [ratio of each run]
    for part in parts:
        for run in range(args.runs):
            print('== %s, run %d of %d' % (part, run + 1, args.runs))
            for key, ratio in measure[part]().items():
                ratios.setdefault(key, []).append(ratio)
    rows = []
    for (workload, target), values in ratios.items():
        met = len(values) == args.runs and all(value <= target for value in values)
        rows.append([workload, '<= %.1f' % target, ', '.join(str(value) if isinstance(value, Lossy) else
                                                             '%.2f' % value for value in values),
                     'not comparable' if any(isinstance(value, Lossy) for value in values) else
                     'yes' if met else 'NO'])
    print()
    common.table(['workload: ratio', 'target', 'each run', 'met in every run'], rows,
                 'The cost table (CPU ratios, each from one run):')
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
