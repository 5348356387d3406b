#!/usr/bin/env python3
"""Every real run with continuous odometry: train on its first part, replay the rest with and without injected
simulator anomalies; recall by type and latency, false windows per hour, kept messages against the need.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/detection_runs.py                       # all runs, seeds 0 1 2, ours and the paper's
    python3 bench/detection_runs.py --runs f1tenth_DS1 --seeds 0 --settings ours   # one run, quick
    python3 bench/detection_runs.py --settings ours --injection robot --threshold calibrated  # second round
    python3 bench/detection_runs.py --settings ours --train-on robot --injection robot   # third round

For each run of RUNS (../shared/data/real/, SOURCES.md there): the odometry up to ``--train`` of its duration
(default 0.5) trains a model (``learning.train`` defaults, nominal only); the rest is replayed through the
classifier trigger (``triggers.ClassifierTrigger``, the one the smart logger runs, classify_every 50ms).
Fires open or extend logging windows of [fire - pre, fire + post] (pre/post 2 s; overlapping ones merge, as
in ``WindowBuffer``). Without injection every window is false. With injection, ``sim.inject_anomalies``
puts one anomaly of one simulator type into the replayed part (warmup 3 s, gap 2 s), per type and seed:
caught when a fire falls in [onset, end + feature window]; latency = first such fire - onset (target
<= 0.5 s); a window with no such fire is false; kept = odometry messages inside windows, needed = those in
[onset - pre, end + post] (target kept <= 1.5 x needed); 'kept' without injection: the share of the replayed
part's messages inside windows. Types that do not fit into a short replay are
counted as 'no room'.

``--injection``: ``bwibot`` injects the simulator's magnitudes (m/s, rad/s of the BWIBot, the same on every
robot); ``robot`` injects them at each run's own scale: ``sim.nominal_envelope`` of its training part (largest
speed, acceleration, deceleration, yaw rate, yaw acceleration) is ``scale`` and ``limits`` of
``sim.inject_anomalies``, so a collision decelerates ~20x harder than the run's hardest braking, a surge
accelerates 4-6x harder than its hardest acceleration up to 2.2x its top speed, twisting adds 1.5-2.2x its
largest yaw rate, a localization jump moves 0.6-2 s of its top speed (the BWIBot's ratios to its limits).

``--threshold``: ``trained`` is ``learning.train``'s (held-out blocks of the training vectors, ``--margin``);
``calibrated`` trains on the first (1 - ``--calibration``) of the training part and sets the threshold with
``tuning.tune`` (``cclog tune``, budget 0 false windows/h) on the rest of it (held-out nominal driving, the
same trigger and windows), then lowers it by ``--calibration-margin`` x (held-out median - threshold).

``--train-on``: ``self`` trains on the run's first part alone; ``robot`` also on every other run of the same
robot (ROBOTS: F1/10 DS1-DS5, the four ICE-lab runs, the two Pioneer traces) in full, each run's vectors
computed apart (no feature window across two runs), as a lab that trains on the robot's earlier runs would;
the replayed part and its injections (at the scale of the run's own first part) are the same as with ``self``.
Husky and ALFA have one run each and keep ``self``. With ``--threshold calibrated`` the last ``--calibration``
of every training piece (the first part and each other run) is held out and calibrates.

Besides kept/needed over every injection, the bench prints it over the anomalies whose windows hold no false
fire (the window rule's own fit), and for every catch later than LATENCY what the classifications within
LATENCY of the onset did (``why_late``): an open window from an earlier fire, no whole-window classification,
an anomalous score the retrigger rule did not fire on, or every score above the threshold.

``--slowed N``: every training piece also trains as N slower copies (``retime.slowed``: stops and slow stretches
along its own path, at its own acceleration and deceleration, at least ``--braking`` m/s^2 when given).

``--separability``: per run, no windows: the deepest nominal score of the replayed part against the
shallowest injected anomaly onset (within LATENCY), as depth in units of the model's threshold; whether any
threshold could separate them. ``--types``: inject only these simulator types.

Settings: ``ours`` = motion features, 2 s window, retrigger 'event' (the default); ``dynamics`` = the level-free
dynamics features, the same otherwise; ``every`` = motion with retrigger
'every' (the paper's rule); ``paper`` = raw features over a count window of about 2 s, nu 0.5, threshold 0
(OneClassSVM.predict), retrigger 'every'. Sequor is left out (trials of a few frames hours apart: no
continuous driving to inject into; bench/detection_real.py scores it by trial); ALFA is used up to its
engine failure (+116.25 s).
"""
import argparse
import collections
import functools
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402
from common import count_of  # noqa: E402

