"""The envelope trigger: a window of odometry beyond what the robot's nominal driving ever reached.

Configuration (``kind: envelope``)::

    triggers:
      - {name: envelope, kind: envelope, limits: envelope.json, topic: /odom, factor: 2.0, joint_factor: 4.0,
         local_factor: 6.0, on_drift: confirm}

``limits``: the file ``cclog learn-envelope`` wrote (``learning.envelope.Envelope``: the largest value of each of
the 19 ``features.envelope`` features over nominal windows); ``topic``: the nav_msgs/Odometry topic (default:
the one it was learned on); ``factor`` (default 2.0): a window is flagged when a feature exceeds ``factor`` x
its training maximum (floored by ``ENVELOPE_FLOORS``); ``joint_factor`` (default 4.0; 0: off), when the file
has a joint check (``learning.envelope.Joint``): a window is flagged too when its squared robust distance from
typical driving goes ``joint_factor`` x farther past the typical one than any training window did;
``local_factor`` (default 6.0; 0: off), when the file has a local part (``learning.local_density``): a window is
flagged too when its local outlier factor among the training windows goes ``local_factor`` x farther past the
typical one than any training window's (a window in a sparse gap between kinds of nominal driving); ``on_drift``
(default ``confirm``; ``none``): once the trigger's own drift monitor has stated drift for a whole span, a feature
beyond its limit needs the robust distance's confirmation (``drift_gate``). A model path
given as the default trigger (``~model``, ``cclog replay --model``) builds this trigger when the file is an
envelope (``logger.config.with_classifier``).

Every ``stride`` (0.25 s, the file's) of message time the trigger computes the row of the window of ``window``
s (1 s, the file's) ending on that grid point, from a ring of the last ``window`` + ``HISTORY`` seconds of
samples (``features.envelope.envelope_rows``: the very rows ``envelope_windows`` gives offline), all of a
batch's windows at once (the joint check: one 19 x 19 quadratic form per window; the local part: the distances
to every stored training window, brute force). A window beyond
the envelope fires at the first message at or after its end, with score ``-ln(max(value / limit, joint
ratio))`` (< 0; lower is more anomalous) and ``why``: the features beyond their limit and the joint check, most
outstanding first, each against the most seen in training (``learning.envelope.explain``). Each such
window fires (every 0.25 s while the motion stays beyond the envelope; the logger merges them). A window that
holds a sample out of any physical range (``features.envelope.out_of_range_samples``: a speed, yaw rate or
position that is inf, NaN or beyond +-1e6, which the rows leave out) fires too, with the score
OUT_OF_RANGE_SCORE and that said first in its ``why``, even when no sample of it could be measured. Pure: no rospy.
"""
import os
import time

import numpy as np

from cc_log.learning.envelope import (
    DEFAULT_FACTOR, DEFAULT_JOINT_FACTOR, DEFAULT_LOCAL_FACTOR, MAX_WHY, Envelope, check_factor, check_joint_factor,
    check_local_factor, explain, part_ratios, score_of)
from cc_log.features.envelope import (
    ENVELOPE_COLUMNS, HISTORY, clean_samples, envelope_rows, odometry_samples, out_of_range_samples, step_details)
from cc_log.features.base import CLIP
from cc_log.features.motion import ODOMETRY, OdometrySet
from cc_log.triggers.base import Trigger, register
from cc_log.triggers import drift_gate

REASON = 'envelope'
OUT_OF_RANGE_SCORE = -CLIP  # the score of a window holding a sample out of range: below any envelope score


