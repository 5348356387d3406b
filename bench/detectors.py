#!/usr/bin/env python3
"""cc_log's defaults against the standard detectors on every real robot, thresholds from training alone.

    /usr/bin/python3 bench/heldout_data.py                            # the held-out bags (once)
    nice -n 10 /usr/bin/python3 bench/detectors.py                    # every robot, seeds 0 1 (~8 min, 2 cores)
    /usr/bin/python3 bench/detectors.py --quick                       # the Husky, seed 0 (~10 s)
    /usr/bin/python3 bench/detectors.py --robots icelab,pioneer --seeds 0 --out /tmp/curves

Robots: the held-out public robots (bench/heldout_data.py: ``tuc``, ``smartloc``, ``mrclam`` with all five
Creates) and the real runs of ../shared/data/real (``husky``, ``f1tenth`` DS1-5, ``icelab`` four runs,
``pioneer`` two traces; bench/detection_runs.py's ROBOTS). Per robot its runs in order; the first
``--train-minutes`` (20) of driving, at most ``--train-fraction`` (0.5) of it, train (bench/detection_heldout.py's
``split``); the rest is held out: replayed as it is (every flag is false) and with ``sim.inject_anomalies`` at the
robot's own scale (``sim.nominal_envelope`` of its training driving), the six types, per seed: one event per
EVENT_EVERY s of a long run (the types repeated), a short run split into fewer types per replay.

Detectors, all on the same windows (1 s, every 0.25 s) of the same 19 envelope features
(``cc_log.features.envelope``), fitted on the training windows, every score lower = more anomalous:

- ``envelope``: the physics envelope (``learning.envelope``, the ``envelope`` trigger's): the training maximum of each
  feature floored at ``ENVELOPE_FLOORS``, score = -(largest ratio of a feature to it);
- ``knn-mean``, ``knn-max``: mean / largest distance to the 5 nearest training windows (training scores leave the
  window itself out); ``lof`` (sklearn, novelty=True, 20 neighbours); ``iforest`` (sklearn IsolationForest);
  ``ocsvm`` (sklearn OneClassSVM, RBF, gamma 'scale', nu 0.01); ``mahalanobis`` (sklearn MinCovDet, robust);
  ``ecod``, ``copod``: implemented here in numpy after their papers (Li et al. 2022, 2020, as PyOD computes them),
  tail probabilities of each feature from the training windows (the window itself counted), summed;
  all on features standardised by a scaler fitted on the training windows;
- ``cclog``: cc_log's defaults as a user runs them: ``cclog learn-envelope`` of the training bags (the envelope
  with its joint check) and ``cclog replay --model envelope.json`` of every held-out bag: its windows, its triggers
  (``--cclog classifier``: the classifier's way instead, ``cclog collect`` / ``learn`` of the training bags and
  ``cclog replay`` with the model, detection_heldout.py's ``defaults``);
- with ``--candidates``, the combinations measured to choose that default (bench/detector_candidates.py: ``a|b``
  flags what either part flags, each at its base level at level 2; ``env2|maha4`` is the default's rule on the
  bench's windows) and one table of them: pooled caught and false windows, the robots where a standard detector at
  the table's level dominates each, and those where it falls short of the envelope at 2x.

The threshold rule, the same for every window detector: ``zero - level x (zero - extreme)`` where ``extreme`` is
the most anomalous training score and ``zero`` the median training score (the envelope: its physical zero, ratio 0,
and its limit, ratio 1, so level 2 is "2x the limit": the issue's envelope at 2x). ``--level`` (2) sets the table's
threshold, LEVELS the recall-versus-false-windows curve. cc_log's defaults keep their own threshold.

Measures: a flagged window's end is a fire; fires merge into episodes [fire - 2 s, fire + 2 s] as cc_log's windows
do. An event is caught when a fire lies in [onset, end + the detector's window] (1 s; cclog: its own), within
0.5 s when the first such fire is at most 0.5 s after onset; its span is kept when >= 95 % of [onset, end] lies in
episodes. False windows: the episodes of the held-out nominal driving, per hour, with the 95 % upper bound
(Poisson: chi2.ppf(0.975, 2k + 2) / 2 / T, or 3 / T for k = 0). kept x ideal: odometry messages inside episodes of
the injected replays / those within [onset - 2 s, end + 2 s] of an event. Per event its extreme: the largest
envelope ratio (feature over the robot's own floored training maximum) of the windows ending in [onset, end + 1 s];
"strong" events (extreme >= 1.5x) are the target's population; ``--events`` prints every event with its extreme
and the false windows of the envelope and cclog (when, and their most outstanding feature).

Figures and what they say: docs/DETECTION.md, "Against the standard detectors".
"""
import argparse
import collections
import os
import shutil
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402
import detector_candidates  # noqa: E402
import detection_heldout as heldout  # noqa: E402
import detection_runs  # noqa: E402
import heldout_data  # noqa: E402
import significance  # noqa: E402
from standard_detectors import STRIDE, WINDOW, Envelope, Knn, Mahalanobis, Sklearn, Standardised, Tails  # noqa: E402

