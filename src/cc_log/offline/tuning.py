"""A false-window budget: set a model's threshold so nominal runs give at most N false windows per hour.

``tune(model, runs, topic, max_false_per_hour, ...)`` replays nominal runs (lists of ``Record``s) through the
classifier trigger the smart logger runs (``triggers.ClassifierTrigger``: classify_every, retrigger), merges
its fires into logging windows of [fire - pre, fire + post] as ``WindowBuffer`` does, and lowers the threshold
(to just below the score of a nominal classification) until the windows per hour of nominal driving are
within the budget. It then injects one anomaly of every simulator type (``sim.inject_anomalies``) into the
first run, at the robot's own scale (``injection_scale='robot'``: every magnitude in the ratio of the runs'
nominal envelope, ``sim.nominal_envelope``, to the BWIBot's; ``'bwibot'``: the simulator's magnitudes), and
reports which the tuned threshold still catches (a fire between onset and end + feature window; the latency is
the first such fire's delay after onset). The result goes into ``model.info['tuned']``. Figures on the tuning
runs are in-sample: held-out nominal runs give the honest rate.

It never loses an event without saying so: recall is measured on those injected anomalies at the model's own
threshold, at the tuned one and along a curve of CURVE_POINTS thresholds (false windows per hour against events
caught, ``curve``); ``lost`` names the types the tuned threshold no longer catches, and ``keep_recall_*`` the
lowest threshold that still catches every type the model's own threshold catches (found by binary search like
the budget's) with its false windows. With ``keep_recall`` that threshold is the one chosen, budget or not.

``choose(model, runs, topic, max_false_per_hour, windows, rates)`` also picks the feature window and the
classify rate: for every window of a small grid and every classify rate it tunes the threshold as above, then
keeps the setting that meets the budget and catches the most injected types, with the smallest mean latency
among those (then the fewest false windows). When a window other than the model's is tried, a model of it is
trained (``learning.train``'s defaults) on the first half of every run by time, and every setting, the given
model's too, is tuned and judged on the second halves: no setting is judged on the data it was trained on.
Pure: no rospy.
"""
import collections
import copy
import math

import numpy as np

from cc_log.learning import learning
from cc_log import sim
from cc_log.features import CLIP, FeatureConfig, FeatureStream
from cc_log.base.spans import Span
from cc_log.triggers import ClassifierTrigger

DEFAULT_PRE = DEFAULT_POST = '2s'
DEFAULT_RETRIGGER = 'event'
DEFAULT_CLASSIFY_EVERY = '50ms'
TRAIN_EVERY = '100ms'   # one training vector per this much of the nominal runs (a model of another window)
CURVE_POINTS = 8        # thresholds of the false-windows-against-recall curve (plus the model's and the chosen)
# The scale of the injected anomalies: 'robot', the tuning runs' own (a 0.09 m/s Create and a 10 m/s car get
# anomalies of their own size); 'bwibot', the simulator's magnitudes in m/s and rad/s whatever the robot.
INJECTION_SCALES = ('robot', 'bwibot')
DEFAULT_INJECTION_SCALE = 'robot'


def _seconds(span, rate, name):
    span = Span.parse(span, name)
    return span.seconds if span.is_duration else span.count / rate


def _rate(records):
    steps = np.diff([r.stamp for r in records])
    steps = steps[steps > 0]
    return 1.0 / float(np.median(steps)) if len(steps) else 1.0


def _below(score):
    """A threshold just below ``score``: below it by more than the rounding between the batch scores
    (``model.scores``) and the trigger's one-vector ``model.score``."""
    return float(score - 1e-9 * max(1.0, abs(score)))


def windows_of(stamps, pre, post):
    """Merged ``[fire - pre, fire + post]`` intervals of sorted fire stamps (seconds)."""
    out = []
    for t in stamps:
        if out and t - pre <= out[-1][1]:
            out[-1][1] = t + post
        else:
            out.append([t - pre, t + post])
    return out