import retime  # noqa: E402
from cc_log.storage.bag import bagio  # noqa: E402
from cc_log.learning import learning  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.offline import tuning  # noqa: E402
from cc_log.features import FeatureConfig, FeatureStream, vector_length  # noqa: E402

# (name, odometry topic, seconds after the start where nominal driving ends or None)
RUNS = [
    ('husky_outdoor_2015', '/husky_velocity_controller/odom', None),
    ('f1tenth_DS1', '/odom', None), ('f1tenth_DS2', '/odom', None), ('f1tenth_DS3', '/odom', None),
    ('f1tenth_DS4', '/odom', None), ('f1tenth_DS5', '/odom', None),
    ('icelab_normal_plan', '/odom', None), ('icelab_normal_plan_1', '/odom', None),
    ('icelab_window_plan', '/odom', None), ('icelab_window_plan_1', '/odom', None),
    ('socspioneer_trace0', '/odom', None), ('socspioneer_trace1', '/odom', None),
    ('alfa_carbonZ_engine_failure', '/mavros/local_position/odom', 116.25),
]
# The runs of one robot (``--train-on robot``: each run is replayed by a model trained on the others in full plus
# its own first part); a robot with one run (Husky, ALFA) keeps the run's own first part.
ROBOTS = collections.OrderedDict([
    ('husky', ('husky_outdoor_2015',)),
    ('f1tenth', ('f1tenth_DS1', 'f1tenth_DS2', 'f1tenth_DS3', 'f1tenth_DS4', 'f1tenth_DS5')),
    ('icelab', ('icelab_normal_plan', 'icelab_normal_plan_1', 'icelab_window_plan', 'icelab_window_plan_1')),
    ('pioneer', ('socspioneer_trace0', 'socspioneer_trace1')),
    ('alfa', ('alfa_carbonZ_engine_failure',)),
])
TRAIN_ON = ('self', 'robot')
WINDOW = '2s'
PRE = POST = 2.0
CLASSIFY_EVERY = '50ms'
LATENCY = 0.5
PERSISTENCE = 5     # classifications: 'k of the last n' needs k within LATENCY (5 at 10 Hz, 10 at 50ms steps)
INJECTIONS = ('bwibot', 'robot')
THRESHOLDS = ('trained', 'calibrated')
TRAIN_OPTIONS = {}  # --gamma-factor, --nu: passed to learning.train (empty: its defaults)
BRAKING = [None]
SLOWED = []  # --slowed N: seeds of the slower copies (retime.slowed) of every training piece that also train
SETTINGS = collections.OrderedDict([
    ('ours', ('motion', 'event', {})),
    ('dynamics', ('dynamics', 'event', {})),
    ('every', ('motion', 'every', {})),
    ('paper', ('raw', 'every', {'nu': 0.5})),
])


def bag_path(name):
    return os.path.normpath(os.path.join(os.path.dirname(common.HUSKY_BAG), name + '.bag'))


@functools.lru_cache(maxsize=None)
def _read(name, topic, stop):
    records = list(bagio.read_messages(bag_path(name), [topic]))
    start = records[0].stamp
    if stop is not None:
        records = [r for r in records if r.stamp - start < stop]
    return tuple(records)


def load(name, topic, stop):
    """The odometry records of a run (up to ``stop`` seconds after its start when given)."""
    return list(_read(name, topic, stop))


def other_runs(name):
    """``(name, topic, stop)`` of every other run of ``name``'s robot (ROBOTS) that is in RUNS."""
    robot = next((runs for runs in ROBOTS.values() if name in runs), (name,))
    return [run for run in RUNS if run[0] in robot and run[0] != name]


def training_pieces(name, first, train_on):
    """What trains a run's model: its first part, with ``train_on`` 'robot' also every other run of its robot."""
    return [first] + ([load(*run) for run in other_runs(name)] if train_on == 'robot' else [])


