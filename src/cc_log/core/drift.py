"""Drift, stated: when a classifier flags far more of the robot's driving than it flagged of its training data.

A model learnt in one place, speed regime or robot flags most of the driving of another (a new hall, twice the
speed, a car that is "always anomalous"): every window is then an "anomaly" and nothing says why.
``DriftMonitor`` is fed a classifier's decisions (``observe(stamp, anomalous)``: every window the classifier
scored, anomalous or nominal, at its message time) and keeps the share flagged over a sliding ``span`` of
message time (default 2 min). It reports drift when that share is far above the model's own rate of flagged
nominal samples (``trained_rate``): at least ``factor`` times it and at least ``min_rate``, judged once the
decisions cover ``settle`` seconds (default: half the span). ``status()`` gives ``(level, message)``: the
level of ``diagnostic_msgs/DiagnosticStatus`` (``OK`` 0, ``WARN`` 1) and one line, e.g.

    drift: classifier flagged 62% of the last 2 min (trained: 0.2%): this robot drives unlike its training
    data; remedies: ...

so a node can publish it on ``/diagnostics`` as it is. ``report()`` says what happened over a whole replay
(``cclog replay``'s summary): when drift was first reported and the highest share flagged; ``as_dict()`` the
same as JSON values.

``trained_rate(model)``: the share of held-out nominal vectors the model flags at its threshold
(``info.held_out_flagged`` / ``info.vectors_held_out`` of ``learning.train``), never less than the
calibration's target (``learning.DEFAULT_QUANTILE``, 0.2 %: the threshold sits below that quantile of the
held-out scores), which is also used when the model file does not say.

Remedies (``REMEDIES``): online adaptation (``learn_online: true``, opt-in: ``online_learning``), a periodic
trigger collecting nominal samples to retrain from (``kind: periodic``), retraining on this robot's nominal
driving (``cclog learn``). Pure: no rospy.
"""
import collections

from cc_log.core.learning import DEFAULT_QUANTILE

OK, WARN = 0, 1  # diagnostic_msgs/DiagnosticStatus levels
DEFAULT_SPAN = 120.0      # seconds of message time the live share is computed over
DEFAULT_FACTOR = 10.0     # drift: the live share is at least this many times the trained rate ...
DEFAULT_MIN_RATE = 0.2    # ... and at least this share (a long true anomaly fills a few % of 2 min, not 20 %)
REMEDIES = ('learn_online: true on the classifier (online adaptation, opt-in), a periodic trigger '
            '(kind: periodic, every: 10min) to collect nominal samples to retrain from, or retrain '
            '(cclog learn) on nominal driving of this robot and place')


def trained_rate(model):
    """The share of nominal samples ``model`` flags (see the module docstring), a float in (0, 1]."""
    info = getattr(model, 'info', None) or {}
    flagged, held_out = info.get('held_out_flagged'), info.get('vectors_held_out')
    measured = 0.0
    if isinstance(flagged, (int, float)) and isinstance(held_out, (int, float)) and held_out > 0:
        measured = min(1.0, max(0.0, float(flagged) / float(held_out)))
    return max(measured, DEFAULT_QUANTILE)  # the held-out quantile the threshold is set below


def percent(share):
    """A share as a short percentage: ``62%``, ``1.5%``, ``0.2%``."""
    value = 100.0 * share
    return '%.0f%%' % value if value >= 10 else '%.1f%%' % value


