"""Drift, stated: when a classifier flags far more of the robot's driving than it flagged of its training data.

A model learnt in one place, speed regime or robot flags most of the driving of another (a new hall, twice the
speed, a car that is "always anomalous"): every window is then an "anomaly" and nothing says why.
``DriftMonitor`` is fed a classifier's decisions (``observe(stamp, anomalous)``: every window the classifier
scored, anomalous or nominal, at its message time) and keeps the share flagged over a sliding ``span`` of
message time (default 2 min). It reports drift when that share is far above the model's own rate of flagged
nominal samples (``trained_rate``): at least ``factor`` times it and at least ``min_rate``, judged once the
decisions cover ``settle`` seconds (default: half the span); or when the flags of the span fall into
``episodes`` (default 4) or more separate episodes (flagged decisions more than EPISODE_GAP apart): a model
calibrated for about one false window an hour that opens four in two minutes no longer fits the driving, even
when each episode is short (a new place flags a second here and there; one long true anomaly is one episode).
``status()`` gives ``(level, message)``: the level of ``diagnostic_msgs/DiagnosticStatus`` (``OK`` 0, ``WARN``
1) and one line, e.g.

    drift: classifier flagged 62% of the last 2 min (trained: 0.2%): this robot drives unlike its training
    data; remedies: ...

so a node can publish it on ``/diagnostics`` as it is. ``report()`` says what happened over a whole replay
(``cclog replay``'s summary): when drift was first reported and the highest share flagged; ``as_dict()`` the
same as JSON values.

``trained_rate(model)``: the share of held-out nominal vectors the model flags at its threshold
(``info.held_out_flagged`` / ``info.vectors_held_out`` of ``learning.train``), never less than the
calibration's target (``learning.DEFAULT_QUANTILE``, 0.2 %: the threshold sits below that quantile of the
held-out scores), which is also used when the model file does not say. That rate was measured at training's
threshold (``info.threshold``): a model ``cclog tune`` set lower flags less, but the driving it sees has not
changed, so its decisions are judged at training's threshold (``judged_margin(model)``, the monitor's ``margin``,
``observe(..., margin=)``); a tuned model reports a new place as soon as the model it was tuned from would.

Coverage: a model file trained by this version records the range its nominal training vectors cover
(``learning.coverage``: the largest speed |v| and yaw rate |w| of a window and the share of windows stopped for
the odometry sets, every feature's range for the others). Given it (``coverage=model.coverage`` with the model's
``config``), the monitor also takes each decision's vector (``observe(stamp, anomalous, vector)``) and says
where the driving leaves that range, beyond a tolerance of COVERAGE_TOLERANCE of the trained spread: ``status()``
warns while at least ``min_rate`` of the last span lies beyond (or is stopped ``min_rate`` more often than in
training), and ``report()`` adds, for a whole run, e.g. ``coverage: training covers |v| <= 0.60 m/s; this run
reaches 1.30 m/s (35% of decisions beyond)``. A model without it (older files) is judged on the flag rate alone.

Remedies (``REMEDIES``): online adaptation (``learn_online: true``, opt-in: ``online_learning``), a periodic
trigger collecting nominal samples to retrain from (``kind: periodic``), retraining on this robot's nominal
driving (``cclog learn``).

The physics envelope (``learning.envelope``, the default detector) is watched the same way: ``monitor_envelopes``
gives each trigger of kind envelope a monitor fed every window it evaluates (one every 0.25 s), at the trained rate
TRAINED_RATE_FLOOR (the envelope flags no training window by construction), with ``EnvelopeCoverage``: per
feature, the share of windows beyond the training maximum (ratio > 1 + COVERAGE_TOLERANCE, as a classifier's
range: past it by that share of the trained spread from 0; before the trigger's 2x), e.g.
``coverage: training reaches jerk 29.6 m/s^3; this run exceeds it in 12% of windows (up to 3.1x)``; its remedies
(ENVELOPE_REMEDIES) re-learn the envelope. Pure: no rospy.
"""
import collections

import numpy as np

