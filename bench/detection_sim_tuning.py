#!/usr/bin/env python3
"""Tuning the demo and the defaults on the simulator, offline (no roscore): feature window, training
minutes and stride, and the smart logger's retrigger rule, judged on whole runs with labelled anomalies.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/detection_sim_tuning.py                 # the grid below (a few minutes)
    python3 bench/detection_sim_tuning.py --quick         # tiny run (smoke test)
    python3 bench/detection_sim_tuning.py --windows 1s --train-minutes 8 --retrigger onset
    python3 bench/detection_sim_tuning.py --windows 1s,2s --train-minutes 16 --retrigger event --progress 500

For every (feature window, training minutes, stride):

1. training: a nominal simulated run (cc_log.sim.Simulator, seed ``--train-seed``, no anomalies, 100 Hz), its
   sliding feature vectors one every ``stride`` messages computed as the smart logger computes them, then
   ``learning.train`` on nominal vectors only (defaults: nu, gamma, held-out threshold) -- exactly what
   ``demo.py`` does; with ``--progress WINDOW`` also a model of the ``progress`` feature set, run as a second
   classifier trigger (as a configuration with two classifiers runs them);
2. test runs, each replayed message by message through ``SmartLogger`` (the class behind the live node and
   ``cclog replay``; json-xz, pre/post 100 messages, IMU as a side topic), once per retrigger rule:
   - ``run10``: 10 minutes, 6 anomalies (one of each type), seed ``--run-seed``, gap 20 s (the storage
     target's run);
   - ``demo``: the demo's live run offline: 2.5 minutes, 6 anomalies, gap 10 s, seed ``--demo-seed``, no
     stamp jitter (as sim_bwibot publishes).
3. windows vs the ground truth ({type, start, end}): an anomaly is caught when a classifier trigger of a saved
   window falls in [start, end + feature window]; a window with no such trigger is a false window; kept =
   messages in saved windows / messages seen; raw/stored = row-per-message JSON bytes of every message /
   bytes of the window files; span kept: the share of each anomaly's span [start, end) inside saved windows
   (``demo.score``, the demo's own verdict), the smallest of the run and how many anomalies have >= 95 %;
   no overlap: windows overlapping no anomaly (the demo's false windows); kept/ideal: odometry messages in saved
   windows / those within [start - 2 s, end + 2 s] of an anomaly (issue 31's ideal).

``--config demo`` replays the demo's own configuration instead of a lone classifier (``demo.config_text``: the
classifier with its ``pre``, a rule on aborted goals with a long ``pre``, ``windows``; the runs then also carry
``/cmd_vel`` and ``/move_base/status``); ``--post`` and ``--recent`` (comma-separated) then compare values of
its ``windows.post`` and the classifier's ``recent``::

    python3 bench/detection_sim_tuning.py --windows 1s --train-minutes 8 --config demo --post 1s,3s,5s
"""
import argparse
import collections
import os
import shutil
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.logger import config as configuration  # noqa: E402
from cc_log.learning import learning  # noqa: E402
from cc_log.base import raw_message  # noqa: E402
from cc_log.offline import demo  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.features import FeatureConfig  # noqa: E402
from cc_log.triggers import ClassifierTrigger  # noqa: E402


SHORT = {'planning_failure': 'plan', 'collision': 'coll', 'sudden_acceleration': 'accel',
         'excessive_twisting': 'twist', 'localization_jump': 'loc', 'wheels_slipping': 'slip'}


def replay(model, records, directory, retrigger, pre, post, progress=None):
    """Feed records to a SmartLogger (with a second classifier of the ``progress`` model when given); return
    (stats, windows [{start, end, messages, bytes, triggers}])."""
    os.makedirs(directory)
    if isinstance(model, configuration.Config):  # the demo's configuration: its triggers and windows
        triggers = model.build_triggers(learning.AnomalyModel.load, raw_message.installed_class)
        options = model.logger_options(triggers)
        result = common.smart_replay(None, records, sim.ODOM_TOPIC, directory, side_topics=(sim.IMU_TOPIC,),
                                     pre=options['pre'], post=options['post'], triggers=triggers)
        shutil.rmtree(directory)
        return result['stats'], result['windows']
    triggers = [] if progress is None else [ClassifierTrigger('progress', progress, [sim.ODOM_TOPIC],
                                                              retrigger=retrigger)]
    result = common.smart_replay(model, records, sim.ODOM_TOPIC, directory, side_topics=(sim.IMU_TOPIC,),
                                 pre=pre, post=post, retrigger=retrigger, triggers=triggers)
    shutil.rmtree(directory)
    return result['stats'], result['windows']


