#!/usr/bin/env python3
"""Fleet scale on Dask: collect + learn + replay over many simulated robot-runs, one process vs 1 and 2 Dask
workers; streamed learning over partitions vs the exact SVM on a subsample.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/fleet.py                        # 40 runs of 1 min at 100 Hz (a tenth of the target's odometry)
    python3 bench/fleet.py --runs 40 --minutes 10 # the full target: 40 runs of 10 min (2.4 M odometry messages)
    python3 bench/fleet.py --quick                # 4 runs of 1 min (tests)

Pipeline: the real ``cclog`` in a subprocess, as users run it, over the directory of runs: ``collect``
(motion features, window 500, stride 25) of every run, ``learn`` (auto: the exact OneClassSVM) on the vectors
of the even runs (no anomalies), ``replay`` (the model on /odom) of every run (the odd ones have anomalies),
each with ``--workers 0`` (the one-process path), ``--workers 1`` and ``--workers 2`` (a local Dask cluster,
started by the command: its start-up is in the wall time). Messages/s are odometry messages read per
wall second. The outputs of the three engines are compared file for file (vector files, windows) and the models
array for array.

Learning: partitions of the same runs' vectors at ``--learn-stride`` (vectors of the time an anomaly of the
truth file, plus the window, reaches are left out), 80 % of the runs to train, 20 % held out:
``fleet.train_streamed`` (scaler from moments, Nystroem components from a sample, ``SGDOneClassSVM.partial_fit``
over the partitions) on 1 and 2 workers, and ``learning.train`` 'auto' (the exact SVM on an even subsample of
DEFAULT_MAX_EXACT vectors, all vectors gathered in one process); the false-positive rate of both on the held-out
runs, with its 95 % Hoeffding bound. Peak memory: of every worker (ru_maxrss) and of this process.
"""
import argparse
import filecmp
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log import fleet, learning, sim  # noqa: E402
from cc_log.features import FeatureConfig  # noqa: E402

CCLOG = os.path.join(common.ROOT, 'scripts', 'cclog')
WINDOW = '500'
STRIDE = 25


