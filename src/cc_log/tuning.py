"""A false-window budget: set a model's threshold so nominal runs give at most N false windows per hour.

``tune(model, runs, topic, max_false_per_hour, ...)`` replays nominal runs (lists of ``Record``s) through the
classifier trigger the smart logger runs (``triggers.ClassifierTrigger``: classify_every, retrigger), merges
its fires into logging windows of [fire - pre, fire + post] as ``WindowBuffer`` does, and lowers the threshold
(to just below the score of a nominal classification) until the windows per hour of nominal driving are
within the budget. It then injects one anomaly of every simulator type (``sim.inject_anomalies``) into the
first run and reports which the tuned threshold still catches (a fire between onset and end + feature
window). The result goes into ``model.info['tuned']``. Figures on the tuning runs are in-sample: held-out
nominal runs give the honest rate. Pure: no rospy.
"""
import collections
import copy

import numpy as np

from . import sim
from .features import FeatureStream
from .spans import Span
from .triggers import ClassifierTrigger

DEFAULT_PRE = DEFAULT_POST = '2s'
DEFAULT_RETRIGGER = 'event'
DEFAULT_CLASSIFY_EVERY = '50ms'


def _seconds(span, rate, name):
    span = Span.parse(span, name)
    return span.seconds if span.is_duration else span.count / rate


def _rate(records):
    steps = np.diff([r.stamp for r in records])
    steps = steps[steps > 0]
    return 1.0 / float(np.median(steps)) if len(steps) else 1.0


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


def tune(model, runs, topic, max_false_per_hour, pre=DEFAULT_PRE, post=DEFAULT_POST,
         classify_every=DEFAULT_CLASSIFY_EVERY, retrigger=DEFAULT_RETRIGGER, sources=None):
    """Lower ``model.threshold`` (in place) until the nominal ``runs`` give at most ``max_false_per_hour``
    windows per hour; return the record stored in ``model.info['tuned']`` (see the module docstring)."""
    if not (max_false_per_hour >= 0):
        raise ValueError('max_false_per_hour: %r must be zero or positive' % (max_false_per_hour,))
    runs = [[r for r in run if r.topic == topic] for run in runs]
    runs = [run for run in runs if len(run) > 1]
    if not runs:
        raise ValueError('bag: no %s messages to tune on' % topic)
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
    if count > allowed:
        scores = np.concatenate([step_scores(model, run, topic, classify_every) for run in runs])
        candidates = np.unique(scores[scores < before])  # ascending: each lowers the threshold below a score
        lo, hi = 0, len(candidates)   # threshold just below candidates[i]; i = 0: below every nominal score
        while lo < hi:
            middle = (lo + hi) // 2
            if false_windows(np.nextafter(candidates[middle], -np.inf)) <= allowed:
                lo = middle + 1
            else:
                hi = middle
        threshold = float(np.nextafter(candidates[lo - 1], -np.inf)) if lo else float(
            np.nextafter(candidates[0], -np.inf) if len(candidates) else before)
        count = false_windows(threshold)
    model.threshold = threshold
    caught, missed = catches(model, runs[0], topic, classify_every, retrigger)
    record = collections.OrderedDict([
        ('max_false_per_hour', float(max_false_per_hour)), ('hours', hours), ('bags', list(sources or [])),
        ('topic', topic), ('pre', str(Span.parse(pre, 'pre'))), ('post', str(Span.parse(post, 'post'))),
        ('classify_every', str(Span.parse(classify_every, 'classify_every'))), ('retrigger', retrigger),
        ('threshold_before', before), ('false_windows_before', start), ('threshold', threshold),
        ('false_windows', count), ('false_per_hour', count / hours if hours else 0.0),
        ('catches', caught), ('misses', missed)])
    model.info = dict(model.info, tuned=record)
    return record


def catches(model, run, topic, classify_every=DEFAULT_CLASSIFY_EVERY, retrigger=DEFAULT_RETRIGGER, seed=0):
    """``(caught types, missed types)``: one anomaly of every simulator type injected into ``run`` at a time
    (types that do not fit into the run are missed, marked ``'<type> (no room)'``)."""
    span = model.config.span
    reach = span.seconds if span.is_duration else span.count / _rate(run)
    caught, missed = [], []
    for kind in sim.ANOMALY_TYPES:
        try:
            injected, truth = sim.inject_anomalies(run, [kind], seed=seed, topic=topic, warmup=3.0, gap=2.0)
        except ValueError:
            missed.append('%s (no room)' % kind)
            continue
        entry = truth[0]
        stamps = fires(model, injected, topic, model.threshold, classify_every, retrigger)
        hit = any(entry['start'] <= t <= entry['end'] + reach for t in stamps)
        (caught if hit else missed).append(kind)
    return caught, missed