def split(records, fraction):
    start, end = records[0].stamp, records[-1].stamp
    cut = start + fraction * (end - start)
    return [r for r in records if r.stamp < cut], [r for r in records if r.stamp >= cut]


def rate_of(records):
    steps = np.diff([r.stamp for r in records])
    return 1.0 / float(np.median(steps[steps > 0]))


def config_of(feature_set, rate):
    if feature_set == 'raw':
        return FeatureConfig('raw', str(max(2, int(round(2.0 * rate)))))
    return FeatureConfig(feature_set, WINDOW)


def vectors_of(records, config):
    """``(stamps, vectors)`` of one continuous run's records, a vector per message once the window is whole."""
    stream = FeatureStream(config, every=1)
    pairs = [(r.stamp, v) for r, v in ((r, stream.add(r.msg, r.stamp)) for r in records) if v is not None]
    return np.array([t for t, _ in pairs]), np.array([v for _, v in pairs])


def train(pieces, config, options, margin=learning.DEFAULT_MARGIN):
    """A model of the vectors (one per message) of ``pieces``, lists of records each of one continuous run."""
    X = []
    for records in pieces:
        X += list(vectors_of(records, config)[1])
        for seed in SLOWED:
            X += list(vectors_of(retime.slowed(records, seed, braking=BRAKING[0]), config)[1])
    if len(X) < learning.MIN_VECTORS:
        raise ValueError('%d training vectors' % len(X))
    X = np.array(X)
    if options.get('nu') == 0.5:
        model, _ = learning.train(X, config=config, nu=0.5, gamma=1.0 / vector_length(config))
        model.threshold = 0.0
    else:
        options = dict(TRAIN_OPTIONS)
        if 'gamma_factor' in options:
            options['gamma'] = options.pop('gamma_factor') / vector_length(config)
        model, _ = learning.train(X, config=config, margin=margin, **options)
    return model, len(X)


def fires(model, records, topic, rule):
    """Stamps at which the classifier trigger fires (the model's threshold, CLASSIFY_EVERY, ``rule``)."""
    return tuning.fires(model, records, topic, model.threshold, CLASSIFY_EVERY, rule)


def windows_of(stamps):
    """Merged [fire - PRE, fire + POST] intervals."""
    return tuning.windows_of(stamps, PRE, POST)


def inside(stamps, intervals):
    return sum(1 for t in stamps if any(a <= t <= b for a, b in intervals))


def calibrate(model, runs, topic, rule, margin):
    """Set ``model.threshold`` on held-out nominal ``runs`` (lists of records) with ``tuning.tune`` (no false
    window), from above every score of theirs, then lower it by ``margin`` x (held-out median - threshold)."""
    model.info = dict(model.info, trained_threshold=model.threshold)
    model.threshold = max(float(np.max(tuning.step_scores(model, records, topic, CLASSIFY_EVERY)))
                          for records in runs) + 1.0
    tuning.tune(model, runs, topic, 0.0, '%gs' % PRE, '%gs' % POST, CLASSIFY_EVERY, rule)
    model.threshold -= margin * max(model.info['held_out_score_median'] - model.threshold, 0.0)
    return model


def prepare(name, topic, stop, setting, fraction, margin=learning.DEFAULT_MARGIN, injection='bwibot',
            threshold='trained', calibration=0.25, calibration_margin=learning.DEFAULT_MARGIN, train_on='self'):
    """A run's records, its replayed part, the model (threshold per ``threshold``, trained per ``train_on``:
    the run's first part, or with ``robot`` also every other run of its robot in full) and the keyword
    arguments of ``sim.inject_anomalies`` for ``injection`` (at the scale of the run's own first part)."""
    feature_set, rule, options = SETTINGS[setting]
    records = load(name, topic, stop)
    first, rest = split(records, fraction)
    config = config_of(feature_set, rate_of(records))
    pieces = training_pieces(name, first, train_on)
    if threshold == 'calibrated':
        cuts = [split(piece, 1.0 - calibration) for piece in pieces]
        model, vectors = train([fit for fit, _ in cuts], config, options, margin)
        calibrate(model, [held for _, held in cuts], topic, rule, calibration_margin)
    else:
        model, vectors = train(pieces, config, options, margin)
    model.info = dict(model.info, nominal_seconds=sum(piece[-1].stamp - piece[0].stamp for piece in pieces))
    inject = dict(topic=topic, warmup=3.0, gap=2.0)
    if injection == 'robot':
        envelope = sim.nominal_envelope(first, topic)
        inject.update(scale=envelope, limits=envelope)
    return records, first, rest, model, vectors, inject