def duration_text(seconds):
    """``2 min`` (whole minutes), ``3.5 min`` (from 2 min), else ``75 s``."""
    if seconds >= 60 and seconds % 60 == 0:
        return '%d min' % (seconds // 60)
    return '%.1f min' % (seconds / 60.0) if seconds >= 120 else '%.0f s' % seconds


class DriftMonitor(object):
    """The live share of anomalous decisions of one classifier against its trained rate (module docstring).

    trained_rate: the model's share of flagged nominal samples (``trained_rate(model)``); span, settle: seconds
    of message time; factor, min_rate: when the share is drift; name: the classifier's, in messages.
    ValueError('<parameter>: ...') for a bad parameter."""

    def __init__(self, trained_rate, span=DEFAULT_SPAN, factor=DEFAULT_FACTOR, min_rate=DEFAULT_MIN_RATE,
                 settle=None, name='classifier'):
        for key, value, low, high in (('trained_rate', trained_rate, 0.0, 1.0), ('span', span, 0.0, None),
                                      ('factor', factor, 0.0, None), ('min_rate', min_rate, 0.0, 1.0)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > low \
                    or (high is not None and value > high):
                raise ValueError('%s: %s must be a number > %g%s' % (
                    key, repr(value)[:40], low, '' if high is None else ' and <= %g' % high))
        self.trained_rate = float(trained_rate)
        self.span = float(span)
        self.settle = self.span / 2.0 if settle is None else float(settle)
        if not 0.0 <= self.settle <= self.span:
            raise ValueError('settle: %s must be between 0 and span (%g s)' % (repr(settle)[:40], self.span))
        self.limit = min(1.0, max(float(factor) * self.trained_rate, float(min_rate)))
        self.name = name
        self.began = None        # message time of the first decision
        self.first_drift = None  # message time drift was first reported
        self.peak = None         # the highest share flagged over a judged span (None: never judged)
        self.reset()

    def reset(self):
        """Forget the decisions (time went back, or the logger restarted); ``first_drift`` and ``peak`` stay."""
        self._decisions = collections.deque()  # (stamp, anomalous)
        self._flagged = 0
        self._start = None  # stamp of the first decision since the reset

    def observe(self, stamp, anomalous):
        """One decision of the classifier at message time ``stamp`` (float s); ``anomalous``: bool."""
        decisions = self._decisions
        if decisions and stamp < decisions[-1][0] - 1.0:
            self.reset()  # time went back (another run): start again
            decisions = self._decisions
        if self._start is None:
            self._start = stamp
            self.began = stamp if self.began is None else self.began
        anomalous = bool(anomalous)
        decisions.append((stamp, anomalous))
        self._flagged += anomalous
        while decisions and decisions[0][0] < stamp - self.span:
            self._flagged -= decisions.popleft()[1]
        if self.judged:
            share = self.share
            self.peak = share if self.peak is None else max(self.peak, share)
            if share >= self.limit and self.first_drift is None:
                self.first_drift = stamp

    @property
    def covered(self):
        """Seconds of message time the decisions held cover (at most ``span``)."""
        if not self._decisions:
            return 0.0
        return min(self.span, self._decisions[-1][0] - self._start)

    @property
    def judged(self):
        """Whether the decisions cover ``settle`` seconds (the share means something)."""
        return bool(self._decisions) and self.covered >= self.settle

    @property
    def share(self):
        """The share of anomalous decisions over the last ``span`` (0.0 without decisions)."""
        return self._flagged / float(len(self._decisions)) if self._decisions else 0.0

    @property
    def drifting(self):
        """Whether the share over the last span is drift now."""
        return self.judged and self.share >= self.limit

    def status(self):
        """``(level, message)``: WARN with the explanation and remedies while drifting, else OK."""
        trained = '(trained: %s)' % percent(self.trained_rate)
        if not self.judged:
            return OK, 'drift: not judged yet (%s of the %s of decisions needed)' % (
                duration_text(self.covered), duration_text(self.settle))
        flagged = '%s flagged %s of the last %s %s' % (self.name, percent(self.share),
                                                       duration_text(round(self.covered)), trained)
        if self.drifting:
            return WARN, 'drift: %s: this robot drives unlike its training data; remedies: %s' % (flagged, REMEDIES)
        return OK, 'drift: none: %s' % flagged

    def report(self):
        """One line on a whole run: when drift was first reported (after the first decision) and the highest share
        flagged, with the remedies; or that there was none, or too few decisions to say."""
        trained = '(trained: %s)' % percent(self.trained_rate)
        if self.first_drift is not None:
            return ('drift: from %s into the run %s flagged up to %s of %s %s: this robot drives unlike its '
                    'training data; remedies: %s' % (duration_text(self.first_drift - self.began), self.name,
                                                     percent(self.peak), duration_text(self.span), trained, REMEDIES))
        if self.peak is None:
            return 'drift: not judged: %s of %s\'s decisions, %s needed%s' % (
                duration_text(self.covered), self.name, duration_text(self.settle),
                ' (it flagged %s of them)' % percent(self.share) if self._decisions else '')
        return 'drift: none: %s flagged at most %s of any %s %s' % (
            self.name, percent(self.peak), duration_text(self.span), trained)

    def as_dict(self):
        """What ``report`` says, as JSON values."""
        return collections.OrderedDict([
            ('name', self.name), ('trained_rate', self.trained_rate), ('limit', self.limit), ('span', self.span),
            ('drift', self.first_drift is not None), ('first_drift', self.first_drift), ('peak', self.peak),
            ('share', self.share if self.judged else None)])


def monitor_classifiers(classifiers, **options):
    """A DriftMonitor for each ``triggers.ClassifierTrigger`` (its model's trained rate), fed by its decisions
    (added to the trigger's ``observers``); returns the monitors in order."""
    monitors = []
    for trigger in classifiers:
        monitor = DriftMonitor(trained_rate(trigger.model), name=trigger.name, **options)
        trigger.observers.append(monitor.observe)
        monitors.append(monitor)
    return monitors