from cc_log.features.envelope import ENVELOPE_COLUMNS, ENVELOPE_UNITS
from cc_log.learning import learning
from cc_log.learning.envelope import LABELS
from cc_log.learning.learning import DEFAULT_QUANTILE

OK, WARN = 0, 1  # diagnostic_msgs/DiagnosticStatus levels
DEFAULT_SPAN = 120.0      # seconds of message time the live share is computed over
DEFAULT_FACTOR = 10.0     # drift: the live share is at least this many times the trained rate ...
DEFAULT_MIN_RATE = 0.2    # ... and at least this share (a long true anomaly fills a few % of 2 min, not 20 %)
DEFAULT_EPISODES = 4      # ... or the flags of the span fall into this many separate episodes
EPISODE_GAP = 7.0        # seconds without a flagged decision that separate two episodes
REMEDIES = ('learn_online: true on the classifier (online adaptation, opt-in; it learns this place\'s unusual '
            'driving too: keep rules for collisions and aborts), a periodic trigger (kind: periodic, every: 10min) '
            'to collect nominal samples to retrain from, or retrain (cclog learn) on nominal driving of this robot '
            'and place')
ENVELOPE_REMEDIES = ('re-learn the envelope (cclog learn-envelope) on nominal driving of this robot and place, '
                     'a periodic trigger (kind: periodic, every: 10min) to collect that driving, or a larger factor '
                     'on the envelope trigger while it drives this way')
TRAINED_RATE_FLOOR = DEFAULT_QUANTILE  # the lowest trained rate a monitor takes (the calibration's target)
COVERAGE_TOLERANCE = 0.1  # a value is beyond the training range when past it by this share of the trained spread
SHOWN_FEATURES = 3        # features named in a coverage line (per-feature coverage)


def trained_rate(model):
    """The share of nominal samples ``model`` flags (see the module docstring), a float in (0, 1]."""
    info = getattr(model, 'info', None) or {}
    flagged, held_out = info.get('held_out_flagged'), info.get('vectors_held_out')
    measured = 0.0
    if isinstance(flagged, (int, float)) and isinstance(held_out, (int, float)) and held_out > 0:
        measured = min(1.0, max(0.0, float(flagged) / float(held_out)))
    return max(measured, TRAINED_RATE_FLOOR)  # the held-out quantile the threshold is set below