def fires(model, records, topic, threshold, classify_every=DEFAULT_CLASSIFY_EVERY, retrigger=DEFAULT_RETRIGGER):
    """Stamps at which the classifier trigger fires on ``records`` (of ``topic``) with ``threshold``."""
    tuned = copy.copy(model)
    tuned.threshold = float(threshold)
    trigger = ClassifierTrigger('classifier', tuned, topic, classify_every=classify_every, retrigger=retrigger)
    return [r.stamp for r in records if r.topic == topic and trigger.on_record(r)]


def step_scores(model, records, topic, classify_every=DEFAULT_CLASSIFY_EVERY):
    """Scores of every classification of the whole feature window (as the trigger classifies) of ``topic``."""
    stream = FeatureStream(model.config, every=classify_every)
    vectors = [v for v in (stream.add(r.msg, r.stamp) for r in records if r.topic == topic) if v is not None]
    return model.scores(np.array(vectors)) if vectors else np.array([])


def injection_envelope(runs, topic, injection_scale=DEFAULT_INJECTION_SCALE):
    """The ``Limits`` anomalies are injected at (``sim.inject_anomalies``' ``scale``): with 'robot' the nominal
    envelope of all ``runs`` on ``topic`` (None when they hold too few messages for one), with 'bwibot' None (the
    simulator's magnitudes)."""
    if injection_scale not in INJECTION_SCALES:
        raise ValueError('injection_scale: %r is not one of %s' % (injection_scale, ', '.join(INJECTION_SCALES)))
    if injection_scale == 'bwibot':
        return None
    try:
        return sim.nominal_envelope([r for run in runs for r in run], topic)
    except ValueError:  # too few messages for an envelope: too few to inject anything into as well
        return None


def _bad_field(msg, prefix=''):
    """The path of the first float field of ``msg`` that is not finite or beyond +-CLIP, or ''."""
    for name in getattr(msg, '__slots__', ()):
        value = getattr(msg, name, None)
        if isinstance(value, float):
            if not (abs(value) <= CLIP):
                return prefix + name
        elif hasattr(value, '__slots__') and not isinstance(value, (str, bytes)):
            found = _bad_field(value, prefix + name + '.')
            if found:
                return found
    return ''


def usable_runs(runs, topic, config, sources=None):
    """``(runs, rejected)``: the records of ``topic`` of each run whose values for the feature set of ``config``
    (its ``read``) are finite and within +-CLIP, as feature rows keep them (a NaN, inf or 1e308 twist is not
    driving), and how many of each run were left out. ValueError('<bag>: ...', naming a field) when no run
    keeps two records."""
    reader = config.feature(config)
    kept, rejected, example = [], [], ''
    for run in runs:
        good, bad = [], 0
        for r in run:
            if r.topic != topic:
                continue
            try:
                values = reader.read(r.msg)
                ok = all(abs(float(v)) <= CLIP for v in values) and math.isfinite(r.stamp)
            except (AttributeError, TypeError, ValueError, OverflowError):
                ok = False
            if ok:
                good.append(r)
            else:
                bad += 1
                example = example or _bad_field(r.msg) or 'a field the %s set reads' % config.feature_set
        kept.append(good)
        rejected.append(bad)
    if not any(len(run) > 1 for run in kept):
        names = ', '.join(sources or []) or 'bag'
        if any(rejected):
            raise ValueError('%s: no usable %s messages to tune on: %d of them have a non-finite or huge value '
                             '(beyond %g; e.g. %s)' % (names, topic, sum(rejected), CLIP, example))
        raise ValueError('%s: no %s messages to tune on' % (names, topic))
    return kept, rejected


def rejected_lines(record):
    """One line per tuning bag that had messages left out (``usable_runs``), for stderr."""
    return ['warning: %s: %d %s message(s) left out of tuning: a non-finite or huge value (beyond %g)'
            % (source, count, record['topic'], CLIP)
            for source, count in zip(record['bags'] or ['bag'] * len(record['rejected']), record['rejected'])
            if count]