from cc_log import sim  # noqa: E402
from cc_log.features.envelope import ENVELOPE_COLUMNS, envelope_windows, odometry_samples  # noqa: E402
from cc_log.offline.tuning import windows_of  # noqa: E402

TOPIC = heldout.TOPIC
PRE = POST = heldout.MARGIN
LATENCY = heldout.LATENCY
MIN_SPAN_KEPT = heldout.MIN_SPAN_KEPT
LEVELS = (1.0, 1.25, 1.5, 2.0, 3.0, 4.0)
STRONG = 1.5
EVENT_EVERY = 60.0      # s of held-out driving per injected event on a long run
WARMUP = GAP = 5.0      # s: sim.inject_anomalies' warmup and gap
REAL = ('husky', 'f1tenth', 'icelab', 'pioneer')
ROBOTS = heldout_data.ORDER + REAL
STANDARD = ('envelope', 'knn-mean', 'knn-max', 'lof', 'iforest', 'ocsvm', 'mahalanobis', 'ecod', 'copod')
SHORT = {'planning_failure': 'plan', 'collision': 'coll', 'sudden_acceleration': 'accel',
         'excessive_twisting': 'twist', 'localization_jump': 'loc', 'wheels_slipping': 'slip'}


# -- detectors ---------------------------------------------------------------------------------------------------

def make_detectors(candidates=False):
    """The window detectors, by name, unfitted (cclog runs through the CLI); with ``candidates`` also the
    combinations measured to choose cc_log's default (bench/detector_candidates.py)."""
    from sklearn.ensemble import IsolationForest
    from sklearn.neighbors import LocalOutlierFactor
    from sklearn.svm import OneClassSVM

    def lof(k):
        return Standardised(lambda: Sklearn(LocalOutlierFactor(n_neighbors=k, novelty=True),
                                            'negative_outlier_factor_', 'score_samples'))

    detectors = collections.OrderedDict([
        ('envelope', Envelope()),
        ('knn-mean', Standardised(lambda: Knn('mean'))),
        ('knn-max', Standardised(lambda: Knn('max'))),
        ('lof', lof(20)),
        ('iforest', Standardised(lambda: Sklearn(IsolationForest(random_state=0), 'score_samples', 'score_samples'))),
        ('ocsvm', Standardised(lambda: Sklearn(OneClassSVM(nu=0.01, gamma='scale'), 'decision_function',
                                               'decision_function'))),
        ('mahalanobis', Standardised(Mahalanobis)),
        ('ecod', Standardised(lambda: Tails(copod=False))),
        ('copod', Standardised(lambda: Tails(copod=True))),
    ])
    if candidates:
        detector_candidates.add_candidates(detectors, lof)
    return detectors


# -- data ----------------------------------------------------------------------------------------------------------