def judged_margin(model):
    """How far above ``model``'s threshold a score still counts as flagged for drift: the threshold
    ``learning.train`` set (``info.threshold``, where the trained rate was measured) minus the model's own (0 for
    a model as trained or a file without it; a model tuned lower, more). Model info holds finite JSON values."""
    trained = (getattr(model, 'info', None) or {}).get('threshold')
    if isinstance(trained, bool) or not isinstance(trained, (int, float)):
        return 0.0
    return max(0.0, float(trained) - float(model.threshold))


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
    of message time; factor, min_rate: when the share is drift; name: the classifier's, in messages;
    margin: a decision observed with its margin (score minus the classifier's threshold) is flagged when the
    margin is below this (``judged_margin``; 0: as the classifier decided); coverage: a model's coverage (with its
    ``config``) or an ``EnvelopeCoverage``; remedies: what the messages advise in drift; action: what the
    detector does while drift lasts (``sustained``), said after them (None: nothing changes).
    ValueError('<parameter>: ...') for a bad parameter."""

    def __init__(self, trained_rate, span=DEFAULT_SPAN, factor=DEFAULT_FACTOR, min_rate=DEFAULT_MIN_RATE,
                 settle=None, name='classifier', coverage=None, config=None, episodes=DEFAULT_EPISODES,
                 margin=0.0, remedies=REMEDIES, action=None):
        for key, value, low, high in (('trained_rate', trained_rate, 0.0, 1.0), ('span', span, 0.0, None),
                                      ('factor', factor, 0.0, None), ('min_rate', min_rate, 0.0, 1.0)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > low \
                    or (high is not None and value > high):
                raise ValueError('%s: %s must be a number > %g%s' % (
                    key, repr(value)[:40], low, '' if high is None else ' and <= %g' % high))
        self.trained_rate = float(trained_rate)
        self.margin = float(margin)
        self.span = float(span)
        self.settle = self.span / 2.0 if settle is None else float(settle)
        if not 0.0 <= self.settle <= self.span:
            raise ValueError('settle: %s must be between 0 and span (%g s)' % (repr(settle)[:40], self.span))
        self.limit = min(1.0, max(float(factor) * self.trained_rate, float(min_rate)))
        self.min_rate = float(min_rate)
        if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 2:
            raise ValueError('episodes: %s must be a whole number >= 2' % repr(episodes)[:40])
        self.episodes = episodes
        self.name = name
        self.remedies = remedies
        self.action = action
        if isinstance(coverage, EnvelopeCoverage):
            self.coverage = coverage
        else:
            self.coverage = None if coverage is None or config is None else Coverage(coverage, config)
        self.began = None        # message time of the first decision
        self.first_drift = None  # message time drift was first reported
        self.first_stated = None  # message time drift or the coverage warning was first stated (``stated``)
        self.first_sustained = None  # message time it had first been stated for a whole span (``sustained``)
        self.peak = None         # the highest share flagged over a judged span (None: never judged)
        self.peak_episodes = 0   # the most episodes that began within a judged span
        self.reset()

    def reset(self):
        """Forget the decisions (time went back, or the logger restarted); ``first_drift`` and ``peak`` stay."""
        self._decisions = collections.deque()  # (stamp, anomalous, beyond coverage, stopped, starts an episode)
        self._flagged = 0
        self._onsets = 0         # episodes that began within the span
        self._last_flag = None   # stamp of the last flagged decision
        self._beyond = 0
        self._stopped = 0
        self._start = None  # stamp of the first decision since the reset
        self._stated_since = None  # stamp from which drift has been stated without a break (None: not stated)
        self._sustained = False  # ``sustained`` as of the last decision (it changes only with one)

    def observe(self, stamp, anomalous, vector=None, margin=None, covered=None):
        """One decision of the classifier at message time ``stamp`` (float s); ``anomalous``: bool; ``vector``: the
        feature vector decided on (for the coverage; None: not known); ``margin``: its score minus the classifier's
        threshold (below the monitor's ``margin``: flagged; None: ``anomalous`` decides); ``covered``: what the
        coverage's ``observe`` of ``vector`` said when it saw it already (``EnvelopeCoverage.observe_rows``)."""
        decisions = self._decisions
        if decisions and stamp < decisions[-1][0] - 1.0:
            self.reset()  # time went back (another run): start again
            decisions = self._decisions
        if self._start is None:
            self._start = stamp
            self.began = stamp if self.began is None else self.began
        anomalous = bool(anomalous if margin is None else margin < self.margin)
        beyond = stopped = False
        if covered is not None:
            beyond, stopped = covered
        elif self.coverage is not None and vector is not None:
            beyond, stopped = self.coverage.observe(vector)
        onset = anomalous and (self._last_flag is None or stamp - self._last_flag > EPISODE_GAP)
        if anomalous:
            self._last_flag = stamp
        decisions.append((stamp, anomalous, beyond, stopped, onset))
        self._flagged += anomalous
        self._beyond += beyond
        self._stopped += stopped
        self._onsets += onset
        while decisions and decisions[0][0] < stamp - self.span:
            _, old_flag, old_beyond, old_stopped, old_onset = decisions.popleft()
            self._flagged -= old_flag
            self._beyond -= old_beyond
            self._stopped -= old_stopped
            self._onsets -= old_onset
        if self.judged:
            share = self.share
            self.peak = share if self.peak is None else max(self.peak, share)
            self.peak_episodes = max(self.peak_episodes, self._onsets)
            if self.drifting and self.first_drift is None:
                self.first_drift = stamp
        stated = self.stated
        if stated and self.first_stated is None:
            self.first_stated = stamp
        self._stated_since = (self._stated_since if self._stated_since is not None else stamp) if stated else None
        self._sustained = stated and self.stated_for >= self.span
        if self.first_sustained is None and self._sustained:
            self.first_sustained = stamp

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
    def leaving(self):
        """Whether at least ``min_rate`` of the last span lies beyond the training range (or is stopped that much
        more often than in training), once judged."""
        if self.coverage is None or not self.judged or not self._decisions:
            return False
        count = float(len(self._decisions))
        trained_stopped = self.coverage.stopped_share
        return self._beyond / count >= self.min_rate or (
            trained_stopped is not None and self._stopped / count >= trained_stopped + self.min_rate)

    @property
    def stated(self):
        """Whether ``status()`` warns now: drift, or the driving leaving the training data (``leaving``)."""
        return self.drifting or self.leaving

    @property
    def stated_for(self):
        """Seconds of message time drift has been stated (``stated``) without a break, up to the last decision."""
        if self._stated_since is None or not self._decisions:
            return 0.0
        return self._decisions[-1][0] - self._stated_since

    @property
    def sustained(self):
        """Whether drift has been stated without a break for a whole span: it lasts (a new place, not a stray
        minute or a true anomaly's few seconds)."""
        return self._sustained

    @property
    def outside(self):
        """The coverage line when the driving leaves the training range (``leaving``), else None."""
        if not self.leaving:
            return None
        count = float(len(self._decisions))
        beyond, stopped = self._beyond / count, self._stopped / count
        return self.coverage.text(beyond_share=beyond, stopped_share=stopped, of='the last %s' % duration_text(
            round(self.covered)))

    @property
    def flag_episodes(self):
        """Separate episodes of flagged decisions that began within the last span."""
        return self._onsets

    @property
    def drifting(self):
        """Whether the last span is drift now: its share flagged, or its episodes of flags."""
        return self.judged and (self.share >= self.limit or self._onsets >= self.episodes)

    def status(self):
        """``(level, message)``: WARN with the explanation and remedies while drifting, else OK."""
        trained = '(trained: %s)' % percent(self.trained_rate)
        if not self.judged:
            return OK, 'drift: not judged yet (%s of the %s of decisions needed)' % (
                duration_text(self.covered), duration_text(self.settle))
        flagged = '%s flagged %s of the last %s %s' % (self.name, percent(self.share),
                                                       duration_text(round(self.covered)), trained)
        if self._onsets >= self.episodes:
            flagged += ' in %d separate episodes' % self._onsets
        outside = self.outside
        action = '; %s' % self.action if self.action and self.sustained else ''
        if self.drifting:
            return WARN, 'drift: %s: this robot drives unlike its training data%s; remedies: %s%s' % (
                flagged, ' (%s)' % outside if outside else '', self.remedies, action)
        if outside:
            return WARN, 'drift: %s, but the driving leaves the training data: %s; remedies: %s%s' % (
                flagged, outside, self.remedies, action)
        return OK, 'drift: none: %s' % flagged

    def report(self):
        """One line on a whole run: when drift was first reported (after the first decision) and the highest share
        flagged, with the remedies; or that there was none, or too few decisions to say."""
        line = self._rate_report()
        if self.coverage is not None:
            line += '; ' + self.coverage.report()
        if self.action and self.first_sustained is not None:
            lasting = duration_text(round(self.first_sustained - self.began))
            line += '; from %s into the run, %s' % (lasting, self.action)
        return line

    def _rate_report(self):
        trained = '(trained: %s)' % percent(self.trained_rate)
        if self.first_drift is not None:
            episodes = ', in up to %d separate episodes' % self.peak_episodes if self.peak_episodes > 1 else ''
            return ('drift: from %s into the run %s flagged up to %s of %s %s%s: this robot drives unlike its '
                    'training data; remedies: %s' % (duration_text(self.first_drift - self.began), self.name,
                                                     percent(self.peak), duration_text(self.span), trained, episodes,
                                                     self.remedies))
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
            ('peak_episodes', self.peak_episodes), ('episodes', self.episodes),
            ('share', self.share if self.judged else None),
            ('first_stated', self.first_stated), ('first_sustained', self.first_sustained),
            ('action', self.action if self.first_sustained is not None else None),
            ('coverage', None if self.coverage is None else self.coverage.as_dict())])