def describe_threshold(name, model):
    """One line: a calibrated threshold and the model's score floor (no support vector near) as depth below
    the held-out median in units of the trained threshold's (1 = trained, as ``--separability``)."""
    if 'trained_threshold' not in model.info:
        return None
    median = model.info['held_out_score_median']
    floor = float(model.scores(np.full((1, model.dimension), 1e9))[0])
    unit = median - model.info['trained_threshold']
    return '%s calibrated threshold at depth %.2f, score floor at %.2f%s' % (
        name, (median - model.threshold) / unit, (median - floor) / unit,
        ': below the floor, nothing can fire' if model.threshold < floor else '')


def describe_scale(name, inject):
    """One line: the run's envelope when anomalies are injected at its scale."""
    scale = inject.get('scale')
    return None if scale is None else '%s envelope: %s' % (
        name, ', '.join('%s %.2f' % item for item in scale._asdict().items()))


def describe_slowed(name, first):
    """One line, with --slowed: how much the twist of the run's first part lags its pose, and its envelope."""
    if not SLOWED:
        return None
    lag = retime.twist_lag([r.stamp for r in first], [retime.state(r.msg) for r in first])
    return '%s slowed copies: twist lags the pose by %.2f s; envelope %s' % (
        name, lag, ', '.join('%s %.2f' % item for item in sim.nominal_envelope(first)._asdict().items()))


def evaluate_run(name, topic, stop, setting, seeds, fraction, margin=learning.DEFAULT_MARGIN,
                 types=sim.ANOMALY_TYPES, **how):
    """One run, one setting, anomalies of ``types`` (``how``: injection, threshold, calibration,
    calibration_margin of ``prepare``): a dict of the figures."""
    rule = SETTINGS[setting][1]
    records, first, rest, model, vectors, inject = prepare(name, topic, stop, setting, fraction, margin, **how)
    rate = rate_of(records)
    config = model.config
    reach = config.span.seconds if config.span.is_duration else config.span.count / rate
    seconds = rest[-1].stamp - rest[0].stamp
    nominal_fires = fires(model, rest, topic, rule)
    nominal_windows = windows_of(nominal_fires)
    every = nominal_fires if rule == 'every' else fires(model, rest, topic, 'every')
    persistence = [sum(1 for t in every if a <= t <= b) for a, b in windows_of(every)]
    result = {'run': name, 'start': records[0].stamp, 'rate': rate, 'train_s': model.info['nominal_seconds'],
              'vectors': vectors, 'replay_from': rest[0].stamp - records[0].stamp,
              'replay_s': seconds, 'false_nominal': len(nominal_windows), 'nominal_windows': nominal_windows,
              'caught': collections.Counter(), 'total': collections.Counter(), 'late': collections.Counter(),
              'no_room': collections.Counter(), 'latency': collections.defaultdict(list), 'false_injected': 0,
              'injected_s': 0.0, 'kept': 0, 'needed': 0, 'clean': 0, 'clean_kept': 0, 'clean_needed': 0,
              'late_cases': [], 'window': config.window,
              'nominal_kept': inside([r.stamp for r in rest], nominal_windows) / float(len(rest)),
              'persistence': persistence, 'threshold': model.threshold, 'scale': describe_scale(name, inject),
              'calibrated': describe_threshold(name, model),
              'slowed': describe_slowed(name, first)}
    for kind in types:
        for seed in seeds:
            try:
                injected, truth = sim.inject_anomalies(rest, [kind], seed=seed, **inject)
            except ValueError:
                result['no_room'][kind] += 1
                continue
            entry = truth[0]
            stamps = fires(model, injected, topic, rule)
            windows = windows_of(stamps)
            near = [t for t in stamps if entry['start'] <= t <= entry['end'] + reach]
            result['total'][kind] += 1
            if near:
                result['caught'][kind] += 1
                result['latency'][kind].append(near[0] - entry['start'])
                if near[0] - entry['start'] > LATENCY:
                    result['late'][kind] += 1
                    result['late_cases'].append(why_late(model, injected, topic, rule, stamps, entry, kind, seed))
            result['false_injected'] += sum(
                1 for a, b in windows if not any(entry['start'] <= t <= entry['end'] + reach and a <= t <= b
                                                 for t in stamps))
            result['injected_s'] += seconds
            odom = [r.stamp for r in injected]
            kept = inside(odom, windows)
            needed = inside(odom, [(entry['start'] - PRE, entry['end'] + POST)])
            result['kept'] += kept
            result['needed'] += needed
            own = [(a, b) for a, b in windows if any(a <= t <= b for t in near)]
            if near and not any(a <= t <= b for a, b in own for t in stamps if t not in near):
                # the anomaly's windows hold no false fire: the window rule's own fit
                result['clean'] += 1
                result['clean_kept'] += inside(odom, own)
                result['clean_needed'] += needed
    return result