def tune(model, runs, topic, max_false_per_hour, pre=DEFAULT_PRE, post=DEFAULT_POST,
         classify_every=DEFAULT_CLASSIFY_EVERY, retrigger=DEFAULT_RETRIGGER, sources=None, keep_recall=False,
         injection_scale=DEFAULT_INJECTION_SCALE):
    """Lower ``model.threshold`` (in place) until the nominal ``runs`` give at most ``max_false_per_hour``
    windows per hour (with ``keep_recall``: to the lowest threshold that still catches every injected type the
    model's own threshold catches); return the record stored in ``model.info['tuned']`` (see the module
    docstring). ``injection_scale``: 'robot' or 'bwibot' (``INJECTION_SCALES``)."""
    if not (max_false_per_hour >= 0):
        raise ValueError('max_false_per_hour: %r must be zero or positive' % (max_false_per_hour,))
    runs, rejected = usable_runs(runs, topic, model.config, sources)
    runs = [run for run in runs if len(run) > 1]
    envelope = injection_envelope(runs, topic, injection_scale)
    hours = sum(run[-1].stamp - run[0].stamp for run in runs) / 3600.0
    rate = _rate(runs[0])
    pre_s, post_s = _seconds(pre, rate, 'pre'), _seconds(post, rate, 'post')
    allowed = int(np.floor(max_false_per_hour * hours + 1e-9))

    def false_windows(threshold):
        return sum(len(windows_of(fires(model, run, topic, threshold, classify_every, retrigger), pre_s, post_s))
                   for run in runs)

    before = model.threshold
    start = false_windows(before)
    threshold, count = before, start
    scores = np.concatenate([step_scores(model, run, topic, classify_every) for run in runs])
    candidates = np.unique(scores[np.isfinite(scores) & (scores < before)])  # ascending: each lowers the threshold
    if count > allowed:
        lo, hi = 0, len(candidates)   # threshold just below candidates[i]; i = 0: below every nominal score
        while lo < hi:
            middle = (lo + hi) // 2
            if false_windows(_below(candidates[middle])) <= allowed:
                lo = middle + 1
            else:
                hi = middle
        while True:
            threshold = _below(candidates[lo - 1]) if lo else (_below(candidates[0]) if len(candidates) else before)
            count = false_windows(threshold)
            # Fewer fires can split a window in two (and 'event' fires where a lower threshold re-arms it), so
            # the count is not monotonic in the threshold: the search may end on a setting it only inferred.
            if count <= allowed or lo == 0:
                break
            lo -= 1
    injected = injections(model, runs[0], topic, envelope=envelope)

    def caught_at(value):
        return [kind for kind, delay in caught_in(model, injected, topic, value, classify_every, retrigger).items()
                if delay is not None]

    reference = caught_at(before)  # what the model's own threshold catches: every event to keep
    keep, keep_count = _keep_recall(candidates, before, start, reference, caught_at, false_windows)
    budget_threshold, budget_count = threshold, count
    if keep_recall:
        threshold, count = keep, keep_count
    model.threshold = threshold
    found = caught_in(model, injected, topic, threshold, classify_every, retrigger)
    caught = [kind for kind, delay in found.items() if delay is not None]
    latencies = [found[kind] for kind in caught]
    curve = _curve(candidates, [before, threshold, keep, budget_threshold], caught_at, false_windows, hours)
    record = collections.OrderedDict([
        ('max_false_per_hour', float(max_false_per_hour)), ('hours', hours), ('bags', list(sources or [])),
        ('topic', topic), ('pre', str(Span.parse(pre, 'pre'))), ('post', str(Span.parse(post, 'post'))),
        ('classify_every', str(Span.parse(classify_every, 'classify_every'))), ('retrigger', retrigger),
        ('threshold_before', before), ('false_windows_before', start), ('threshold', threshold),
        ('false_windows', count), ('false_per_hour', count / hours if hours else 0.0),
        ('catches', caught), ('misses', [kind for kind, delay in found.items() if delay is None]),
        ('latencies', dict((kind, found[kind]) for kind in caught)),
        ('mean_latency', float(np.mean(latencies)) if latencies else None),
        ('injected', sum(1 for entry in injected if entry[1] is not None)), ('injection_scale', injection_scale),
        ('envelope', dict(envelope._asdict()) if envelope else None), ('caught_before', reference),
        ('lost', [kind for kind in reference if kind not in caught]), ('keep_recall', bool(keep_recall)),
        ('keep_recall_threshold', keep), ('keep_recall_false_windows', keep_count),
        ('keep_recall_false_per_hour', keep_count / hours if hours else 0.0),
        ('budget_threshold', budget_threshold), ('budget_false_windows', budget_count), ('curve', curve),
        ('rejected', rejected)])
    model.info = dict(model.info, tuned=record)
    return record