class Coverage(object):
    """A model's ``coverage`` (``learning.coverage``) against the vectors of a run: per quantity the value
    reached and how many decisions lay beyond the trained range (COVERAGE_TOLERANCE of the trained spread past
    it; the odometry quantities only above it), and how many windows were stopped."""

    def __init__(self, coverage, config):
        known = dict((name, (unit, function, upper)) for name, unit, function, upper
                     in learning.coverage_quantities(config))
        self.entries = [entry for entry in coverage.get('quantities', ()) if entry.get('name') in known]
        self.functions = [known[entry['name']][1] for entry in self.entries]
        self.upper = np.array([known[entry['name']][2] for entry in self.entries], dtype=bool)
        names = learning.vector_names(config)
        self.columns = None  # per-feature coverage: the vector's own columns, read at once
        if self.entries and not self.upper.any():
            self.columns = np.array([names.index(entry['name']) for entry in self.entries])
        low = np.array([entry['min'] for entry in self.entries], dtype=float)
        high = np.array([entry['max'] for entry in self.entries], dtype=float)
        tolerance = COVERAGE_TOLERANCE * np.maximum(high - low, np.maximum(0.1 * np.abs(high), 1e-9))
        self.low = np.where(self.upper, -np.inf, low - tolerance)
        self.high = high + tolerance
        self.stopped_share = coverage.get('stopped_share')
        self.stopped_speed = coverage.get('stopped_speed', learning.STOPPED_SPEED)
        self.decisions = 0
        self.stopped = 0
        self.beyond = np.zeros(len(self.entries), dtype=int)
        self.beyond_any = 0
        self.reached_high = np.full(len(self.entries), -np.inf)
        self.reached_low = np.full(len(self.entries), np.inf)

    def observe(self, vector):
        """``(beyond the range, stopped)`` of one decision's vector, counted for the run."""
        X = np.asarray(vector, dtype=float).reshape(1, -1)
        if self.columns is not None:
            values = X[0, self.columns]
        else:
            values = np.array([function(X)[0] for function in self.functions]) if self.functions else np.zeros(0)
        self.reached_high = np.maximum(self.reached_high, values)
        self.reached_low = np.minimum(self.reached_low, values)
        outside = (values > self.high) | (values < self.low)
        self.beyond += outside
        self.decisions += 1
        beyond = bool(outside.any())
        self.beyond_any += beyond
        stopped = bool(self.stopped_share is not None and len(values) and values[0] < self.stopped_speed)
        self.stopped += stopped
        return beyond, stopped

    def _range(self, index):
        entry, unit = self.entries[index], self.entries[index].get('unit', '')
        unit = ' ' + unit if unit else ''
        if self.upper[index]:
            return '%s <= %.3g%s' % (entry['name'], entry['max'], unit), '%.3g%s' % (self.reached_high[index], unit)
        reached = self.reached_high[index] if self.reached_high[index] > self.high[index] else self.reached_low[index]
        return ('%s in [%.3g, %.3g]%s' % (entry['name'], entry['min'], entry['max'], unit),
                '%.3g%s' % (reached, unit))

    def text(self, beyond_share=None, stopped_share=None, of='decisions'):
        """One line on where the run leaves the range: the quantities beyond it (the most often beyond first,
        at most SHOWN_FEATURES of them) and the share stopped when it exceeds training's; '' when neither."""
        parts = []
        order = [i for i in np.argsort(-self.beyond, kind='stable') if self.beyond[i]]
        if order:
            ranges = [self._range(i) for i in order[:SHOWN_FEATURES]]
            parts.append('training covers %s; this run reaches %s' % (
                ', '.join(covered for covered, _ in ranges), ', '.join(reached for _, reached in ranges)))
            if len(self.entries) > 2:
                parts[-1] += ' (%d of %d features beyond)' % (len(order), len(self.entries))
            if beyond_share is not None:
                parts[-1] += ' (%s of %s beyond)' % (percent(beyond_share), of)
        if self.stopped_share is not None and stopped_share is not None and self.decisions \
                and stopped_share > self.stopped_share + 1e-12:
            parts.append('training was stopped %s of the time, this run %s' % (
                percent(self.stopped_share), percent(stopped_share)))
        return '; '.join(parts)

    def report(self):
        """``coverage: ...`` on the whole run: what ``text`` says with the run's shares, or that it stayed
        within the training range (or that no vector was seen)."""
        if not self.decisions:
            return 'coverage: no decision to compare with the training range'
        run_stopped = self.stopped / float(self.decisions)
        stopped = run_stopped if self.stopped_share is not None and \
            run_stopped >= self.stopped_share + DEFAULT_MIN_RATE / 2 else None
        text = self.text(self.beyond_any / float(self.decisions), stopped)
        if text:
            return 'coverage: ' + text
        return 'coverage: within the training range (%s)' % ', '.join(
            self._range(i)[0] for i in range(min(len(self.entries), SHOWN_FEATURES)))

    def as_dict(self):
        """The run against the range, as JSON values."""
        return collections.OrderedDict([
            ('decisions', self.decisions), ('beyond', self.beyond_any),
            ('quantities', [collections.OrderedDict([
                ('name', entry['name']), ('unit', entry.get('unit', '')), ('min', entry['min']), ('max', entry['max']),
                ('reached_min', float(self.reached_low[i]) if self.decisions else None),
                ('reached_max', float(self.reached_high[i]) if self.decisions else None),
                ('beyond', int(self.beyond[i]))]) for i, entry in enumerate(self.entries)]),
            ('stopped_share', self.stopped_share),
            ('run_stopped_share', self.stopped / float(self.decisions) if self.decisions else None)])


