"""The classifier trigger: a learned model (one-class SVM) over a feature set of one or more topics.

The model's feature configuration names the set and its window; ``topics`` are the topic names of the set's
inputs, in its order (the first makes the rows). Its ``features.FeatureStream`` scores the window every
``classify_every`` (a count or a duration) once the window holds continuous data; an anomalous score
(``score < threshold``) fires, every time (``retrigger='every'``, the paper's rule) or only at the onset
(``'onset'``: the score must come back above the threshold before it fires again), or at the onset and then
only while the newest rows are anomalous (``'event'``: the window ends at the anomaly's end plus post, not a
whole feature window later). Several classifiers may run at once, each with its own model, topics,
``classify_every`` and ``retrigger``. A Fire says why (``base.why.classifier_why``): the entries of the window
vector furthest outside what the model's training vectors covered. A window whose rows hold a value out of
any physical range (``features.base.out_of_range``: clipped at +-CLIP) is anomalous whatever the model says,
with the score OUT_OF_RANGE_SCORE: clipped, it would look like any far vector, which a threshold tuned low may
call nominal. Pure: no rospy.
"""
import os
import time

import numpy as np

from cc_log import features
from cc_log.learning import online_learning
from cc_log.base import why
from cc_log.features import FeatureStream
from cc_log.features.base import CLIP, out_of_range
from cc_log.base.spans import Span
from cc_log.base.topic_select import topic_list
from cc_log.triggers.base import Trigger, register

# Which anomalous scores fire:
# - 'every': every message scored anomalous (the paper's rule). A feature window of W messages keeps scoring
#   anomalous for up to W messages after the anomaly itself ended, so windows grow by that tail.
# - 'onset': only the onset, i.e. a message scored anomalous after a message scored nominal (or the first
#   score since the start / a restart): hysteresis at the threshold.
# - 'event': the onset (as 'onset'), then, while the whole feature window stays anomalous, only the scores of the
#   newest rows: the ``recent`` rows (default: the newest quarter of the feature window) put in place of the
#   newest rows of the last window scored nominal. Once the anomalous rows are older than ``recent`` this
#   window is nominal again, so the logging window ends at the anomaly's end + recent + post instead of
#   end + feature window + post (the anomalous rows still in the feature window no longer extend it).
RETRIGGER_MODES = ('every', 'onset', 'event')
DEFAULT_RETRIGGER = 'event'
RECENT_FRACTION = 0.25  # default ``recent``: this fraction of the feature window

# How often the classifier scores the feature window (a Span): '1' = every message of the first input (the
# paper's rule), 'N' = every N-th message, a duration such as '50ms' = at most one decision per 50 ms of
# message time (20 decisions/s: every 5th message at 100 Hz, every message at 10 Hz). Skipping saves the
# window vector and the model on the skipped messages; an anomaly still fires at the message where it is
# detected (at most one period late), and the window's pre part keeps the skipped messages before it.
DEFAULT_CLASSIFY_EVERY = '50ms'
OUT_OF_RANGE_SCORE = -CLIP  # the score of a window holding a value out of range: below any model's threshold


def default_topics(topics, feature_set, resolve):
    """The resolved topics of a classifier: ``topics`` (a list or a space-separated string), else the role
    names of its feature set's inputs (``odom``, ``imu``, ``cmd_vel``)."""
    if topics is None:
        topics = [role for role, _ in features.get(feature_set).inputs]
    return [resolve(topic) for topic in topic_list(topics, 'topics')]


