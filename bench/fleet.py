#!/usr/bin/env python3
"""Fleet scale on Dask: collect + learn + replay over many simulated robot-runs, one process vs 1 and 2 Dask
workers; streamed learning over partitions vs the exact SVM on a subsample.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/fleet.py --work W               # 40 runs of 1 min at 100 Hz, odometry + IMU, into W
    python3 bench/fleet.py --work W --minutes 10  # the full target: 40 runs of 10 min (~4.8 M messages)
    python3 bench/fleet.py --work W --stage collect --engines 0   # one part; a later call resumes from W
    python3 bench/fleet.py --quick                # 4 runs of 1 min (tests)

Data: the runs (odometry and IMU at ``--rate``, ``--no-imu`` for odometry only) are simulated once into
``--work``/runs and reused by every later invocation with the same ``--work`` (which refuses other run settings).
Pipeline: the real ``cclog`` in a subprocess, as users run it, over the directory of runs: ``collect``
(motion features of /odom, window 500, stride 25) of every run, ``learn`` (auto: the exact OneClassSVM) on the
vectors of the even runs (no anomalies), ``replay`` (the model on /odom, /imu/data kept beside it in the windows)
of every run (the odd ones have anomalies), each with ``--workers 0`` (the one-process path), ``--workers 1``
and ``--workers 2`` (a local Dask cluster, started by the command: its start-up is in the wall time).
Each finished step is stored in ``--work``/results.json, so ``--stage`` / ``--engines`` run parts and a later
call prints the whole table. Messages/s count every message read: collect reads /odom, replay /odom and
/imu/data. The outputs of the engines are compared file for file (vector files, windows) and the models
array for array.

Learning: partitions of the same runs' vectors at ``--learn-stride`` (vectors of the time an anomaly of the
truth file, plus the window, reaches are left out), 80 % of the runs to train, 20 % held out:
``partition_learning.train_streamed`` (scaler from moments, Nystroem components from a sample,
``SGDOneClassSVM.partial_fit`` over the partitions) on 1 and 2 workers, and ``learning.train`` 'auto' (the exact
SVM on an even subsample of DEFAULT_MAX_EXACT vectors, all vectors gathered in one process); the false-positive
rate of both on the held-out runs, with its 95 % Hoeffding bound. Peak memory (VmHWM): of every worker and of the
gathering process.
"""
import argparse
import filecmp
import json
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.offline import fleet, partition_learning  # noqa: E402
from cc_log.learning import learning  # noqa: E402
from cc_log import sim  # noqa: E402
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
    """One simulated run (odometry, and IMU with ``imu``, at ``rate``) and its truth file: ``anomalous*`` runs
    with anomalies."""
    path, minutes, seed, rate, imu = job
    anomalies = max(1, min(6, int(minutes * 60 // 30) - 1)) if 'anomalous' in os.path.basename(path) else 0
    sim.simulate_to_bag(path, sim.SimConfig(rate=rate, seed=seed, minutes=minutes, anomalies=anomalies, imu=imu))
    return {'messages': int(minutes * 60 * rate) * (2 if imu else 1)}


def make_runs(work, runs, minutes, rate, imu):
    """The simulated runs in ``work/runs`` (made once: a later call with the same settings reuses them); their
    paths. SystemExit when ``work`` holds runs of other settings."""
    bags_dir = os.path.join(work, 'runs')
    os.makedirs(bags_dir, exist_ok=True)
    settings = {'runs': runs, 'minutes': minutes, 'rate': rate, 'imu': imu}
    stored = os.path.join(bags_dir, 'settings.json')
    if os.path.exists(stored):
        with open(stored) as stream:
            if json.load(stream) != settings:
                raise SystemExit('%s: runs of other settings (%s); use another --work' % (stored, open(stored).read()))
    else:
        with open(stored, 'w') as stream:
            json.dump(settings, stream)
    jobs = [(os.path.join(bags_dir, '%s%02d.bag' % ('anomalous' if i % 2 else 'nominal', i)), minutes, 100 + i,
             rate, imu) for i in range(runs)]
    missing = [job for job in jobs if not os.path.exists(sim.truth_path(job[0]))]  # the truth file comes last
    if missing:
        with fleet.Engine(2) as engine:
            bad = fleet.failures(engine.run(simulate, missing))
        if bad:
            raise SystemExit(bad[0])
    return bags_dir, [job[0] for job in jobs]


def same_files(a, b):
    names = sorted(os.path.relpath(os.path.join(d, f), a) for d, _, fs in os.walk(a) for f in fs)
    other = sorted(os.path.relpath(os.path.join(d, f), b) for d, _, fs in os.walk(b) for f in fs)
    return names == other and not filecmp.cmpfiles(a, b, names, shallow=False)[1]


def model_arrays(path):
    with open(path) as stream:
        document = json.load(stream)
    document.pop('info')
    return document


STAGES = ('collect', 'learn', 'replay')


def run_stage(stage, bags_dir, out, workers, imu):
    """One step of the pipeline with ``--workers workers`` into ``out``: ``{'wall', 'cpu', 'messages' (read),
    'count' (vectors, training vectors or windows), 'load'}``."""
    engine = ['--workers', workers]
    load = os.getloadavg()[0]
    if stage == 'collect':
        shutil.rmtree(out + '/vectors', ignore_errors=True)
        document, wall, cpu = cclog('collect', bags_dir, '--topic', '/odom', '--out', out + '/vectors',
                                    '--window', WINDOW, '--stride', STRIDE, *engine)
        messages, count = document['messages'], document['vectors']
    elif stage == 'learn':
        document, wall, cpu = cclog('learn', '--train', out + '/vectors/nominal*', '--model', out + '/model.json',
                                    *engine)
        messages = count = document['info']['vectors_nominal']
    else:
        shutil.rmtree(out + '/windows', ignore_errors=True)
        side = ['--side-topic', '/imu/data'] if imu else []
        document, wall, cpu = cclog('replay', bags_dir, '--topic', '/odom', *side, '--model', out + '/model.json',
                                    '--out', out + '/windows', *engine)
        messages, count = document['messages'], document['windows']
    return {'wall': wall, 'cpu': cpu, 'messages': messages, 'count': count, 'load': load}


def load_results(work):
    path = os.path.join(work, 'results.json')
    if not os.path.exists(path):
        return {}
    with open(path) as stream:
        return json.load(stream)


def save_results(work, results):
    path = os.path.join(work, 'results.json')
    with open(path + '.new', 'w') as stream:
        json.dump(results, stream, indent=1, sort_keys=True)
    os.replace(path + '.new', path)


def partition_of_run(job):
    """Nominal vectors of one run: every ``stride``-th window of /odom not reached by an anomaly of its truth."""
    from cc_log.storage.bag import bagio
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
        with fleet.Engine(workers) as engine:
            with common.Timer() as timer:
                model, info = partition_learning.train_streamed(engine, partition_of_run, [(p, stride) for p in train])
            every = sorted(engine.client.run(fleet.peak_rss_mb).values())  # VmHWM of every worker process
        fp = false_positive_rate(model, held_X)
        rows.append(['streamed Nystroem + SGD partial_fit (%d partitions)' % info['partitions'], workers,
                     info['vectors_train'] + info['vectors_held_out'], timer.wall,
                     'workers %s' % ', '.join('%.0f' % mb for mb in every),
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
    parser.add_argument('--no-imu', dest='imu', action='store_false', help='odometry only (no /imu/data)')
    parser.add_argument('--learn-stride', type=int, default=5, help='a learning vector every N messages')
    parser.add_argument('--work', help='directory for runs, outputs and results.json, reused by later calls '
                        '(default: a temporary one)')
    parser.add_argument('--stage', choices=STAGES + ('all', 'none'), default='all',
                        help='the pipeline step(s) to run now (each needs the one before it, run earlier)')
    parser.add_argument('--engines', default='0,1,2', help='--workers of the pipeline runs (0: one process)')
    parser.add_argument('--quick', action='store_true', help='4 runs of 1 min')
    parser.add_argument('--learning-only', action='store_true', help='only the learning rows')
    parser.add_argument('--no-learning', dest='learning', action='store_false', help='no learning rows')
    args = parser.parse_args()
    if args.quick:
        args.runs, args.minutes = 4, 1.0
    engines = [int(value) for value in args.engines.split(',')]
    work = args.work or tempfile.mkdtemp(prefix='cc_log_fleet_')
    bags_dir, bags = make_runs(work, args.runs, args.minutes, args.rate, args.imu)
    full = 40 * 10 * 60 * 100.0 * 2  # the target: 40 runs of 10 min, odometry and IMU at 100 Hz
    messages = args.runs * args.minutes * 60 * args.rate * (2 if args.imu else 1)
    common.header('Fleet scale on Dask: collect + learn + replay over %d runs' % args.runs, [
        'data: %d simulated BWIBot runs (cc_log.sim, seeds 100..%d; odd ones with anomalies) of %g min at %g Hz, '
        '%s: %d messages (%.3f of the target\'s ~4.8 M messages of 40 runs x 10 min, odometry + IMU) in %s'
        % (args.runs, 99 + args.runs, args.minutes, args.rate, 'odometry + IMU' if args.imu else 'odometry only',
           messages, messages / full, bags_dir)])
    if not args.learning_only:
        results = load_results(work)
        for workers in engines:
            for stage in (STAGES if args.stage == 'all' else [s for s in STAGES if s == args.stage]):
                print('%s --workers %d ...' % (stage, workers))
                sys.stdout.flush()
                results['%s/w%d' % (stage, workers)] = run_stage(stage, bags_dir, os.path.join(work, 'w%d' % workers),
                                                                 workers, args.imu)
                save_results(work, results)
        pipeline_tables(work, results, messages, overhead=args.stage == 'none' or len(engines) > 1)
    if args.learning_only or (args.learning and args.stage == 'all'):
        learn_table, compute, held = learning_rows(bags, args.learn_stride, (1, 2))
        common.table(['model', 'workers', 'vectors', 'train wall s', 'peak RSS MB (VmHWM)', 'held-out FP (95% bound)'],
                     learn_table, title='Learning at fleet scale (vectors every %d messages; %d held-out nominal '
                     'vectors of 20%% of the runs; %.0f s to compute the vectors)' % (args.learn_stride, held, compute))


def pipeline_tables(work, results, bag_messages, overhead=True):
    """The end-to-end tables of the engines whose three steps are in ``results``, the comparison of their
    outputs and the per-message costs (one process)."""
    rows = []
    for workers in sorted(set(int(key.split('/w')[1]) for key in results)):
        steps = [results.get('%s/w%d' % (stage, workers)) for stage in STAGES]
        if None in steps:
            print('--workers %d: %s not run yet' % (workers, ', '.join(s for s, r in zip(STAGES, steps) if r is None)))
            continue
        collect, learn, replay = steps
        total = sum(step['wall'] for step in steps)
        rows.append({'workers': workers, 'collect': collect, 'learn': learn, 'replay': replay, 'total': total,
                     'cpu': sum(step['cpu'] for step in steps), 'out': os.path.join(work, 'w%d' % workers)})
    if not rows:
        return
    base = rows[0]
    common.table(['engine', 'load at start', 'collect msg/s', 'vectors', 'learn s', 'replay msg/s', 'windows',
                  'total s', 'end-to-end msg/s', 'speedup'],
                 [['this process (--workers 0)' if r['workers'] == 0 else 'Dask, %d worker(s)' % r['workers'],
                   '%.1f' % r['collect']['load'], r['collect']['messages'] / r['collect']['wall'],
                   r['collect']['count'], r['learn']['wall'], r['replay']['messages'] / r['replay']['wall'],
                   r['replay']['count'], r['total'], bag_messages / r['total'],
                   base['total'] / r['total'] if base['workers'] == 0 else float('nan')] for r in rows],
                 title='End to end (wall seconds, cluster start-up included; collect reads /odom, replay /odom + '
                 '/imu/data; end-to-end: the runs\' messages / total s)')
    common.table(['engine', 'collect CPU s', 'learn CPU s', 'replay CPU s', 'total CPU s'],
                 [[r['workers'], r['collect']['cpu'], r['learn']['cpu'], r['replay']['cpu'], r['cpu']] for r in rows],
                 title='CPU seconds of the commands and their worker processes (the machine is shared: wall seconds '
                 'include waiting for a core)')
    for row in rows[1:]:
        same = (same_files(base['out'] + '/vectors', row['out'] + '/vectors')
                and same_files(base['out'] + '/windows', row['out'] + '/windows')
                and model_arrays(base['out'] + '/model.json') == model_arrays(row['out'] + '/model.json'))
        print('identical to the --workers %d outputs with %d worker(s) (vector files, model, window files): %s'
              % (base['workers'], row['workers'], 'yes' if same else 'NO'))
    print()
    collect, learn, replay = base['collect'], base['learn'], base['replay']
    print('per-message cost, --workers %d: collect %.0f us wall, %.0f us CPU per /odom message read; replay %.0f us '
          'wall, %.0f us CPU per message read (/odom + /imu/data); learn (exact, %d vectors) %.1f s wall, %.1f s CPU'
          % (base['workers'], 1e6 * collect['wall'] / collect['messages'], 1e6 * collect['cpu'] / collect['messages'],
             1e6 * replay['wall'] / replay['messages'], 1e6 * replay['cpu'] / replay['messages'], learn['count'],
             learn['wall'], learn['cpu']))
    if overhead:
        print('scheduler overhead per task (empty task, local cluster of 2): %.1f ms' % (1e3 * scheduler_overhead(2)))
    print()


if __name__ == '__main__':
    main()