def explain_false(name, topic, stop, setting, fraction, top=4, **how):
    """The false windows of a run's replayed part without injection, one line each: when, how the robot drove
    in it (speed and yaw rate against the training part's), and its most anomalous vector's features farthest
    from the training vectors (z: in training standard deviations; beyond: past the training range, in units of
    that range)."""
    how = {key: value for key, value in how.items() if key in ('train_on', 'injection', 'threshold')}
    records, first, rest, model, _, _ = prepare(name, topic, stop, setting, fraction, **how)
    rule = SETTINGS[setting][1]
    config = model.config
    pieces = training_pieces(name, first, how.get('train_on'))
    X = np.vstack([vectors_of(piece, config)[1] for piece in pieces])
    mean, std, low, high = X.mean(0), X.std(0), X.min(0), X.max(0)
    names = model.names
    stamps, V = vectors_of(rest, config)
    scores = model.scores(V)

    def motion(recs):
        return (np.array([math.hypot(r.msg.twist.twist.linear.x, r.msg.twist.twist.linear.y) for r in recs]),
                np.array([r.msg.twist.twist.angular.z for r in recs]))
    train_speed, train_yaw = motion([r for piece in pieces for r in piece])
    lines = []
    for a, b in windows_of(fires(model, rest, topic, rule)):
        inside_window = (stamps >= a) & (stamps <= b)
        k = int(np.argmin(np.where(inside_window, scores, np.inf)))
        z = (V[k] - mean) / np.where(std > 0, std, 1.0)
        beyond = np.maximum(V[k] - high, low - V[k]) / np.where(high > low, high - low, 1.0)
        speed, yaw = motion([r for r in rest if a <= r.stamp <= b])
        lines.append('%s %.1f-%.1f s: speed %.2f-%.2f m/s (training 5-95%%: %.2f-%.2f), |yaw rate| up to %.2f rad/s '
                     '(training 99%%: %.2f); farthest: %s; beyond the training range: %s' % (
                         name, a - records[0].stamp, b - records[0].stamp, speed.min(), speed.max(),
                         np.quantile(train_speed, 0.05), np.quantile(train_speed, 0.95), np.abs(yaw).max(),
                         np.quantile(np.abs(train_yaw), 0.99),
                         ', '.join('%s z %.1f' % (names[j], z[j]) for j in np.argsort(-np.abs(z))[:top]),
                         ', '.join('%s %.2f' % (names[j], beyond[j]) for j in np.argsort(-beyond)[:top]
                                   if beyond[j] > 0) or 'none'))
    return lines


def why_late(model, injected, topic, rule, stamps, entry, kind, seed):
    """A catch later than LATENCY: what the classifications within LATENCY of its onset did. 'open': a fire
    within POST before the onset (its window already logs the onset); 'not scored': no classification of a
    whole feature window within LATENCY; 'suppressed': one scored anomalous but the retrigger rule did not fire;
    'above threshold': every score stayed above the threshold (the model's ranking)."""
    onset = entry['start']
    times, scores = scored(model, injected, topic)
    near = (times >= onset) & (times <= onset + LATENCY)
    before = [t for t in stamps if onset - POST <= t < onset]
    if before:
        cause = 'open'
    elif not near.any():
        cause = 'not scored'
    elif (scores[near] < model.threshold).any():
        cause = 'suppressed (%s)' % rule
    else:
        cause = 'above threshold'
    median = model.info['held_out_score_median']
    depth = (median - float(scores[near].min())) / (median - model.threshold) if near.any() else float('nan')
    first = next(t for t in stamps if t >= onset)
    return {'kind': kind, 'seed': seed, 'onset': onset, 'latency': first - onset, 'cause': cause,
            'depth': depth, 'scored': int(near.sum()), 'anomalous': int((scores[near] < model.threshold).sum())}