@register
class EnvelopeTrigger(Trigger):
    """Fires on odometry windows beyond the learned envelope (see the module docstring).

    envelope: a ``learning.envelope.Envelope``; topic: its nav_msgs/Odometry topic; factor: the limit factor;
    joint_factor: the joint check's (0: off; no effect when the envelope has no joint check); local_factor: the
    local part's (likewise); on_drift: what changes once its drift monitor states drift (``drift_gate``)."""

    kind = 'envelope'
    config_keys = ('limits', 'topic', 'factor', 'joint_factor', 'local_factor', 'on_drift')
    batched = True

    @classmethod
    def from_config(cls, name, options, context):
        """The envelope file of ``limits``; ``topic`` defaults to the one it was learned on."""
        options = dict(options)
        path = options.pop('limits', None)
        if not isinstance(path, str) or not path:
            raise ValueError('limits: required (the envelope file written by cclog learn-envelope)')
        envelope = Envelope.load(os.path.expanduser(path))
        topic = options.pop('topic', None)
        if topic is not None and (not isinstance(topic, str) or not topic):
            raise ValueError('%s: topic: %r is not a topic name' % (name, topic))
        return cls(name, envelope, context.resolve(topic or envelope.topic), **options)

    def __init__(self, name, envelope, topic, factor=DEFAULT_FACTOR, joint_factor=DEFAULT_JOINT_FACTOR,
                 local_factor=DEFAULT_LOCAL_FACTOR, on_drift=drift_gate.DEFAULT_ON_DRIFT, pre=None, post=None):
        super(EnvelopeTrigger, self).__init__(name, pre, post)
        if not isinstance(envelope, Envelope):
            raise ValueError('%s: envelope: expected an Envelope, got %s' % (name, type(envelope).__name__))
        self.envelope = envelope
        self.factor = check_factor(factor, '%s: factor' % name)
        self.limits = envelope.limits(self.factor)
        self.joint_factor = check_joint_factor(joint_factor, '%s: joint_factor' % name)
        self.joint = envelope.joint if self.joint_factor else None   # None: per feature only
        self.local_factor = check_local_factor(local_factor, '%s: local_factor' % name)
        self.local = envelope.local if self.local_factor else None   # None: no local part
        self.on_drift = drift_gate.check_on_drift(on_drift, '%s: on_drift' % name)
        # the drift monitor on_drift follows (drift.monitor_envelopes reports it); None: nothing to gate
        self.drift = drift_gate.monitor_for(self) if on_drift == 'confirm' and self.joint is not None else None
        self.unconfirmed = 0    # windows beyond a feature's limit left closed under drift (not confirmed)
        self.topic = topic
        self.topics = frozenset([topic])
        self.window, self.stride = envelope.window, envelope.stride
        # callables (stamp, anomalous, row) told every window evaluated (its end, beyond the envelope or not, its
        # features; None when it holds no measured sample), e.g. drift.DriftMonitor.observe (drift.monitor_envelopes)
        self.observers = []
        self.evaluated = 0      # windows computed
        self.beyond = 0         # of them beyond the envelope
        self.seconds = 0.0
        self.reset()

    def reset(self):
        self._ring = tuple(np.zeros(0) for _ in range(6))   # stamps, x, y, yaw, v, w
        self._beyond = np.zeros(0)  # the stamps of the samples out of range still inside a window to come
        self._first = None      # the first stamp since the start or a restart
        self._last_end = None   # the last grid point evaluated

    def topic_types(self):
        return {self.topic: ODOMETRY}

    def needs_message(self, record):
        return not OdometrySet.reads_raw(record.connection)

    def on_record(self, record):
        return self.on_records([record])[0]

    def on_records(self, records):
        """The Fires of a batch of odometry records (a list per record): the samples joined to the ring, then
        every grid window that ended by the newest one evaluated at once."""
        started = time.perf_counter()
        samples = odometry_samples(records)
        fires = [[] for _ in records]
        finite = np.isfinite(samples[0])
        stamps = np.where(finite, samples[0], -np.inf)
        start = 0
        while start < len(records):
            known = self._ring[0][-1] if len(self._ring[0]) else -np.inf
            newest = np.maximum.accumulate(np.concatenate(([known], stamps[start:])))
            # time going back more than a window (a bag played again): the ring starts over there
            back = np.flatnonzero(finite[start:] & (stamps[start:] < newest[:-1] - self.window))
            if len(back) and back[0] == 0:
                self.reset()
                continue
            stop = start + int(back[0]) if len(back) else len(records)
            self._take(tuple(a[start:stop] for a in samples), newest[1:stop - start + 1], fires, start)
            start = stop
        self.seconds += time.perf_counter() - started
        return fires

    def _take(self, samples, newest, fires, offset):
        """Add ``samples`` (in time order but for dropped ones) to the ring and evaluate the windows they end."""
        beyond = samples[0][out_of_range_samples(*samples)]
        samples = clean_samples(*samples)
        if len(self._ring[0]):   # the ring's stamps only go forward (a stamp repeated for ever never grows it)
            samples = tuple(a[samples[0] > self._ring[0][-1]] for a in samples)
        if not len(samples[0]) and not len(beyond):
            return
        self._ring = tuple(np.concatenate((ring, new)) for ring, new in zip(self._ring, samples))
        self._beyond = np.sort(np.concatenate((self._beyond, beyond)))
        if self._first is None:
            self._first = float(samples[0][0] if len(samples[0]) else beyond[0])
        k0 = np.ceil((self._first + self.window) / self.stride - 1e-9)
        if self._last_end is not None:
            k0 = max(k0, np.round(self._last_end / self.stride) + 1)
        k1 = np.floor(newest[-1] / self.stride + 1e-9)
        grid = self._ends(k0, k1)
        if not len(grid):
            return
        self._last_end = float(grid[-1])
        ends, rows = envelope_rows(*self._ring, ends=grid, window=self.window)
        self.evaluated += len(ends)
        worst, other = part_ratios(rows, self.limits, self.joint, self.joint_factor, self.local, self.local_factor)
        window_scores = score_of(np.maximum(worst, other))
        if self.drift is not None:
            drifted, confirming = drift_gate.drifted_ratios(rows, worst, other, self.joint, self.joint_factor)
            drifted_scores = score_of(drifted)
        held = (np.searchsorted(self._beyond, grid, side='right') -
                np.searchsorted(self._beyond, grid - self.window, side='right'))  # out-of-range samples per window
        measured = dict(zip(ends.tolist(), range(len(ends))))
        if self.drift is not None:  # its coverage sees every row at once (each is observed below, in grid order)
            covered = self.drift.coverage.observe_rows(rows).tolist() if len(rows) else []
        best = {}
        for end, count in zip(grid.tolist(), held.tolist()):
            k = measured.get(end)
            score = OUT_OF_RANGE_SCORE if count else float(window_scores[k]) if k is not None else 0.0
            confirmed = False
            if k is not None or count:
                row = None if k is None else rows[k]
                if self.drift is not None:
                    self.drift.observe(end, score < 0.0, row, covered=None if k is None else (covered[k], False))
                for observe in self.observers:
                    observe(end, score < 0.0, row)
                if k is not None and not count and self.drift is not None and self.drift.sustained:
                    self.unconfirmed += score < 0.0 <= drifted_scores[k]
                    score = float(drifted_scores[k])
                    confirmed = score < 0.0 and confirming[k] > 1.0
            if score >= 0.0:
                continue
            self.beyond += 1
            at = min(int(np.searchsorted(newest, end, side='left')), len(newest) - 1)  # the first record at or after
            if at not in best or score < best[at][1]:   # the window's end: its most anomalous window
                best[at] = (end, score, k, count, confirmed)
        for at, (end, score, k, count, confirmed) in sorted(best.items()):
            joint_factor = self.joint_factor if self.joint else 0
            if confirmed:   # under drift the joint check's own factor is lower
                joint_factor = min(joint_factor, drift_gate.DRIFT_JOINT_FACTOR)
            why = () if k is None else explain(rows[k], self.envelope, self.factor,
                                               step_details(*self._ring, end=end, window=self.window),
                                               joint_factor, self.local_factor if self.local else 0)
            if confirmed:
                why = tuple(why)[:MAX_WHY - 1] + (drift_gate.confirmation_why(rows[k], self.joint),)
            if count:
                why = (out_of_range_why(count),) + tuple(why)
            fires[offset + at].append(self.fire(REASON, score, why))
        keep = self._ring[0] > self._last_end - self.window - HISTORY
        self._ring = tuple(a[keep] for a in self._ring)
        self._beyond = self._beyond[self._beyond > self._last_end - self.window]

    def _ends(self, k0, k1):
        """The grid's window ends from ``k0`` to ``k1`` (in strides) whose windows hold a sample of the ring or an
        out-of-range one: a jump of the stamps (a year ahead, to 2106) makes no grid over the time between."""
        held = np.concatenate((self._ring[0], self._beyond))
        held = held[(held >= (k0 - 1) * self.stride - self.window) & (held <= (k1 + 1) * self.stride)]
        if not len(held):
            return held
        lo = np.ceil(held / self.stride - 1e-9)
        ks = lo[:, None] + np.arange(int(self.window / self.stride) + 2)[None, :]
        ks = np.unique(ks[ks * self.stride <= held[:, None] + self.window + 1e-9 * self.stride])
        return ks[(ks >= k0) & (ks <= k1)] * self.stride

    def stats(self):
        result = super(EnvelopeTrigger, self).stats()
        result.update(envelope_windows=self.evaluated, envelope_beyond=self.beyond,
                      envelope_unconfirmed=self.unconfirmed,
                      envelope_seconds=self.seconds, envelope_ring=len(self._ring[0]))
        return result

    def describe(self):
        result = super(EnvelopeTrigger, self).describe()
        result.update(factor=self.factor, window=self.window, stride=self.stride,
                      joint_factor=self.joint_factor,
                      joint=None if self.joint is None else {'typical': self.joint.typical,
                                                             'farthest': self.joint.farthest},
                      local_factor=self.local_factor, on_drift=self.on_drift,
                      local=None if self.local is None else dict(self.local.summary()),
                      learned={'topic': self.envelope.topic, 'windows': self.envelope.windows,
                               'seconds': self.envelope.seconds},
                      limits={name: float(limit) for name, limit in zip(ENVELOPE_COLUMNS, self.limits)})
        return result


def out_of_range_why(count):
    """The ``why`` entry of a window holding ``count`` samples out of any physical range."""
    return {'feature': 'out_of_range', 'value': float(count),
            'text': '%d odometry sample(s) with a speed, yaw rate or position out of any physical range (inf, NaN '
                    'or beyond %g)' % (count, CLIP)}