def judge(truth, windows, reach):
    """(caught types Counter, caught count, false windows, per-anomaly delays)."""
    caught = collections.Counter()
    delays = []
    for entry in truth:
        near = [t for w in windows for t in w['triggers'] if entry['start'] <= t <= entry['end'] + reach]
        if near:
            caught[entry['type']] += 1
            delays.append(min(near) - entry['start'])
    false = sum(1 for w in windows
                if not any(e['start'] <= t <= e['end'] + reach for t in w['triggers'] for e in truth))
    return caught, sum(caught.values()), false, delays


def span_kept(truth, windows):
    """(smallest share of an anomaly's span kept, anomalies with >= demo.MIN_COVERAGE kept, windows overlapping no
    anomaly, the share of each anomaly as text): the demo's verdict (``demo.score``)."""
    events, no_overlap, _ = demo.score(windows, truth)
    shares = [share for _, share, _ in events]
    text = ' '.join('%s%.0f' % (SHORT[event['type']], 100.0 * share) for event, share, _ in events)
    return (min(shares or [float('nan')]), sum(1 for s in shares if s >= demo.MIN_COVERAGE), len(no_overlap),
            text)


def demo_configs(model, model_path, posts, recents):
    """[(label, Config)] of the demo's configuration with ``model`` saved at ``model_path``, one per (post, recent)."""
    import yaml
    model.save(model_path)
    out = []
    for post in posts:
        for recent in recents:
            data = yaml.safe_load(demo.config_text(model_path, post))
            if recent:
                data['triggers'][0]['recent'] = recent
            out.append(('post %s%s' % (post, ', recent %s' % recent if recent else ''),
                        configuration.Config.from_dict(data, 'demo config')))
    return out


