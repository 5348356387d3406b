"""Cost of cclog's progress bars (tqdm) per ``update()`` call: disabled, and drawing to /dev/null.

    python3 bench/progress_bars.py [--quick]

The commands call ``update()`` once per window file or record read, so the per-call cost bounds what a
bar adds to a loop. No data file: the loop counts ``--calls`` items.
"""
import argparse
import os
import time

import common  # noqa: F401  (puts src/ on sys.path)
from common import header, table

from cc_log.offline.progress import Progress


def per_call(enabled, calls, stream):
    """Microseconds per update() of one bar over ``calls`` calls (best of 3)."""
    best = float('inf')
    for _ in range(3):
        started = time.perf_counter()
        with Progress('bench', calls, enabled=enabled, stream=stream) as bar:
            for _ in range(calls):
                bar.update()
        best = min(best, time.perf_counter() - started)
    return best / calls * 1e6


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='10,000 calls instead of 1,000,000')
    parser.add_argument('--calls', type=int, default=None)
    args = parser.parse_args()
    calls = args.calls or (10000 if args.quick else 1000000)
    import tqdm
    header('Progress bars (tqdm %s): cost per update() call' % tqdm.__version__,
           ['data: none (a loop of %d update() calls, best of 3)' % calls])
    started = time.perf_counter()
    with open(os.devnull, 'w') as sink:
        rows = [['disabled (stderr not a terminal, no --progress)', per_call(False, calls, sink)],
                ['enabled, drawn to /dev/null (redraw at most every 0.1 s)', per_call(True, calls, sink)]]
    table(['bar', 'microseconds per update()'], rows)
    print('total %.1f s' % (time.perf_counter() - started))


if __name__ == '__main__':
    main()
