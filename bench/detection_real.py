#!/usr/bin/env python3
"""Detection quality on the real bags in ../shared/data/real, trained on nominal data only.

    cd /work/main && source .catkin_ws/devel/setup.bash && PATH=/usr/bin:$PATH python3 bench/detection_real.py

Experiments (see docs/DETECTION.md for what the figures mean):

- husky: train on the first half of /husky_velocity_controller/odom (time), replay the second half: every
  flag there is a false alarm. Flags are merged into logging windows the way the smart logger merges them
  (pre/post 100 messages: two flags at most 200 messages apart share one window).
- alfa: train on the vectors whose window ends before the engine failure (+116.25 s after the bag start),
  score the whole flight: detection delay after onset, flags before onset.
- sequor: train on 15 of the 20 E2 (normal) trials, score the 5 held-back E2 trials (false alarms), the N2
  (jerky) trial and the 20 N3 (crash) trials; a trial counts as flagged when any of its vectors is.

Each is run with the default 'motion' features and with the paper's 'raw' features (the same training and
threshold calibration), plus the paper's own setting (raw features, nu 0.5, threshold 0 = sklearn predict).
"""
import argparse
import collections
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.storage.bag import bagio  # noqa: E402
from cc_log.learning import learning  # noqa: E402
from cc_log.features import FeatureConfig, vector_length  # noqa: E402

DATA = common.DATA
HUSKY = ('husky_outdoor_2015.bag', '/husky_velocity_controller/odom')
ALFA = ('alfa_carbonZ_engine_failure.bag', '/mavros/local_position/odom')
ALFA_ONSET = 116.25          # seconds after the bag start (SOURCES.md)
SEQUOR_E2 = ('sequor_E2_normal_safe_escape_straight.bag', '/odom')
SEQUOR_N2 = ('sequor_N2_anomalous_jerky_driving.bag', '/odom')
SEQUOR_N3 = ('sequor_N3_anomalous_crash_wall.bag', '/odom')
PRE_POST = 100               # messages before and after a flag kept by the smart logger (paper default)

# Default windows per robot (docs/DETECTION.md): duration windows for 'motion', the count windows of about
# the same length for 'raw'.
WINDOWS = {
    'husky': {'motion': '2s', 'raw': '20'},
    'alfa': {'motion': '2s', 'raw': '8'},
    'sequor': {'motion': '1s', 'raw': '10'},
}

_cache = {}


def vectors(name, topic, config):
    key = (name, topic, config)
    if key not in _cache:
        _cache[key] = bagio.feature_vectors(os.path.join(DATA, name), topic, config)
    return _cache[key]


def bag_start(name):
    bag = bagio.open_bag(os.path.join(DATA, name))
    try:
        return bag.get_start_time()
    finally:
        bag.close()


def merge_windows(flag_indices, pre=PRE_POST, post=PRE_POST):
    """Number of logging windows from flags at message indices (merged when within pre + post)."""
    windows = 0
    last = None
    for index in flag_indices:
        if last is None or index - last > pre + post:
            windows += 1
        last = index
    return windows


def fit(X, config, setting):
    """Train; 'paper' = nu 0.5, gamma 1/n_features, threshold 0 (OneClassSVM.predict)."""
    if setting == 'paper':
        model, info = learning.train(X, config=config, nu=0.5, gamma=1.0 / vector_length(config))
        model.threshold = 0.0
        info['threshold'] = 0.0
        return model, info
    return learning.train(X, config=config, **setting)


def husky(feature_set, setting, window=None):
    config = FeatureConfig(feature_set, window or WINDOWS['husky'][feature_set])
    stamps, X = vectors(*HUSKY, config=config)
    half = stamps[0] + (stamps[-1] - stamps[0]) / 2.0
    train_mask = stamps < half
    model, info = fit(X[train_mask], config, setting)
    replay = X[~train_mask]
    flagged = np.flatnonzero(model.scores(replay) < model.threshold)
    hours = (stamps[-1] - half) / 3600.0
    windows = merge_windows(flagged)
    return collections.OrderedDict([
        ('window', config.window), ('train vectors', int(train_mask.sum())), ('replay vectors', len(replay)),
        ('replay s', round(hours * 3600.0, 1)), ('false flags', len(flagged)),
        ('false flag %', round(100.0 * len(flagged) / max(1, len(replay)), 1)),
        ('false windows', windows), ('false windows/h', round(windows / hours, 1)),
        ('train s', round(info['train_seconds'], 2))])


def alfa(feature_set, setting, window=None):
    config = FeatureConfig(feature_set, window or WINDOWS['alfa'][feature_set])
    stamps, X = vectors(*ALFA, config=config)
    onset = bag_start(ALFA[0]) + ALFA_ONSET
    before = stamps < onset
    model, info = fit(X[before], config, setting)
    flags = model.scores(X) < model.threshold
    early = np.flatnonzero(flags & before)
    late = np.flatnonzero(flags & ~before)
    delay = (stamps[late[0]] - onset) if len(late) else float('nan')
    return collections.OrderedDict([
        ('window', config.window), ('train vectors', int(before.sum())),
        ('flags before onset', len(early)), ('windows before onset', merge_windows(early)),
        ('detection delay s', round(delay, 2)),
        ('flagged after onset %', round(100.0 * len(late) / max(1, int((~before).sum())), 1)),
        ('train s', round(info['train_seconds'], 2))])


def trial_of(name, stamps):
    """Trial label of every stamp (the /label String published with each frame)."""
    labels = [(record.stamp, record.msg.data) for record in bagio.read_messages(os.path.join(DATA, name), ['/label'])]
    label_stamps = np.array([stamp for stamp, _ in labels])
    index = np.clip(np.searchsorted(label_stamps, stamps, side='right') - 1, 0, len(labels) - 1)
    return np.array([labels[i][1] for i in index])