@register
class ClassifierTrigger(Trigger):
    """Fires on anomalous classifier scores (see the module docstring).

    model: an ``AnomalyModel`` (or anything with ``config``, ``threshold`` and ``is_anomalous(vector)``);
    topics: a topic name or a list of them, one per input of the model's feature set.
    """

    kind = 'classifier'
    config_keys = ('model', 'topics', 'feature_set', 'window', 'classify_every', 'retrigger', 'recent',
                   'learn_online', 'learn_every', 'learn_keep', 'learn_guard', 'learn_resume')

    @classmethod
    def from_config(cls, name, options, context):
        """The model file of ``model``; ``feature_set`` and ``window``, when given, must be the model's;
        ``topics`` default to the feature set's role names."""
        options = dict(options)
        path = options.pop('model', None)
        if not isinstance(path, str) or not path:
            raise ValueError('model: required (the model file written by learn mode)')
        try:
            model = context.load_model(os.path.expanduser(path))
        except ValueError as error:
            raise ValueError('model: %s' % error)
        for key in ('feature_set', 'window'):
            value = options.pop(key, None)
            if value is not None and str(value) != getattr(model.config, key) and not (
                    key == 'window' and Span.parse(value, 'window') == model.config.span):
                raise ValueError('%s: %s does not match the model\'s %s (it is part of the model; leave it out)'
                                 % (key, value, getattr(model.config, key)))
        topics = default_topics(options.pop('topics', None), model.config.feature_set, context.resolve)
        learner = online_learning.from_options(model, os.path.expanduser(path), options, context.load_model,
                                               context.online_dir)
        return cls(name, model, topics, learner=learner, **options)

    def __init__(self, name, model, topics, classify_every=DEFAULT_CLASSIFY_EVERY, retrigger=DEFAULT_RETRIGGER,
                 pre=None, post=None, recent=None, learner=None):
        super(ClassifierTrigger, self).__init__(name, pre, post)
        if retrigger not in RETRIGGER_MODES:
            raise ValueError('retrigger: %r is not one of %s' % (retrigger, ', '.join(RETRIGGER_MODES)))
        self.model = model
        self.original = model  # the model file's (online learning: refits only widen it, online_learning)
        self.config = model.config
        self.threshold = float(model.threshold)
        self.retrigger = retrigger
        inputs = self.config.feature.inputs
        names = [topics] if isinstance(topics, str) else list(topics)
        if len(names) != len(inputs) or not all(isinstance(t, str) and t for t in names):
            raise ValueError('%s: topics: the %s feature set reads %d topic(s) (%s), got %r'
                             % (name, self.config.feature_set, len(inputs), ', '.join(r for r, _ in inputs), topics))
        self.input_topics = tuple(names)
        self.topic = names[0]
        self.topics = frozenset(names)
        self._roles = {topic: role for topic, (role, _) in zip(names[1:], inputs[1:])}
        self._types = {topic: kind for topic, (_, kind) in zip(names, inputs)}
        self.classify_every = Span.parse(classify_every, 'classify_every')
        if self.classify_every.count == 0:
            raise ValueError('classify_every: 0 messages; use 1 to classify every message')
        self.recent = recent_span(self.config.span, recent, name)
        self.learner = learner  # an online_learning.OnlineLearner, or None (no online learning)
        # callables (stamp, anomalous, vector, margin: score - threshold) told every decision, e.g.
        # drift.DriftMonitor.observe
        self.observers = []
        self.calls = 0
        self.seconds = 0.0
        self.max_seconds = 0.0
        self.anomalous = 0
        self.reset()

    def reset(self):
        self.stream = FeatureStream(self.config, every=self.classify_every)
        self._armed = True  # 'onset': the next anomalous score fires (no anomalous score since a nominal one)
        self._nominal_rows = None  # 'event': the rows of the last feature window scored nominal

    def topic_types(self):
        return dict(self._types)

    def needs_message(self, record):
        return not self.config.feature.reads_raw(record.connection)

    batched = True

    def on_record(self, record):
        return self.on_records([record])[0]

    def on_records(self, records):
        """Feature rows and window vectors of the whole batch (``FeatureStream.add_records``), every vector
        scored in one call (``scores``), then the retrigger rule over the scores in order."""
        if self.learner is not None:
            self._take_learned()
        started = time.perf_counter()
        batch = self.stream.add_records(records, self._roles)
        vectors = batch.vectors
        scores = scores_of(self.model, vectors) if len(vectors) else ()
        if len(vectors):
            elapsed = time.perf_counter() - started
            self.calls += len(vectors)
            self.seconds += elapsed
            self.max_seconds = max(self.max_seconds, elapsed / len(vectors))
        nominal = self._nominal_rows
        fires = [self._decide(record, step, batch, scores) for record, step in zip(records, batch.steps)]
        if self._nominal_rows is not nominal:
            self._nominal_rows = self._nominal_rows.copy()  # a view of the feature window until now
        return fires

    def _decide(self, record, step, batch, scores):
        """The Fires of one record's step (``WindowBatch.steps``): None (another input), no vector (not scored
        when the window is not whole), or a vector's score."""
        if step is None:
            return []
        reset, whole, k = step
        # not scored (start, after a gap or a jump back): the next anomalous score is an onset
        if reset or not whole:
            self._armed = True
        if k is None:
            return []
        score = min(OUT_OF_RANGE_SCORE, scores[k]) if out_of_range(batch.rows(k)) else scores[k]
        anomalous = score < self.threshold
        fires = []
        if self.learner is not None:
            self.learner.observe(record.stamp, batch.vectors[k], anomalous)
        for observe in self.observers:
            observe(record.stamp, anomalous, batch.vectors[k], score - self.threshold)
        if anomalous:
            self.anomalous += 1
            if not self._armed and self.retrigger == 'event':
                anomalous, score = self._score_recent(batch.rows(k), batch.newest(k, self.recent))
            if anomalous and (self._armed or self.retrigger != 'onset'):
                fires.append(self.fire('classifier', float(score), self.explain(batch.vectors[k])))
            self._armed = False
        else:
            self._armed = True
            if self.retrigger == 'event':
                self._nominal_rows = batch.rows(k)
        return fires

    def explain(self, vector):
        """The features of a window ``vector`` that stood out against the model file's training data
        (``base.why.classifier_why``; () for a model without a scaler)."""
        if getattr(self.original, 'scale', None) is None:
            return ()
        return why.classifier_why(self.original, vector)

    def _score_recent(self, window_rows, recent):
        """``(anomalous, score)`` of the newest ``recent`` rows in place of the newest rows of the last window
        scored nominal (of the whole feature window ``window_rows`` when there is none)."""
        if self._nominal_rows is None or len(recent) >= len(self._nominal_rows):
            rows = window_rows if self._nominal_rows is None else recent
        else:
            rows = np.concatenate((self._nominal_rows[len(recent):], recent))
        if out_of_range(rows):
            return True, OUT_OF_RANGE_SCORE
        return self.model.is_anomalous(self.config.feature.vector(rows, self.config.span))

    def _take_learned(self):
        """Online learning: take a refitted model when one is ready."""
        model = self.learner.take()
        if model is not None:
            self.model = online_learning.WidenedModel(self.original, model)
            self.threshold = self.model.threshold

    def stats(self):
        result = super(ClassifierTrigger, self).stats()
        result.update(classifier_calls=self.calls, classifier_seconds=self.seconds,
                      classifier_max_seconds=self.max_seconds, anomalous_messages=self.anomalous)
        if self.learner is not None:
            result['online'] = self.learner.stats()
        return result

    def describe(self):
        result = super(ClassifierTrigger, self).describe()
        result.update(topics=list(self.input_topics), model=self.config.to_dict(), threshold=self.threshold,
                      classify_every=str(self.classify_every), retrigger=self.retrigger)
        if self.retrigger == 'event':
            result['recent'] = str(self.recent)
        if self.learner is not None:
            result['online'] = self.learner.resumed or 'learning online from scratch'
        return result