def _keep_recall(candidates, before, start, reference, caught_at, false_windows):
    """``(threshold, false windows)``: the lowest threshold (just below a nominal score) that still catches every
    type of ``reference``, by binary search over ``candidates`` (ascending), checked as the budget's is."""
    def keeps(value):
        found = caught_at(value)
        return all(kind in found for kind in reference)

    lo, hi = 0, len(candidates)  # find the first candidate whose threshold just below it keeps every event
    while lo < hi:
        middle = (lo + hi) // 2
        if keeps(_below(candidates[middle])):
            hi = middle
        else:
            lo = middle + 1
    while lo < len(candidates) and not keeps(_below(candidates[lo])):  # recall is not monotonic either
        lo += 1
    if lo >= len(candidates):
        return before, start
    value = _below(candidates[lo])
    return value, false_windows(value)


def _curve(candidates, extra, caught_at, false_windows, hours):
    """``[{threshold, false_windows, false_per_hour, caught}]``, highest threshold first: CURVE_POINTS thresholds
    spread evenly over the range of the nominal scores below the model's threshold, and ``extra``."""
    values = set(extra)
    if len(candidates):  # evenly over the score range (quantiles would crowd at the model's score floor)
        targets = np.linspace(candidates[0], candidates[-1], CURVE_POINTS)
        values.update(_below(candidates[min(len(candidates) - 1, int(i))])
                      for i in np.searchsorted(candidates, targets))
    curve = []
    for value in sorted(values, reverse=True):
        count = false_windows(value)
        curve.append(collections.OrderedDict([
            ('threshold', value), ('false_windows', count), ('false_per_hour', count / hours if hours else 0.0),
            ('caught', caught_at(value))]))
    return curve


def injections(model, run, topic, seed=0, envelope=None):
    """``[(type, the run with one anomaly of it injected, its truth entry, reach)]`` of ``detections``: one per
    simulator type that fits into ``run`` (reach: the feature window in seconds), at the scale of ``envelope``
    (``injection_envelope``; None: the simulator's magnitudes)."""
    span = model.config.span
    reach = span.seconds if span.is_duration else span.count / _rate(run)
    out = []
    for kind in sim.ANOMALY_TYPES:
        try:
            injected, truth = sim.inject_anomalies(run, [kind], seed=seed, topic=topic, warmup=3.0, gap=2.0,
                                                   scale=envelope, limits=envelope or sim.BWIBOT_LIMITS)
        except ValueError:
            out.append((kind, None, None, reach))
            continue
        out.append((kind, injected, truth[0], reach))
    return out


def caught_in(model, injected, topic, threshold, classify_every=DEFAULT_CLASSIFY_EVERY,
              retrigger=DEFAULT_RETRIGGER):
    """``detections`` of ``injections`` at ``threshold``."""
    found = collections.OrderedDict()
    for kind, run, entry, reach in injected:
        if run is None:
            found['%s (no room)' % kind] = None
            continue
        hits = [t for t in fires(model, run, topic, threshold, classify_every, retrigger)
                if entry['start'] <= t <= entry['end'] + reach]
        found[kind] = hits[0] - entry['start'] if hits else None
    return found


def detections(model, run, topic, classify_every=DEFAULT_CLASSIFY_EVERY, retrigger=DEFAULT_RETRIGGER, seed=0):
    """``{type: seconds from onset to the first fire within [onset, end + feature window], or None}``: one
    anomaly of every simulator type injected into ``run`` at a time (a type that does not fit into the run is
    None under the key ``'<type> (no room)'``)."""
    return caught_in(model, injections(model, run, topic, seed), topic, model.threshold, classify_every, retrigger)