def sequor(feature_set, setting, window=None):
    config = FeatureConfig(feature_set, window or WINDOWS['sequor'][feature_set])
    stamps, X = vectors(*SEQUOR_E2, config=config)
    trials = trial_of(SEQUOR_E2[0], stamps)
    names = sorted(set(trials))
    held_back = set(names[3::4])                      # E2_004, E2_008, ... : 5 of 20
    train_mask = np.array([trial not in held_back for trial in trials])
    model, info = fit(X[train_mask], config, setting)

    def flagged_trials(X_, trials_):
        flags = model.scores(X_) < model.threshold if len(X_) else np.zeros(0, bool)
        return len(set(trials_[flags])), len(set(trials_)), int(flags.sum()), len(flags)

    e2 = flagged_trials(X[~train_mask], trials[~train_mask])
    out = collections.OrderedDict([('window', config.window), ('train vectors', int(train_mask.sum())),
                                   ('E2 held-back trials flagged', '%d/%d' % e2[:2]),
                                   ('E2 held-back vectors flagged', '%d/%d' % e2[2:])])
    for label, (name, topic) in (('N2', SEQUOR_N2), ('N3', SEQUOR_N3)):
        stamps_, X_ = vectors(name, topic, config=config)
        result = flagged_trials(X_, trial_of(name, stamps_))
        out['%s trials flagged' % label] = '%d/%d' % result[:2]
        out['%s vectors flagged' % label] = '%d/%d' % result[2:]
    n3_trials = len(set(trial_of(SEQUOR_N3[0], np.array([r.stamp for r in bagio.read_messages(
        os.path.join(DATA, SEQUOR_N3[0]), ['/label'])]))))
    out['N3 trials too short for a window'] = n3_trials - int(out['N3 trials flagged'].split('/')[1])
    out['train s'] = round(info['train_seconds'], 2)
    return out


def paper_tables():
    """The paper's table (Total, TP, FP, FN, TN, Precision, Recall) for ALFA and Sequor, default features.

    ALFA: positives are the vectors whose window ends after the onset, negatives the pre-onset training
    vectors themselves (so FP counts flags on data the model saw). Sequor: positives are every N2 and N3
    vector, negatives the vectors of the 5 held-back E2 trials.
    """
    out = []
    config = FeatureConfig('motion', WINDOWS['alfa']['motion'])
    stamps, X = vectors(*ALFA, config=config)
    before = stamps < bag_start(ALFA[0]) + ALFA_ONSET
    model, info = learning.train(X[before], config=config)
    out.append(('ALFA, motion %s' % config.window, learning.evaluate(model, X[before], X[~before]), info))
    config = FeatureConfig('motion', WINDOWS['sequor']['motion'])
    stamps, X = vectors(*SEQUOR_E2, config=config)
    trials = trial_of(SEQUOR_E2[0], stamps)
    held_back = set(sorted(set(trials))[3::4])
    train_mask = np.array([trial not in held_back for trial in trials])
    model, info = learning.train(X[train_mask], config=config)
    anomalous = np.vstack([vectors(*SEQUOR_N2, config=config)[1], vectors(*SEQUOR_N3, config=config)[1]])
    out.append(('Sequor, motion %s' % config.window, learning.evaluate(model, X[~train_mask], anomalous), info))
    return out


def training_cost(n=17512, seed=0):
    """Training time and peak memory on n vectors: the Husky 2 s vectors tiled with 1% noise."""
    config = FeatureConfig('motion', '2s')
    _, X = vectors(*HUSKY, config=config)
    rng = np.random.default_rng(seed)
    big = np.tile(X, (n // len(X) + 1, 1))[:n]
    big = big + rng.normal(size=big.shape) * 0.01 * (X.std(axis=0) + 1e-9)
    rows = []
    for method in ('exact', 'nystroem'):
        model, info = learning.train(big, config=config, method=method)
        rows.append((method, info))
    return rows


SETTINGS = collections.OrderedDict([
    ('motion', ('motion', {})),
    ('raw', ('raw', {})),
    ('paper', ('raw', 'paper')),
])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--only', choices=('husky', 'alfa', 'sequor'), action='append')
    args = parser.parse_args(argv)
    print('machine: %s' % common.machine())
    for name in (HUSKY[0], ALFA[0], SEQUOR_E2[0], SEQUOR_N2[0], SEQUOR_N3[0]):
        print(common.describe_data(os.path.join(DATA, name)))
    print('columns: motion = default features and training; raw = the paper\'s features, same training; '
          'paper = raw features, nu 0.5, threshold 0\n')
    started = time.time()
    for experiment in (husky, alfa, sequor):
        if args.only and experiment.__name__ not in args.only:
            continue
        results = collections.OrderedDict(
            (column, experiment(feature_set, setting)) for column, (feature_set, setting) in SETTINGS.items())
        print('%-36s' % experiment.__name__ + ''.join('%16s' % column for column in results))
        for key in results['motion']:
            print('  %-34s' % key + ''.join('%16s' % results[column].get(key, '') for column in results))
        print()
    if not args.only:
        for title, report, info in paper_tables():
            print(title)
            print('  ' + learning.format_report(report, info).replace('\n', '\n  '))
            print()
        print('training on 17512 vectors (Husky 2 s vectors tiled, 1% noise), peak RSS of this process so far:')
        for method, info in training_cost():
            print('  %-9s %5.2f s  %4d support vectors/components  peak RSS %.0f MB  held-out flagged %d/%d' % (
                method, info['train_seconds'], info['support_vectors'], info['peak_rss_mb'],
                info['held_out_flagged'], info['vectors_held_out']))
        print()
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