def scores_of(model, vectors):
    """The scores of ``vectors`` (a list of 1-D arrays), each what the model gives one vector (see ``score_each``):
    ``AnomalyModel.score_each``, or one ``is_anomalous`` call at a time for another model."""
    score_each = getattr(model, 'score_each', None)
    if score_each is None:
        return [model.is_anomalous(vector)[1] for vector in vectors]
    return score_each(vectors)


def recent_span(window, recent, name='classifier'):
    """The ``recent`` Span of the 'event' rule: ``recent`` parsed (a count or duration of the feature window's
    kind, at most the window), or RECENT_FRACTION of the feature window ``window`` (a Span) when None."""
    if recent in (None, ''):
        if window.is_duration:
            return Span.duration(window.seconds * RECENT_FRACTION)
        return Span.messages(max(1, int(round(window.count * RECENT_FRACTION))))
    span = Span.parse(recent, '%s: recent' % name)
    if span.is_duration != window.is_duration or (span.count or span.seconds or 0) <= 0:
        raise ValueError('%s: recent: %s must be a positive %s like the feature window %s' % (
            name, span, 'duration' if window.is_duration else 'message count', window))
    if (span.seconds or span.count) > (window.seconds or window.count):
        raise ValueError('%s: recent: %s is longer than the feature window %s' % (name, span, window))
    return span