def catches(model, run, topic, classify_every=DEFAULT_CLASSIFY_EVERY, retrigger=DEFAULT_RETRIGGER, seed=0):
    """``(caught types, missed types)`` of ``detections``."""
    found = detections(model, run, topic, classify_every, retrigger, seed)
    return ([kind for kind, delay in found.items() if delay is not None],
            [kind for kind, delay in found.items() if delay is None])


def _halves(run):
    """``run`` cut in two at the middle of its time span."""
    if not run:
        return [], []
    middle = (run[0].stamp + run[-1].stamp) / 2.0
    index = next(i for i, r in enumerate(run) if r.stamp >= middle)
    return run[:index], run[index:]


def model_for(model, runs, topic, window, every=TRAIN_EVERY):
    """``model`` when its feature window is ``window``, else a model of its feature set with that window
    trained with ``learning.train``'s defaults on the vectors of ``runs`` (one per ``every``)."""
    config = FeatureConfig(model.config.feature_set, window, model.config.topic_type)
    if config == model.config:
        return copy.deepcopy(model)
    vectors = []
    for run in runs:
        stream = FeatureStream(config, every=every)
        vectors += [v for v in (stream.add(r.msg, r.stamp) for r in run if r.topic == topic) if v is not None]
    try:
        trained, _ = learning.train(np.array(vectors), config=config)
    except ValueError as error:
        raise ValueError('windows: %s: %s' % (config.window, error))
    return trained


def choose(model, runs, topic, max_false_per_hour, windows=None, rates=(DEFAULT_CLASSIFY_EVERY,), pre=DEFAULT_PRE,
           post=DEFAULT_POST, retrigger=DEFAULT_RETRIGGER, sources=None, keep_recall=False,
           injection_scale=DEFAULT_INJECTION_SCALE):
    """Tune every feature window in ``windows`` (default: the model's) with every classify rate in ``rates``;
    return ``(model, record)`` of the chosen setting (see the module docstring). ``record`` is ``tune``'s with
    ``window``, ``chosen_by`` and ``grid`` (a summary of every setting) added; it is the model's
    ``info['tuned']``. ``keep_recall``, ``injection_scale``: as ``tune``'s."""
    runs, rejected = usable_runs(runs, topic, model.config, sources)
    windows = [model.config.window] if not windows else list(windows)
    configs = [FeatureConfig(model.config.feature_set, window, model.config.topic_type) for window in windows]
    train_runs = tune_runs = runs
    if any(config != model.config for config in configs):
        halves = [_halves([r for r in run if r.topic == topic]) for run in runs]
        train_runs, tune_runs = [first for first, _ in halves], [second for _, second in halves]
    grid, best = [], None
    for config in configs:
        base = model_for(model, train_runs, topic, config.window)
        for rate in rates:
            candidate = copy.deepcopy(base)
            record = tune(candidate, tune_runs, topic, max_false_per_hour, pre, post, rate, retrigger, sources,
                          keep_recall, injection_scale)
            meets = record['false_per_hour'] <= max_false_per_hour + 1e-9
            key = (meets, len(record['catches']), -(record['mean_latency'] if record['catches'] else float('inf')),
                   -record['false_windows'])
            grid.append(collections.OrderedDict([
                ('window', candidate.config.window), ('classify_every', record['classify_every']),
                ('trained', candidate.config != model.config), ('threshold', record['threshold']),
                ('false_windows', record['false_windows']), ('false_per_hour', record['false_per_hour']),
                ('meets_budget', meets), ('catches', record['catches']), ('mean_latency', record['mean_latency']),
                ('lost', record['lost']), ('keep_recall_false_per_hour', record['keep_recall_false_per_hour'])]))
            if best is None or key > best[0]:
                best = (key, candidate, record)
    _, chosen, record = best
    record = collections.OrderedDict(record, window=chosen.config.window, grid=grid, rejected=rejected,
                                     chosen_by='meets the budget, most types caught, smallest mean latency',
                                     tuned_on='whole runs' if tune_runs is runs else
                                     'second halves (the first halves trained the other windows)')
    chosen.info = dict(chosen.info, tuned=record)
    return chosen, record