def children_cpu():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def cclog(*args):
    """``cclog ARGS --json`` in a subprocess: (document, wall seconds, CPU seconds of it and its worker processes)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [common.SRC, os.environ.get('PYTHONPATH')])))
    started, cpu = time.perf_counter(), children_cpu()
    result = subprocess.run([sys.executable, CCLOG] + [str(a) for a in args] + ['--json'], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, universal_newlines=True, env=env)
    wall, cpu = time.perf_counter() - started, children_cpu() - cpu
    if result.returncode != 0:
        raise SystemExit('cclog %s failed: %s' % (' '.join(map(str, args)), result.stderr))
    return json.loads(result.stdout), wall, cpu


def simulate(job):
    """One simulated run (odometry at ``rate``) and its truth file: ``anomalous*`` runs with anomalies."""
    path, minutes, seed, rate = job
    anomalies = max(1, min(6, int(minutes * 60 // 30) - 1)) if 'anomalous' in os.path.basename(path) else 0
    sim.simulate_to_bag(path, sim.SimConfig(rate=rate, seed=seed, minutes=minutes, anomalies=anomalies))
    return {'messages': int(minutes * 60 * rate)}


def same_files(a, b):
    names = sorted(os.path.relpath(os.path.join(d, f), a) for d, _, fs in os.walk(a) for f in fs)
    other = sorted(os.path.relpath(os.path.join(d, f), b) for d, _, fs in os.walk(b) for f in fs)
    return names == other and not filecmp.cmpfiles(a, b, names, shallow=False)[1]


def model_arrays(path):
    with open(path) as stream:
        document = json.load(stream)
    document.pop('info')
    return document


def pipeline(bags_dir, work, workers):
    """collect, learn, replay with ``--workers workers``: rows and output paths."""
    out = os.path.join(work, 'w%d' % workers)
    engine = ['--workers', workers]
    collected, collect_wall, collect_cpu = cclog('collect', bags_dir, '--topic', '/odom', '--out', out + '/vectors',
                                                 '--window', WINDOW, '--stride', STRIDE, *engine)
    learned, learn_wall, learn_cpu = cclog('learn', '--train', out + '/vectors/nominal*', '--model',
                                           out + '/model.json', *engine)
    replayed, replay_wall, replay_cpu = cclog('replay', bags_dir, '--topic', '/odom', '--model', out + '/model.json',
                                              '--out', out + '/windows', *engine)
    messages = collected['messages']
    return {'workers': workers, 'out': out, 'messages': messages, 'vectors': collected['vectors'],
            'windows': replayed['windows'], 'collect': collect_wall, 'learn': learn_wall, 'replay': replay_wall,
            'collect_cpu': collect_cpu, 'learn_cpu': learn_cpu, 'replay_cpu': replay_cpu,
            'learn_vectors': learned['info']['vectors_nominal'], 'total': collect_wall + learn_wall + replay_wall,
            'total_cpu': collect_cpu + learn_cpu + replay_cpu}


def partition_of_run(job):
    """Nominal vectors of one run: every ``stride``-th window of /odom not reached by an anomaly of its truth."""
    from cc_log import bagio
    path, stride = job
    config = FeatureConfig('motion', WINDOW)
    stamps, X = bagio.feature_vectors(path, '/odom', config, stride)
    reach = int(WINDOW) / 100.0  # seconds a 500-message window spans at 100 Hz
    keep = np.ones(len(stamps), dtype=bool)
    for anomaly in sim.load_truth(sim.truth_path(path)):
        keep &= ~((stamps >= anomaly['start']) & (stamps <= anomaly['end'] + reach))
    return {'vectors': {'nominal': X[keep]}, 'config': config, 'messages': int(keep.sum()),
            'peak_rss_mb': fleet.peak_rss_mb()}


def false_positive_rate(model, X):
    flagged = int(np.sum(model.scores(X) < model.threshold))
    bound = math.sqrt(math.log(2 / 0.05) / (2 * len(X)))  # Hoeffding, 95 %
    return flagged, flagged / float(len(X)), bound


def learning_rows(bags, stride, workers_list):
    split = max(1, int(round(0.8 * len(bags))))
    train, held = bags[:split], bags[split:] or bags[-1:]
    rows = []
    with fleet.Engine(max(workers_list)) as engine:
        started = time.perf_counter()
        held_X = np.concatenate([o.value['vectors']['nominal']
                                 for o in engine.run(partition_of_run, [(p, stride) for p in held])])
        outcomes = engine.run(partition_of_run, [(p, stride) for p in train])
        X = np.concatenate([o.value['vectors']['nominal'] for o in outcomes])
        compute = time.perf_counter() - started
        with common.Timer() as timer:
            exact, info = learning.train(X, None, FeatureConfig('motion', WINDOW), method='auto')
        fp = false_positive_rate(exact, held_X)
        name = 'exact OCSVM on %d training vectors%s (one process, all %d vectors in it)' % (
            info['vectors_train'], ', an even subsample' if info['subsampled'] else '', len(X))
        rows.append([name, '-', len(X), timer.wall, '%.0f (this process)' % fleet.peak_rss_mb(),
                     '%d/%d = %.4f +- %.4f' % (fp[0], len(held_X), fp[1], fp[2])])
    del X
    for workers in workers_list:
        with fleet.Engine(workers) as engine, common.Timer() as timer:
            model, info = fleet.train_streamed(engine, partition_of_run, [(p, stride) for p in train])
        fp = false_positive_rate(model, held_X)
        rows.append(['streamed Nystroem + SGD partial_fit (%d partitions)' % info['partitions'], workers,
                     info['vectors_train'] + info['vectors_held_out'], timer.wall,
                     '%.0f per worker' % info['worker_peak_rss_mb'],
                     '%d/%d = %.4f +- %.4f' % (fp[0], len(held_X), fp[1], fp[2])])
    return rows, compute, len(held_X)


def scheduler_overhead(workers, tasks=200):
    """Seconds per empty task on a local cluster of ``workers`` (submit, run, gather)."""
    with fleet.Engine(workers) as engine:
        engine.run(int, range(10))  # warm up
        started = time.perf_counter()
        engine.run(int, range(tasks))
        return (time.perf_counter() - started) / tasks


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--runs', type=int, default=40)
    parser.add_argument('--minutes', type=float, default=1.0)
    parser.add_argument('--rate', type=float, default=100.0)
    parser.add_argument('--learn-stride', type=int, default=5, help='a learning vector every N messages')
    parser.add_argument('--work', help='directory for bags and outputs (default: a temporary one)')
    parser.add_argument('--quick', action='store_true', help='4 runs of 1 min')
    parser.add_argument('--learning-only', action='store_true', help='only the learning rows')
    args = parser.parse_args()
    if args.quick:
        args.runs, args.minutes = 4, 1.0
    work = args.work or tempfile.mkdtemp(prefix='cc_log_fleet_')
    bags_dir = os.path.join(work, 'runs')
    os.makedirs(bags_dir, exist_ok=True)
    jobs = [(os.path.join(bags_dir, '%s%02d.bag' % ('anomalous' if i % 2 else 'nominal', i)), args.minutes, 100 + i,
             args.rate) for i in range(args.runs)]
    with fleet.Engine(2) as engine:  # the runs: made once, kept in --work
        missing = [job for job in jobs if not os.path.exists(sim.truth_path(job[0]))]
        bad = fleet.failures(engine.run(simulate, missing))
        if bad:
            raise SystemExit(bad[0])
    full = 40 * 10 * 60 * 100.0 * 2  # the target: 40 runs of 10 min, odometry and IMU at 100 Hz
    messages = args.runs * args.minutes * 60 * args.rate
    common.header('Fleet scale on Dask: collect + learn + replay over %d runs' % args.runs, [
        'data: %d simulated BWIBot runs (cc_log.sim, seeds 100..%d; odd ones with anomalies) of %g min at %g Hz, '
        'odometry only: %d messages (%.3f of the target\'s ~4.8 M messages of 40 runs x 10 min, odometry + IMU) '
        'in %s'
        % (args.runs, 99 + args.runs, args.minutes, args.rate, messages, messages / full, bags_dir)])

    rows = [] if args.learning_only else pipeline_rows(bags_dir, work)
    learn_table, compute, held = learning_rows([job[0] for job in jobs], args.learn_stride, (1, 2))
    common.table(['model', 'workers', 'vectors', 'train wall s', 'peak RSS MB', 'held-out FP (95% bound)'],
                 learn_table, title='Learning at fleet scale (vectors every %d messages; %d held-out nominal vectors '
                 'of 20%% of the runs; %.0f s to compute the vectors)' % (args.learn_stride, held, compute))
    print('total %.0f s' % sum(row['total'] for row in rows))


def pipeline_rows(bags_dir, work):
    """The end-to-end tables (one process, 1 and 2 workers) and the per-message costs; the rows."""
    rows = [pipeline(bags_dir, work, workers) for workers in (0, 1, 2)]
    base = rows[0]
    table = []
    for row in rows:
        table.append(['this process (--workers 0)' if row['workers'] == 0 else 'Dask, %d worker(s)' % row['workers'],
                      row['messages'], row['vectors'], row['windows'],
                      row['messages'] / row['collect'], row['learn'], row['messages'] / row['replay'], row['total'],
                      row['messages'] / row['total'], base['total'] / row['total']])
    common.table(['engine', 'messages', 'vectors', 'windows', 'collect msg/s', 'learn s', 'replay msg/s', 'total s',
                  'end-to-end msg/s', 'speedup'], table, title='End to end (wall seconds, cluster start-up included)')
    common.table(['engine', 'collect CPU s', 'learn CPU s', 'replay CPU s', 'total CPU s'],
                 [[r['workers'], r['collect_cpu'], r['learn_cpu'], r['replay_cpu'], r['total_cpu']] for r in rows],
                 title='CPU seconds of the commands and their worker processes (the machine is shared: wall seconds '
                 'include waiting for a core)')
    for row in rows[1:]:
        same = (same_files(base['out'] + '/vectors', row['out'] + '/vectors')
                and same_files(base['out'] + '/windows', row['out'] + '/windows')
                and model_arrays(base['out'] + '/model.json') == model_arrays(row['out'] + '/model.json'))
        print('identical to the one-process outputs with %d worker(s) (vector files, model, window files): %s'
              % (row['workers'], 'yes' if same else 'NO'))
    print()
    print('per-message cost, one process: collect %.0f us wall, %.0f us CPU; replay %.0f us wall, %.0f us CPU; '
          'learn (exact, %d vectors) %.1f s wall, %.1f s CPU'
          % (1e6 * base['collect'] / base['messages'], 1e6 * base['collect_cpu'] / base['messages'],
             1e6 * base['replay'] / base['messages'], 1e6 * base['replay_cpu'] / base['messages'],
             base['learn_vectors'], base['learn'], base['learn_cpu']))
    overhead = scheduler_overhead(2)
    print('scheduler overhead per task (empty task, local cluster of 2): %.1f ms' % (1e3 * overhead))
    print()
    return rows


if __name__ == '__main__':
    main()