def scored(model, records, topic):
    """(stamps, scores) of every classification of the whole feature window (CLASSIFY_EVERY)."""
    stream = FeatureStream(model.config, every=CLASSIFY_EVERY)
    pairs = [(r.stamp, v) for r in records if r.topic == topic for v in [stream.add(r.msg, r.stamp)] if v is not None]
    return np.array([t for t, _ in pairs]), model.scores(np.array([v for _, v in pairs]))


def separability(name, topic, stop, setting, seeds, fraction, types=sim.ANOMALY_TYPES, **how):
    """Could any threshold separate this run? Scores as depth below the held-out median in units of
    (median - threshold), so 1 is the model's threshold (``how``: as ``evaluate_run``): the deepest nominal
    classification of the replayed part against, per injected anomaly, the deepest one within LATENCY of its
    onset (the shallowest of those)."""
    _, _, rest, model, _, inject = prepare(name, topic, stop, setting, fraction, **how)
    median = model.info['held_out_score_median']
    depth = lambda scores: (median - scores) / (median - model.threshold)  # noqa: E731
    _, nominal = scored(model, rest, topic)
    anomalies = []
    for kind in types:
        for seed in seeds:
            try:
                injected, truth = sim.inject_anomalies(rest, [kind], seed=seed, **inject)
            except ValueError:
                continue
            stamps, scores = scored(model, injected, topic)
            near = (stamps >= truth[0]['start']) & (stamps <= truth[0]['start'] + LATENCY)
            anomalies.append((float(depth(scores[near]).max()) if near.any() else float('-inf'), kind))
    return float(depth(nominal).max()), min(anomalies)