def monitor_classifiers(classifiers, **options):
    """A DriftMonitor for each ``triggers.ClassifierTrigger`` (its model's trained rate), fed by its decisions
    (added to the trigger's ``observers``) and told to its online learner (``drifting``); returns the monitors in
    order."""
    monitors = []
    for trigger in classifiers:
        monitor = DriftMonitor(trained_rate(trigger.model), name=trigger.name,
                               coverage=getattr(trigger.model, 'coverage', None), config=trigger.model.config,
                               margin=judged_margin(getattr(trigger, 'original', trigger.model)), **options)
        trigger.observers.append(monitor.observe)
        if getattr(trigger, 'learner', None) is not None:
            trigger.learner.drifting = (lambda m: lambda: m.drifting)(monitor)  # online learning adapts in drift
        monitors.append(monitor)
    return monitors


class EnvelopeCoverage(object):
    """An envelope's training maxima (``Envelope.trained()``: floored) against the windows of a run: per feature,
    how many windows exceed it (ratio > 1 + COVERAGE_TOLERANCE: a window of the training itself, evaluated on the
    live grid, may pass its maximum by a rounding; the trigger flags at its factor, 2x) and the largest ratio.
    The ``Coverage`` interface of a ``DriftMonitor``: ``observe(row)``, ``text``, ``report``, ``as_dict``."""

    stopped_share = None  # the envelope has no share of stopped windows to compare

    def __init__(self, envelope):
        self.maxima = envelope.trained()
        self.floored = np.array([float(envelope.maxima[name]) < limit
                                 for name, limit in zip(ENVELOPE_COLUMNS, self.maxima)])
        self.decisions = 0
        self.beyond = np.zeros(len(ENVELOPE_COLUMNS), dtype=int)
        self.beyond_any = 0
        self.peak = np.zeros(len(ENVELOPE_COLUMNS))  # the largest value / training maximum per feature

    def observe(self, row):
        """``(beyond a training maximum, False)`` of one window's row (``features.envelope`` columns)."""
        return bool(self.observe_rows(np.asarray(row, dtype=float)[None])[0]), False

    def observe_rows(self, rows):
        """``observe`` of each of ``rows`` (a 2-D array, one window a row) at once: whether each is beyond a
        training maximum (a bool array)."""
        ratio = np.asarray(rows, dtype=float) / self.maxima
        over = ratio > 1.0 + COVERAGE_TOLERANCE
        self.peak = np.fmax(self.peak, np.fmax.reduce(ratio, axis=0))
        self.beyond += over.sum(axis=0)
        self.decisions += len(ratio)
        beyond = over.any(axis=1)
        self.beyond_any += int(beyond.sum())
        return beyond

    def _reached(self, index):
        name = ENVELOPE_COLUMNS[index]
        unit = ENVELOPE_UNITS[name]
        return '%s %.3g%s%s' % (LABELS[name], self.maxima[index], '' if unit == '1' else ' ' + unit,
                                ' (its floor)' if self.floored[index] else '')

    def text(self, beyond_share=None, stopped_share=None, of='decisions'):
        """One line on the features the run takes past their training maximum (the most often first, then the
        farthest; at most SHOWN_FEATURES): ``training reaches <feature> <maximum>; this run exceeds it in <share>
        of windows (up to <ratio>x)``; with ``beyond_share`` (of windows beyond any maximum, over ``of``) the
        ratios only and that share; '' when none. ``stopped_share``: unused (``Coverage``'s interface)."""
        order = [i for i in np.lexsort((-self.peak, -self.beyond)) if self.beyond[i]][:SHOWN_FEATURES]
        if not order:
            return ''
        them = 'it' if len(order) == 1 else 'them'
        peaks = ', '.join('%.1fx' % self.peak[i] for i in order)
        line = 'training reaches %s; this run ' % ', '.join(self._reached(i) for i in order)
        if beyond_share is None:
            line += 'exceeds %s in %s of windows (up to %s)' % (
                them, ', '.join(percent(self.beyond[i] / float(self.decisions)) for i in order), peaks)
        else:
            line += 'goes up to %s (%s of %s beyond)' % (peaks, percent(beyond_share), of)
        beyond = int(np.count_nonzero(self.beyond))
        if beyond > len(order):
            line += ' (%d of %d features beyond)' % (beyond, len(ENVELOPE_COLUMNS))
        return line

    def report(self):
        """``coverage: ...`` on the whole run: ``text``, or that every window stayed within the training maxima
        (or that no window was seen)."""
        if not self.decisions:
            return 'coverage: no window to compare with the training maxima'
        return 'coverage: ' + (self.text() or 'within the training maxima (no window %s past one)' % percent(
            COVERAGE_TOLERANCE))

    def as_dict(self):
        """The run against the training maxima, as JSON values: per feature its maximum, the windows beyond it and
        the largest ratio."""
        return collections.OrderedDict([
            ('decisions', self.decisions), ('beyond', self.beyond_any),
            ('features', [collections.OrderedDict([
                ('name', name), ('unit', ENVELOPE_UNITS[name]), ('max', float(self.maxima[i])),
                ('beyond', int(self.beyond[i])), ('peak_ratio', float(self.peak[i]) if self.decisions else None)])
                for i, name in enumerate(ENVELOPE_COLUMNS)])])


def monitor_envelopes(triggers, **options):
    """A DriftMonitor for each trigger of kind envelope among ``triggers`` (``triggers.envelope.EnvelopeTrigger``),
    at TRAINED_RATE_FLOOR with its ``EnvelopeCoverage``, fed every window it evaluates (added to its
    ``observers``); a trigger's own monitor (``drift``: the one its ``on_drift`` follows, ``triggers.drift_gate``)
    where it has one, ``options`` unused then; returns the monitors in order."""
    monitors = []
    for trigger in triggers:
        if getattr(trigger, 'kind', None) != 'envelope':
            continue
        if getattr(trigger, 'drift', None) is not None:
            monitors.append(trigger.drift)
            continue
        monitor = DriftMonitor(TRAINED_RATE_FLOOR, name=trigger.name, coverage=EnvelopeCoverage(trigger.envelope),
                               remedies=ENVELOPE_REMEDIES, **options)
        trigger.observers.append(monitor.observe)
        monitors.append(monitor)
    return monitors