def load_robot(robot, data):
    """[(run name, records on TOPIC)] of a robot, in order."""
    if robot in heldout_data.ORDER:
        return heldout.load_runs(robot, data, 5)
    topics = {name: topic for name, topic, _ in detection_runs.RUNS}
    return [(name, [r._replace(topic=TOPIC) for r in detection_runs.load(name, topics[name], None)])
            for name in detection_runs.ROBOTS[robot]]


def windows(records):
    """(window ends, envelope feature matrix) of one continuous run."""
    return envelope_windows(*odometry_samples(records), window=WINDOW, stride=STRIDE)


def duration(records):
    return records[-1].stamp - records[0].stamp


def injections(records, seed, envelope):
    """[(injected records, truth)] of one held-out run for one seed: one event per EVENT_EVERY s (the six types
    repeated) when it fits, else the six types split into the fewest replays that fit; [] when none fits."""
    types = list(sim.ANOMALY_TYPES) * max(1, int(duration(records) // (EVENT_EVERY * len(sim.ANOMALY_TYPES))))
    for parts in range(1, len(types) + 1):
        groups = [types[k::parts] for k in range(parts)]
        try:
            return [sim.inject_anomalies(records, group, seed=seed, topic=TOPIC, warmup=WARMUP, gap=GAP,
                                         scale=envelope, limits=envelope) for group in groups]
        except ValueError:
            continue
    return []


# -- measures ------------------------------------------------------------------------------------------------------

def merged(intervals):
    """Overlapping [a, b] intervals merged, sorted."""
    out = []
    for a, b in sorted(intervals):
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return out


def count_inside(stamps, intervals):
    """How many of the sorted ``stamps`` lie in the union of ``intervals``."""
    spans = np.array(merged(intervals)).reshape(-1, 2)
    return int((np.searchsorted(stamps, spans[:, 1], 'right') - np.searchsorted(stamps, spans[:, 0], 'left')).sum())


def tally():
    return {'false': 0, 'caught': [], 'fast': [], 'spans': [], 'kept': 0, 'need': 0}


def add_events(stats, fires, episodes, truth, reach, stamps):
    """Add one injected replay's events (caught, within LATENCY, span kept) and kept / need to ``stats``."""
    fires = np.sort(np.asarray(fires, dtype=float))
    for entry in truth:
        near = fires[(fires >= entry['start']) & (fires <= entry['end'] + reach)]
        stats['caught'].append(bool(len(near)))
        stats['fast'].append(bool(len(near)) and near[0] - entry['start'] <= LATENCY)
        stats['spans'].append(span_kept(episodes, entry))
    stats['kept'] += count_inside(stamps, episodes)
    stats['need'] += count_inside(stamps, [(e['start'] - PRE, e['end'] + POST) for e in truth])


def span_kept(episodes, entry):
    """Whether at least MIN_SPAN_KEPT of an event's [onset, end] lies in ``episodes``."""
    length = entry['end'] - entry['start']
    covered = sum(max(0.0, min(b, entry['end']) - max(a, entry['start'])) for a, b in merged(episodes))
    return length <= 0 or covered / length >= MIN_SPAN_KEPT


def upper95(k, hours):
    """The 95 % upper bound of a Poisson rate (per hour) after ``k`` counts in ``hours``."""
    from scipy.stats import chi2
    if not hours:
        return float('nan')
    return 3.0 / hours if k == 0 else chi2.ppf(0.975, 2 * k + 2) / 2.0 / hours


def extreme_of(envelope, ends, M, entry):
    """(largest envelope ratio, its feature) of the windows ending in [onset, end + WINDOW] of an event."""
    inside = (ends >= entry['start']) & (ends <= entry['end'] + WINDOW)
    if not inside.any():
        return 0.0, '-'
    ratios = envelope.ratios(M[inside])
    row, column = np.unravel_index(int(np.argmax(ratios)), ratios.shape)
    return float(ratios[row, column]), ENVELOPE_COLUMNS[column]


def episodes_of(envelope, ends, M, run, t0, factor=2.0):
    """The envelope's (at ``factor`` x) episodes of a nominal run: [('envelope', run, start s, end s, its most
    outstanding window's feature and ratio)], times into the run."""
    ratios = envelope.ratios(M) if len(M) else np.zeros((0, len(ENVELOPE_COLUMNS)))
    flagged = ratios.max(axis=1) > factor if len(M) else np.zeros(0, dtype=bool)
    out = []
    for a, b in windows_of(ends[flagged], PRE, POST):
        inside = (ends >= a) & (ends <= b) & flagged
        row, column = np.unravel_index(int(np.argmax(np.where(inside[:, None], ratios, -1.0))), ratios.shape)
        out.append(('envelope', run, a - t0, b - t0, '%s %.2fx' % (ENVELOPE_COLUMNS[column], ratios[row, column])))
    return out


# -- one robot -----------------------------------------------------------------------------------------------------

def learn_envelope(train, tmp):
    """``cclog learn-envelope`` of every training piece (each a bag); (envelope path, its first and last lines)."""
    bags = []
    for k, (_, records) in enumerate(train):
        bags.append(os.path.join(tmp, 'train%d.bag' % k))
        common.write_bag(bags[-1], records)
    path = os.path.join(tmp, 'envelope.json')
    lines = heldout.quiet_cli(['learn-envelope'] + bags + ['--topic', TOPIC, '--out', path]).strip().splitlines()
    for bag in bags:
        os.remove(bag)
    return path, [lines[0], lines[-1]]


def fitted(runs, train_seconds, fraction, candidates=False):
    """A robot's runs split and its detectors fitted: (training pieces, held-out pieces, the injection scale
    (``sim.Limits`` of the training driving), {name: detector fitted on the training windows}, those windows)."""
    total = sum(duration(records) for _, records in runs)
    train, rest = heldout.split(runs, min(train_seconds, fraction * total))
    # each training run apart: runs of one robot may be stamped in any order
    envelope = sim.Limits(*np.max([sim.nominal_envelope(records, TOPIC) for _, records in train], axis=0))
    detectors = make_detectors(candidates)
    X = np.concatenate([windows(records)[1] for _, records in train])
    for detector in detectors.values():
        detector.fit(X)
    return train, rest, envelope, detectors, X


def evaluate(robot, runs, seeds, train_seconds, fraction, tmp, with_cclog=True, default='envelope',
             candidates=False):
    """Every detector on one robot: {'robot', 'train_s', 'hours', 'rate', 'lines', 'events' [{type, extreme}],
    'stats' {detector: {level: tally}}, 'seconds'}. ``default``: how cc_log's defaults run (``envelope``: cclog
    learn-envelope, ``classifier``: cclog collect / learn)."""
    started = time.time()
    train, rest, envelope, detectors, X = fitted(runs, train_seconds, fraction, candidates)
    out = {'robot': robot, 'train_s': sum(duration(r) for _, r in train), 'rate': detection_runs.rate_of(train[0][1]),
           'hours': sum(duration(r) for _, r in rest) / 3600.0, 'runs': [name for name, _ in rest],
           'train_windows': len(X), 'events': [], 'lines': [], 'no_room': 0, 'false_episodes': [], 'scored': [],
           'stats': {name: {level: tally() for level in LEVELS} for name in detectors}}
    setting = heldout.SETTINGS['defaults']
    if with_cclog:
        if default == 'envelope':
            model, lines = learn_envelope(train, tmp)
            reach = WINDOW
        else:
            model, lines = heldout.learn(train, setting, tmp)
            reach = heldout.reach_of(setting, out['rate'])
        out['lines'] = lines
        out['stats']['cclog'] = {None: tally()}

    def cclog(records, tag, truth=None):
        if not with_cclog:
            return
        found, _ = heldout.replay(records, model, setting, tmp, tag)
        fires = sorted(t for w in found for t in w['triggers'])
        episodes = [(w['start'], w['end']) for w in found]
        stats = out['stats']['cclog'][None]
        if truth is None:
            stats['false'] += len(found)
            out['false_episodes'] += [('cclog', tag[len('nominal-'):], w['start'] - records[0].stamp,
                                       w['end'] - records[0].stamp, '; '.join(w['why'])) for w in found]
        else:
            add_events(stats, fires, episodes, truth, reach, np.array([r.stamp for r in records]))

    for name, records in rest:
        ends, M = windows(records)
        for label, detector in detectors.items():
            scores = detector_candidates.part_score(detector, M, ends)
            for level in LEVELS:
                out['stats'][label][level]['false'] += len(windows_of(ends[scores < detector.threshold(level)],
                                                                      PRE, POST))
        out['false_episodes'] += episodes_of(detectors['envelope'], ends, M, name, records[0].stamp)
        cclog(records, 'nominal-' + name)
        out['scored'].append('nominal')
        for seed in seeds:
            replays = injections(records, seed, envelope)
            out['no_room'] += not replays
            for k, (injected, truth) in enumerate(replays):
                ends, M = windows(injected)
                stamps = np.array([r.stamp for r in injected])
                for entry in truth:
                    extreme, feature = extreme_of(detectors['envelope'], ends, M, entry)
                    out['events'].append({'type': entry['type'], 'run': name, 'seed': seed, 'feature': feature,
                                          'at': entry['start'] - records[0].stamp, 'extreme': extreme})
                for label, detector in detectors.items():
                    scores = detector_candidates.part_score(detector, M, ends)
                    for level in LEVELS:
                        fires = ends[scores < detector.threshold(level)]
                        add_events(out['stats'][label][level], fires, windows_of(fires, PRE, POST), truth, WINDOW,
                                   stamps)
                cclog(injected, 'inj-%s-%d-%d' % (name, seed, k), truth)
                out['scored'].append('injected')
    out['drift'] = detector_candidates.drift_shares(detectors, out['scored'])
    out['seconds'] = time.time() - started
    return out


# -- report --------------------------------------------------------------------------------------------------------

def pooled(results):
    """The results of several robots as one (stats and events concatenated, hours summed)."""
    out = {'hours': sum(r['hours'] for r in results), 'events': [e for r in results for e in r['events']],
           'stats': {}}
    for name in results[0]['stats']:
        out['stats'][name] = {}
        for level in results[0]['stats'][name]:
            parts = [r['stats'][name][level] for r in results if name in r['stats']]
            out['stats'][name][level] = {key: sum((p[key] for p in parts), [] if key in ('caught', 'fast', 'spans')
                                                  else 0) for key in tally()}
    return out


def row_of(result, name, level):
    """The table row of one detector at one level: caught, fast, strong caught, false, rates, kept, spans."""
    stats = result['stats'][name][level if name != 'cclog' else None]
    strong = [e['extreme'] >= STRONG for e in result['events']]
    n, hours = len(stats['caught']), result['hours']
    caught = sum(stats['caught'])
    strong_caught = sum(c and s for c, s in zip(stats['caught'], strong))
    return [name, '%d/%d' % (caught, n), sum(stats['fast']), '%d/%d' % (strong_caught, sum(strong)),
            stats['false'], stats['false'] / hours if hours else float('nan'), upper95(stats['false'], hours),
            '%.2fx' % (stats['kept'] / float(stats['need'])) if stats['need'] else '-',
            '%d/%d' % (sum(stats['spans']), n), by_type(stats['caught'], result['events'])]


def by_type(caught, events):
    """'a/b c/d ...': events caught of each type, in sim.ANOMALY_TYPES' order."""
    return ' '.join('%d/%d' % (sum(c for c, e in zip(caught, events) if e['type'] == kind),
                               sum(1 for e in events if e['type'] == kind)) for kind in sim.ANOMALY_TYPES)


def recall_false(result, name, level):
    """(recall, false windows per hour) of one detector at one level."""
    stats = result['stats'][name][level if name != 'cclog' else None]
    recall = sum(stats['caught']) / float(len(stats['caught'])) if stats['caught'] else float('nan')
    return recall, stats['false'] / result['hours'] if result['hours'] else float('nan')


def point(result, name, level):
    """'recall % / false per hour' of one detector at one level."""
    recall, false = recall_false(result, name, level)
    return '%.0f%% / %.1f' % (100 * recall, false)


def dominating(result, level=None):
    """The standard detectors (at ``level``, or at any level of LEVELS) whose recall and false windows are both at
    least as good as cclog's, one strictly better: [(name, level)]."""
    if 'cclog' not in result['stats']:
        return []
    recall, false = recall_false(result, 'cclog', None)
    out = []
    for name in STANDARD:
        for lv in ([level] if level is not None else LEVELS):
            r, f = recall_false(result, name, lv)
            if r >= recall and f <= false and (r > recall or f < false):
                out.append((name, lv))
    return out


def significantly_dominating(result, level):
    """The standard detectors at ``level`` that dominate cclog by more than chance (``significance``: McNemar's
    exact test on the events, the conditional binomial test on the false windows, p < ALPHA on the better side):
    [(name, catches p, false windows p)]."""
    if 'cclog' not in result['stats']:
        return []
    stats = result['stats']
    ours = stats['cclog'][None]
    return significance.significantly_dominating(
        dict((name, (stats[name][level]['caught'], stats[name][level]['false'])) for name in STANDARD if name in stats),
        (ours['caught'], ours['false']))


def p_values(result, level):
    """'name (events p P, false windows p Q)' of each standard detector dominating cclog at ``level``."""
    if 'cclog' not in result['stats']:
        return ''
    stats = result['stats']
    ours = stats['cclog'][None]
    return ', '.join('%s (events p %.2f, false windows p %.2f)' % (
        name, significance.catches_p(stats[name][level]['caught'], ours['caught']),
        significance.false_windows_p(stats[name][level]['false'], ours['false']))
        for name, _ in dominating(result, level))


HEADERS = ['detector', 'caught', 'within 0.5 s', 'strong (>= 1.5x) caught', 'false windows', 'false/h',
           'false/h 95% upper', 'kept x ideal', 'span >= 95% kept', 'caught per type (%s)' % ' '.join(
               SHORT[kind] for kind in sim.ANOMALY_TYPES)]


def report_events(r, level):
    """One line per injected event: where, its extreme (and which feature), the detectors that caught it."""
    print('every event (run, seed, onset s into the held-out run, type, extreme: feature; caught at level %g by):'
          % level)
    for k, e in enumerate(r['events']):
        caught = [name for name in r['stats'] if r['stats'][name][level if name != 'cclog' else None]['caught'][k]]
        print('  %s seed %d %7.1f s %-19s %6.2fx %-18s %s' % (
            e['run'], e['seed'], e['at'], e['type'], e['extreme'], e['feature'], ' '.join(caught) or 'none'))
    print('false windows of the envelope (2x) and cclog in the held-out nominal driving (run, s into it, why):')
    for name, run, start, end, why in r['false_episodes']:
        print('  %-8s %s %7.1f-%7.1f s %s' % (name, run, start, end, why))
    print()


def report_robot(r, level):
    print('## %s: %.1f Hz, trained on %.1f min (%d windows), held out %.1f min nominal (%s), %d events injected%s'
          % (r['robot'], r['rate'], r['train_s'] / 60.0, r['train_windows'], r['hours'] * 60.0, ', '.join(r['runs']),
             len(r['events']), ', %d run x seed(s) too short to inject' % r['no_room'] if r['no_room'] else ''))
    for line in r['lines']:
        print('  ' + line.replace('\n', '\n  '))
    common.table(HEADERS, [row_of(r, name, level) for name in r['stats']])
    found = dominating(r, level)
    print('dominating cclog at level %g: %s; at some level of the curve: %s' % (
        level, ', '.join(name for name, _ in found) or 'none',
        ', '.join('%s (%g)' % item for item in dominating(r)) or 'none'))
    if found:
        print('  by more than chance (p < %g)? %s: %s' % (
            significance.ALPHA, p_values(r, level),
            ', '.join(name for name, _, _ in significantly_dominating(r, level)) or 'none'))
    if 'cclog' in r['stats']:
        env, ours = recall_false(r, 'envelope', 2.0), recall_false(r, 'cclog', None)
        print('cclog against the envelope at 2x: recall %.0f%% vs %.0f%%, false/h %.1f vs %.1f: at least as many '
              'caught with no more false windows: %s' % (100 * ours[0], 100 * env[0], ours[1], env[1],
                                                         'yes' if ours[0] >= env[0] and ours[1] <= env[1] else 'NO'))
    print('(%.0f s)\n' % r['seconds'])
    sys.stdout.flush()


def report_pooled(p, results, level, out_dir):
    print('## Pooled over %d robots: %.2f h of held-out nominal driving, %d events' % (
        len(results), p['hours'], len(p['events'])))
    common.table(HEADERS, [row_of(p, name, level) for name in p['stats']])
    rows = []
    types = sim.ANOMALY_TYPES
    for name in p['stats']:
        stats = p['stats'][name][level if name != 'cclog' else None]
        cells = [name]
        for kind in types:
            hits = [c for c, e in zip(stats['caught'], p['events']) if e['type'] == kind]
            cells.append('%d/%d' % (sum(hits), len(hits)))
        rows.append(cells)
    common.table(['detector'] + list(types), rows, 'recall per anomaly type (pooled, level %g):' % level)
    rows = []
    for kind in types:
        extremes = [e['extreme'] for e in p['events'] if e['type'] == kind]
        rows.append([kind, len(extremes), np.median(extremes) if extremes else float('nan'),
                     min(extremes) if extremes else float('nan'), sum(x >= STRONG for x in extremes)])
    common.table(['type', 'events', 'median extreme (x nominal max)', 'least extreme', 'strong (>= 1.5x)'], rows,
                 "each event's most extreme envelope feature over the robot's own floored training maximum:")
    rows = [[name] + [point(p, name, lv) for lv in LEVELS] for name in p['stats'] if name != 'cclog']
    if 'cclog' in p['stats']:
        rows.append(['cclog (own threshold)'] + [point(p, 'cclog', None)] * len(LEVELS))
    common.table(['detector'] + ['level %g' % lv for lv in LEVELS], rows,
                 'recall / false windows per hour, pooled, per threshold level (the curve):')
    plot_curve(p, os.path.join(out_dir, 'detectors_curve.png'))
    strong = [e['extreme'] >= STRONG for e in p['events']]
    if 'cclog' in p['stats']:
        stats = p['stats']['cclog'][None]
        print('target cclog defaults pooled: %.1f false windows/h (95%% upper %.1f; target <= 5/h) over %.2f h '
              '(target >= 3 h); strong events caught within %.1f s %d/%d, >= 95%% of the span kept %d/%d' % (
                  stats['false'] / p['hours'], upper95(stats['false'], p['hours']), p['hours'], LATENCY,
                  sum(f and s for f, s in zip(stats['fast'], strong)), sum(strong),
                  sum(k and s for k, s in zip(stats['spans'], strong)), sum(strong)))
        print('target no standard detector at level %g dominates cclog on any robot: %s' % (level, '; '.join(
            '%s: %s' % (r['robot'], ', '.join(n for n, _ in dominating(r, level))) for r in results
            if dominating(r, level)) or 'met'))
        print('target no standard detector at level %g dominates cclog on any robot by more than chance (p < %g): '
              '%s' % (level, significance.ALPHA, '; '.join(
                  '%s: %s' % (r['robot'], ', '.join(n for n, _, _ in significantly_dominating(r, level)))
                  for r in results if significantly_dominating(r, level)) or 'met'))
    if any('|' in name for name in p['stats']):
        detector_candidates.report(results, p, level, cell_of, STANDARD, common.table)


def cell_of(result, name, level):
    """(caught, false windows) of one detector at one level (cclog: its own threshold)."""
    stats = result['stats'][name][level if name != 'cclog' else None]
    return sum(stats['caught']), stats['false']


def plot_curve(p, path):
    """Recall against false windows per hour of every detector over LEVELS (cclog: one point) into ``path``."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    os.makedirs(os.path.dirname(path), exist_ok=True)
    figure, axes = plt.subplots(figsize=(7, 5))
    for name in p['stats']:
        points = [recall_false(p, name, lv) for lv in (LEVELS if name != 'cclog' else [None])]
        axes.plot([f for _, f in points], [100 * r for r, _ in points], 'o-' if name != 'cclog' else 's',
                  label=name, markersize=4 if name != 'cclog' else 9)
    axes.set_xscale('symlog', linthresh=1.0)
    axes.set_xlabel('false windows per hour of held-out nominal driving')
    axes.set_ylabel('events caught (%)')
    axes.set_title('pooled, threshold levels %s' % ', '.join('%g' % lv for lv in LEVELS))
    axes.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)
    print('curve: %s\n' % path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--data', default=heldout_data.OUT, help='the held-out bags (default %s)' % heldout_data.OUT)
    parser.add_argument('--robots', default=','.join(ROBOTS), help='of %s (default: all)' % ', '.join(ROBOTS))
    parser.add_argument('--seeds', default='0,1')
    parser.add_argument('--train-minutes', type=float, default=20.0)
    parser.add_argument('--train-fraction', type=float, default=0.5, help='at most this share of a robot trains')
    parser.add_argument('--level', type=float, default=2.0, help='the threshold level of the tables (default 2)')
    parser.add_argument('--no-cclog', action='store_true', help="leave cc_log's defaults out (faster)")
    parser.add_argument('--cclog', choices=('envelope', 'classifier'), default='envelope',
                        help="cc_log's defaults: the envelope file (default) or the classifier's collect / learn")
    parser.add_argument('--candidates', action='store_true',
                        help="also the combinations measured to choose cc_log's default (env2|maha4 is it) and "
                             "where a standard detector dominates each")
    parser.add_argument('--out', default=os.path.join(tempfile.gettempdir(), 'cc_log_detectors'),
                        help='where the curve PNG goes')
    parser.add_argument('--events', action='store_true',
                        help='one line per injected event (its extreme, who caught it) and per false window of the '
                             'envelope and cclog')
    parser.add_argument('--quick', action='store_true', help='the Husky alone, seed 0')
    args = parser.parse_args(argv)
    robots = ['husky'] if args.quick else args.robots.split(',')
    seeds = [0] if args.quick else [int(s) for s in args.seeds.split(',')]
    for robot in robots:
        if robot not in ROBOTS:
            raise SystemExit('robots: unknown robot %r (choose from %s)' % (robot, ', '.join(ROBOTS)))
    if args.level not in LEVELS:
        raise SystemExit('level: %g is not one of %s' % (args.level, ', '.join('%g' % lv for lv in LEVELS)))
    started = time.time()
    paths = [p for robot in robots if robot in heldout_data.ORDER for p in heldout_data.runs(robot, args.data)]
    paths += [detection_runs.bag_path(name) for robot in robots if robot in REAL
              for name in detection_runs.ROBOTS[robot]]
    common.header("Detectors: cc_log's defaults against the standard detectors, thresholds from training alone",
                  ['data: %s (bench/HELDOUT_SOURCES.md, ../shared/data/real/SOURCES.md)' % ', '.join(
                      '%s %s' % (os.path.basename(p), common.sha12(p)) for p in paths),
                   'seeds %s; windows %g s every %g s; train the first %g min, at most %g of a robot; level %g; '
                   'ECOD and COPOD: numpy, after their papers (PyOD not used)' % (
                       seeds, WINDOW, STRIDE, args.train_minutes, args.train_fraction, args.level)])
    results = []
    for robot in robots:
        tmp = tempfile.mkdtemp(prefix='cc_log_detectors_')
        try:
            results.append(evaluate(robot, load_robot(robot, args.data), seeds, args.train_minutes * 60.0,
                                    args.train_fraction, tmp, not args.no_cclog, args.cclog, args.candidates))
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        report_robot(results[-1], args.level)
        if args.events:
            report_events(results[-1], args.level)
    report_pooled(pooled(results), results, args.level, args.out)
    print('total %.0f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