def main(argv=None):
    global WINDOW
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', help='comma-separated run names (default: all of RUNS)')
    parser.add_argument('--seeds', default='0,1,2')
    parser.add_argument('--settings', default=','.join(SETTINGS),
                        help='comma-separated: ours, dynamics, every, paper')
    parser.add_argument('--train', type=float, default=0.5, help='fraction of each run that trains (default 0.5)')
    parser.add_argument('--margin', type=float, default=learning.DEFAULT_MARGIN,
                        help='threshold margin of learning.train (default %g)' % learning.DEFAULT_MARGIN)
    parser.add_argument('--types', default='all', help='anomaly types to inject, comma-separated (default all)')
    parser.add_argument('--injection', default='bwibot', choices=INJECTIONS,
                        help="bwibot: the simulator's magnitudes; robot: at each run's own nominal envelope")
    parser.add_argument('--threshold', default='trained', choices=THRESHOLDS,
                        help="trained: learning.train's; calibrated: tuning.tune on held-out nominal driving")
    parser.add_argument('--calibration', type=float, default=0.25,
                        help='with --threshold calibrated: the last part of the training part that calibrates')
    parser.add_argument('--calibration-margin', type=float, default=learning.DEFAULT_MARGIN,
                        help='with --threshold calibrated: lower by this x (held-out median - threshold)')
    parser.add_argument('--train-on', default='self', choices=TRAIN_ON,
                        help="self: the run's first part; robot: also every other run of its robot in full")
    parser.add_argument('--window', default=WINDOW, help='feature window of ours/dynamics/every (default %s)' % WINDOW)
    parser.add_argument('--gamma-factor', type=float,
                        help='RBF gamma x the vector length (default: learning.DEFAULT_GAMMA_FACTOR, %g)'
                        % learning.DEFAULT_GAMMA_FACTOR)
    parser.add_argument('--nu', type=float, help='one-class SVM nu (default: learning.DEFAULT_NU, %g)'
                        % learning.DEFAULT_NU)
    parser.add_argument('--slowed', type=int, default=0, metavar='N',
                        help='also train on N slower copies of every training piece (retime.slowed: stops and '
                        'slow stretches at the piece\'s own acceleration and deceleration)')
    parser.add_argument('--braking', type=float, metavar='M/S2',
                        help='with --slowed: the copies brake and start at least this hard (default: the piece\'s '
                        'own envelope)')
    parser.add_argument('--explain', action='store_true',
                        help='per false window without injection: how the robot drove, the features farthest '
                        'from the training vectors')
    parser.add_argument('--separability', action='store_true',
                        help='per run: the deepest nominal score against the shallowest anomaly onset (no windows)')
    args = parser.parse_args(argv)
    WINDOW = args.window
    SLOWED[:] = range(args.slowed)
    BRAKING[0] = args.braking
    TRAIN_OPTIONS.clear()
    TRAIN_OPTIONS.update((key, value) for key, value in (('gamma_factor', args.gamma_factor), ('nu', args.nu))
                         if value is not None)
    seeds = [int(s) for s in args.seeds.split(',')]
    types = sim.parse_anomaly_types(args.types, 'types')
    how = dict(types=types, injection=args.injection, threshold=args.threshold, calibration=args.calibration,
               calibration_margin=args.calibration_margin, train_on=args.train_on)
    runs = [r for r in RUNS if not args.runs or r[0] in args.runs.split(',')]
    settings = args.settings.split(',')
    started = time.time()
    common.header('Every real run with odometry: trained on its first part, replayed with injected anomalies',
                  [common.describe_data(bag_path(name)) for name, _, _ in runs] +
                  ['training: first %g of each run; injection: one anomaly per type (%s) and seed %s into the rest; '
                   'window %s, pre/post %gs/%gs, classify_every %s, threshold margin %g' % (
                       args.train, ', '.join(types), seeds, WINDOW, PRE, POST, CLASSIFY_EVERY, args.margin)
                   + ''.join(', %s %g' % item for item in sorted(TRAIN_OPTIONS.items())),
                   'injection: %s (%s); threshold: %s%s' % (
                       args.injection, "the simulator's BWIBot magnitudes" if args.injection == 'bwibot' else
                       "each run's own nominal envelope (sim.nominal_envelope of its training part)",
                       args.threshold, '' if args.threshold == 'trained' else
                       ' on the last %g of every training piece (tuning.tune, 0 false windows), margin %g' % (
                           args.calibration, args.calibration_margin)),
                   'training on: %s' % (
                       "each run's first part" if args.train_on == 'self' else
                       "each run's first part and every other run of its robot in full (%s)" % (
                           '; '.join(', '.join(runs) for runs in ROBOTS.values())))])
    if args.explain:
        for setting in settings:
            print('setting %s: false windows without injection' % setting)
            for name, topic, stop in runs:
                for line in explain_false(name, topic, stop, setting, args.train, **how):
                    print(line)
        print('total %.1f s' % (time.time() - started))
        return 0
    if args.separability:
        for setting in settings:
            rows = []
            for name, topic, stop in runs:
                nominal, (anomaly, kind) = separability(name, topic, stop, setting, seeds, args.train, **how)
                rows.append([name, '%.2f' % nominal, '%.2f (%s)' % (anomaly, kind),
                             'yes' if anomaly > nominal else 'no'])
            common.table(['run', 'deepest nominal', 'shallowest anomaly within %gs' % LATENCY,
                          'a threshold separates'], rows,
                         'setting %s: depth below the held-out median, 1 = the model\'s threshold' % setting)
        print('total %.1f s' % (time.time() - started))
        return 0
    for setting in settings:
        rows, totals = [], collections.Counter()
        by_type = collections.defaultdict(collections.Counter)
        latencies = collections.defaultdict(list)
        oddities, persistence, late_cases = [], [], []
        for name, topic, stop in runs:
            try:
                r = evaluate_run(name, topic, stop, setting, seeds, args.train, args.margin, **how)
            except ValueError as error:
                rows.append([name, '-', '-', '-', '-', '-', '-', 'not run: %s' % error, '-', '-', '-'])
                continue
            caught, total = sum(r['caught'].values()), sum(r['total'].values())
            late = sum(r['late'].values())
            rows.append([name, '%.0f' % r['rate'], '%.0f' % r['train_s'], '%.0f' % r['replay_s'],
                         r['false_nominal'], '%.1f' % (3600.0 * r['false_nominal'] / r['replay_s']),
                         '%.0f%%' % (100.0 * r['nominal_kept']),
                         '%s (%d late, %d no room)' % (count_of(caught, total), late, sum(r['no_room'].values())),
                         r['false_injected'], '%.2fx' % (r['kept'] / float(r['needed'])) if r['needed'] else '-',
                         '%.2fx (%d)' % (r['clean_kept'] / float(r['clean_needed']), r['clean'])
                         if r['clean_needed'] else '-'])
            totals.update({'false': r['false_nominal'], 'replay_s': r['replay_s'], 'caught': caught,
                           'total': total, 'late': late, 'kept': r['kept'], 'needed': r['needed'],
                           'false_injected': r['false_injected'], 'clean': r['clean'],
                           'clean_kept': r['clean_kept'], 'clean_needed': r['clean_needed']})
            late_cases += [dict(case, run=name) for case in r['late_cases']]
            totals['injected_s'] += r['injected_s']
            persistence += r['persistence']
            for kind in types:
                by_type[kind].update({'caught': r['caught'][kind], 'total': r['total'][kind],
                                      'late': r['late'][kind], 'no_room': r['no_room'][kind]})
                latencies[kind].extend(r['latency'][kind])
            oddities += [line for line in (r['scale'], r['calibrated'], r['slowed']) if line]
            if name in ('f1tenth_DS2', 'f1tenth_DS5'):
                oddities.append('%s: windows without injection from %s s after the run start (replay from %.0f s)'
                                % (name, ', '.join('%.1f-%.1f' % (a - r['start'], b - r['start'])
                                                   for a, b in r['nominal_windows']) or 'none',
                                   r['replay_from']))
        print('setting %s: %s features, retrigger %s %s' % (setting, SETTINGS[setting][0], SETTINGS[setting][1],
                                                            SETTINGS[setting][2] or ''))
        common.table(['run', 'Hz', 'train s', 'replay s', 'false windows (no injection)', 'false/h', 'kept',
                      'caught (late > %gs)' % LATENCY, 'false windows (injected)', 'kept/needed',
                      'kept/needed, no false fire in its windows (n)'], rows)
        common.table(['type', 'caught', 'late', 'no room', 'median latency s', 'worst latency s'],
                     [[kind, count_of(c['caught'], c['total']), c['late'], c['no_room'],
                       '%.2f' % np.median(latencies[kind]) if latencies[kind] else '-',
                       '%.2f' % max(latencies[kind]) if latencies[kind] else '-']
                      for kind, c in by_type.items()], 'by type:')
        hours = totals['replay_s'] / 3600.0
        print('all runs: caught %s (%d later than %gs); false windows without injection %d in %.3f h = %.1f/h; '
              'false windows with injection %d in %.3f h = %.1f/h; kept/needed %.2fx' % (
                  count_of(totals['caught'], totals['total']), totals['late'], LATENCY, totals['false'], hours,
                  totals['false'] / hours if hours else 0.0, totals['false_injected'], totals['injected_s'] / 3600.0,
                  totals['false_injected'] / (totals['injected_s'] / 3600.0) if totals['injected_s'] else 0.0,
                  totals['kept'] / float(totals['needed']) if totals['needed'] else float('nan')))
        print('kept/needed over the %d anomalies whose windows hold no false fire: %.2fx' % (
            totals['clean'], totals['clean_kept'] / float(totals['clean_needed']) if totals['clean_needed']
            else float('nan')))
        if late_cases:
            common.table(['run', 'type', 'seed', 'latency s', 'why', 'classifications within %gs' % LATENCY,
                          'of them anomalous', 'deepest (1 = threshold)'],
                         [[c['run'], c['kind'], c['seed'], '%.2f' % c['latency'], c['cause'], c['scored'],
                           c['anomalous'], '%.2f' % c['depth']] for c in late_cases],
                         'later than %gs:' % LATENCY)
        if persistence:
            print('anomalous classifications per false window without injection (retrigger every): median %d, '
                  'fewer than %d (what a %g s persistence rule could remove): %d of %d windows' % (
                      np.median(persistence), PERSISTENCE, LATENCY,
                      sum(1 for n in persistence if n < PERSISTENCE), len(persistence)))
        for line in oddities:
            print(line if 'envelope' in line or 'calibrated' in line else 'real oddity: ' + line)
        print()
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