def window_seconds(config, rate):
    span = config.span
    return span.seconds if span.is_duration else span.count / rate


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--windows', default='500,2s,1s', help='feature windows to compare (comma-separated)')
    parser.add_argument('--train-minutes', default='8,16', help='nominal training minutes (comma-separated)')
    parser.add_argument('--strides', default='10', help='messages between training vectors (comma-separated)')
    parser.add_argument('--retrigger', default='every,onset,event', help='SmartLogger retrigger rules to compare')
    parser.add_argument('--progress', metavar='WINDOW',
                        help='also a classifier of the progress feature set over WINDOW (e.g. 500), trained on the '
                        'same nominal run (the "motion + progress" column of bench/detection_sim.py)')
    parser.add_argument('--runs', default='run10,demo', help='test runs: run10, demo')
    parser.add_argument('--pre', default='100', help='the logger\'s pre (without --config)')
    parser.add_argument('--post', default=None, help='the logger\'s post (default 100); with --config demo: its '
                        'windows.post, comma-separated (default: demo.DEMO_POST)')
    parser.add_argument('--config', choices=('demo',), help='replay the demo\'s configuration (see above)')
    parser.add_argument('--recent', default='', help='with --config demo: the classifier\'s recent, comma-separated '
                        '(default: a quarter of the feature window)')
    parser.add_argument('--train-seed', type=int, default=7)
    parser.add_argument('--run-seed', type=int, default=1)
    parser.add_argument('--demo-seed', type=int, default=8)
    parser.add_argument('--quick', action='store_true', help='tiny run: 2 training minutes, 1s window, demo run')
    args = parser.parse_args(argv)
    if args.quick:
        args.windows, args.train_minutes, args.strides, args.runs = '1s', '2', '10', 'demo'
    windows = args.windows.split(',')
    minutes_list = [float(m) for m in args.train_minutes.split(',')]
    strides = [int(s) for s in args.strides.split(',')]
    rules = args.retrigger.split(',')
    posts = (args.post or (demo.DEMO_POST if args.config else '100')).split(',')
    commands = bool(args.config)  # the demo's rule reads /move_base/status
    run_specs = {
        'run10': sim.SimConfig(seed=args.run_seed, minutes=10.0, anomalies=6, imu=True, commands=commands),
        'demo': sim.SimConfig(seed=args.demo_seed, minutes=2.5, anomalies=6, gap=10.0, imu=True, jitter=0.0,
                              commands=commands),
    }
    runs = [name for name in args.runs.split(',')]
    started = time.time()
    common.header('Simulator tuning: feature window, training, retrigger rule (smart logger replay)', [
        'data: cc_log.sim BWIBot 100 Hz; training: nominal runs, seed %d, %s min; test runs: %s' % (
            args.train_seed, args.train_minutes, '; '.join(
                '%s = %g min, %d anomalies (one per type), gap %g s, seed %d, IMU side topic' % (
                    name, run_specs[name].minutes, run_specs[name].anomalies, run_specs[name].gap,
                    run_specs[name].seed) for name in runs)),
        ('smart logger: the demo\'s configuration (demo.config_text), post %s' % ','.join(posts)) if args.config else
        'smart logger: json-xz, pre %s, post %s%s' % (args.pre, posts[0], '; beside motion a progress classifier '
                                                      'over %s' % args.progress if args.progress else '')])

    tests = {}
    for name in runs:
        records, truth = common.sim_records(run_specs[name])
        tests[name] = ([r for r in records if r.topic in (sim.ODOM_TOPIC, sim.IMU_TOPIC, sim.STATUS_TOPIC)], truth)
    training = {}
    for minutes in minutes_list:
        records, _ = common.sim_records(sim.SimConfig(seed=args.train_seed, minutes=minutes, anomalies=0))
        training[minutes] = [r for r in records if r.topic == sim.ODOM_TOPIC]
    print('simulated in %.0f s' % (time.time() - started))

    rows = []
    tmp = tempfile.mkdtemp(prefix='cc_log_tuning_')
    try:
        for window in windows:
            config = FeatureConfig('motion', window)
            reach = window_seconds(config, 100.0)
            if args.progress:  # a progress fire counts up to its own window after the anomaly's end
                reach = max(reach, window_seconds(FeatureConfig('progress', args.progress), 100.0))
            for minutes in minutes_list:
                for stride in strides:
                    _, X = common.window_vectors(training[minutes], sim.ODOM_TOPIC, config, stride=stride)
                    with common.Timer() as timer:
                        model, info = learning.train(X, config=config)
                        progress = None
                        if args.progress:
                            progress_config = FeatureConfig('progress', args.progress)
                            _, Xp = common.window_vectors(training[minutes], sim.ODOM_TOPIC, progress_config,
                                                          stride=stride)
                            progress, _ = learning.train(Xp, config=progress_config)
                    # (label, a model or the demo's Config, retrigger, post) of each replay
                    if args.config:
                        settings = [(label, config, None, None) for label, config in demo_configs(
                            model, os.path.join(tmp, 'model.json'), posts, args.recent.split(','))]
                    else:
                        settings = [(rule if len(posts) == 1 else '%s, post %s' % (rule, post), model, rule, post)
                                    for rule in rules for post in posts]
                    for name in runs:
                        records, truth = tests[name]
                        for label, source, rule, post in settings:
                            stats, saved = replay(source, records, os.path.join(tmp, 'w%d' % len(rows)), rule,
                                                  args.pre, post, progress)
                            caught, n_caught, false, delays = judge(truth, saved, reach)
                            least, whole, no_overlap, shares = span_kept(truth, saved)
                            kept_odom, ideal = common.kept_messages(records, sim.ODOM_TOPIC, saved, truth, 2.0, 2.0)
                            by_type = ' '.join('%s%d' % (SHORT[k], caught[k]) for k in sim.ANOMALY_TYPES
                                               if any(e['type'] == k for e in truth))
                            rows.append([window, '%g' % minutes, stride, len(X), '%.1f' % timer.wall,
                                         name, label, '%d/%d' % (n_caught, len(truth)), by_type, false,
                                         len(saved),
                                         '%.1f%%' % (100.0 * stats['messages_kept'] / stats['messages_seen']),
                                         '%.0fx' % (stats['raw_json_bytes'] / max(1, stats['stored_bytes'])),
                                         '%.2f' % (max(delays) if delays else float('nan')),
                                         '%.1f%%' % (100.0 * least), '%d/%d' % (whole, len(truth)), shares, no_overlap,
                                         '%.2fx' % (kept_odom / float(max(1, ideal)))])
                            print('  done: window %s, %g min, stride %d, %s, %s  [%.0f s]' % (
                                window, minutes, stride, name, label, time.time() - started))
                            sys.stdout.flush()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print()
    common.table(['window', 'train min', 'stride', 'vectors', 'train s', 'run', 'setting', 'caught',
                  'caught by type', 'false windows', 'windows', 'kept', 'raw/stored', 'max delay s',
                  'span kept (least)', 'span kept >= 95%', 'span kept % by anomaly', 'no overlap',
                  'kept/ideal'], rows,
                 'Smart logger on simulated runs (caught: a trigger in [onset, end + feature window]):')
    print('total %.0f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
