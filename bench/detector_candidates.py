"""The combinations measured to choose cc_log's default (``bench/detectors.py --candidates``) and, per candidate,
where a standard detector dominates it.

A candidate ``a|b|c`` flags what any of its parts flags (``Either``), each part at its base level at level 2: the
default's rule is ``env2|maha4`` (the envelope at 2x or the robust distance at level 4). ``--candidates`` prints
one table: per candidate its pooled caught and false windows per hour, the robots where a standard detector at the
table's level dominates it (catches as many with fewer false windows, or more with as few: the rule of the
``dominating cclog`` column), and the robots where it catches fewer than the envelope at 2x or opens more false
windows than it.

A drift-gated candidate ``env2|maha4|lof6/<when>:<rule>`` (``DriftGated``) is the default's rule until its drift
monitor (``learning.drift.DriftMonitor``, fed the windows in order as the envelope trigger feeds it) states drift
(``when``: ``drift``, as soon as it is stated; ``drifting``, by the flags alone; ``sustained``, stated for a whole
span), ``<rule>`` after; ``--candidates`` prints per robot the share of windows under stated and sustained drift and
each one's (caught; false windows). ``sustained:env2&maha1|maha2`` is the envelope trigger's ``on_drift: confirm``.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from standard_detectors import STRIDE, TOPIC, WINDOW  # noqa: E402

from cc_log.learning import drift, envelope as learned_envelope  # noqa: E402


class Either(object):
    """Flags a window when any of its parts would at its own level: parts ``[(detector, base level)]``, each at
    ``base x level / 2``, so level 2 is every part at its base level (the default's shape: the envelope at 2x or
    the robust distance at level 4). A part reaches level ``(zero - score) / (zero - extreme)``; the score is
    minus the largest of ``2 x that / base``. A part's scores of the same windows are computed once."""

    zero, extreme = 0.0, -1.0

    def __init__(self, parts):
        self.parts = parts

    def threshold(self, level):
        """Flag a window whose score is below this."""
        return self.zero - level * (self.zero - self.extreme)

    def fit(self, X):
        for detector, _ in self.parts:
            if not hasattr(detector, 'zero'):
                detector.fit(X)
        return self

    def score(self, X):
        if not len(X):
            return np.zeros(0)
        reached = [2.0 * (d.zero - part_score(d, X)) / (d.zero - d.extreme) / base for d, base in self.parts]
        return -np.max(reached, axis=0)


class Both(Either):
    """Flags a window when every one of its parts would at its own level (``base x level / 2``, as ``Either``):
    the score is minus the smallest level reached."""

    def score(self, X):
        if not len(X):
            return np.zeros(0)
        reached = [2.0 * (d.zero - part_score(d, X)) / (d.zero - d.extreme) / base for d, base in self.parts]
        return -np.min(reached, axis=0)


def part_score(detector, X, ends=None):
    """``detector.score(X)`` (``score_at(X, ends)`` for a detector that follows the run in time: ``ends``, the
    windows' ends, in order), remembered for the last ``X`` (the parts are shared by many candidates)."""
    memo = getattr(detector, '_memo', None)
    if memo is None or memo[0] is not X:
        score = detector.score_at(X, ends) if hasattr(detector, 'score_at') else detector.score(X)
        memo = detector._memo = (X, score)
    return memo[1]


class DriftState(object):
    """Per window of a run (in order), what a fresh envelope drift monitor (``drift.monitor_envelopes``' own: a
    ``drift.DriftMonitor`` at ``drift.TRAINED_RATE_FLOOR`` with the envelope's coverage) says once fed it and the
    windows before, each with whether ``usual`` (a candidate) flags it at level 2, as the envelope trigger feeds
    it: ``stated`` (drift or the coverage warning), ``drifting`` (drift by the flags alone), and per feature the
    share of the last span's windows beyond its training maximum (the coverage's rule). Fitted once, shared by the
    drift-gated candidates; remembered for the last run. ``log``: per run, (windows, windows under stated drift)."""

    zero, extreme = 0.0, -1.0

    def __init__(self, usual):
        self.usual = usual
        self.log = []

    def fit(self, X):
        self.learned = learned_envelope.learn([X], TOPIC, WINDOW, STRIDE, len(X) * STRIDE, joint=False, local=False)
        return self

    def of(self, X, ends):
        """({'stated', 'drifting', 'sustained': per window}, per-feature share beyond) of the windows ``X`` ending
        at ``ends``; sustained: stated without a break for a whole span."""
        memo = getattr(self, '_memo', None)
        if memo is not None and memo[0] is X:
            return memo[1]
        flags = part_score(self.usual, X) < self.usual.threshold(2.0)
        monitor = drift.DriftMonitor(drift.TRAINED_RATE_FLOOR, coverage=drift.EnvelopeCoverage(self.learned))
        stated, drifting = np.zeros(len(X), dtype=bool), np.zeros(len(X), dtype=bool)
        sustained = np.zeros(len(X), dtype=bool)
        for k, (end, flag, row) in enumerate(zip(ends, flags, X)):
            monitor.observe(float(end), bool(flag), row)
            stated[k], drifting[k] = monitor.stated, monitor.drifting
            sustained[k] = monitor.sustained
        over = np.asarray(X, dtype=float) / self.learned.trained() > 1.0 + drift.COVERAGE_TOLERANCE
        counts = np.vstack([np.zeros((1, over.shape[1])), np.cumsum(over, axis=0)])
        first = np.searchsorted(ends, np.asarray(ends) - monitor.span, side='left')
        last = np.arange(1, len(X) + 1)
        share = (counts[last] - counts[first]) / np.maximum(last - first, 1)[:, None]
        self.log.append((len(X), int(stated.sum()), int(sustained.sum())))
        self._memo = (X, ({'stated': stated, 'drifting': drifting, 'sustained': sustained}, share))
        return self._memo[1]


class DriftGated(Either):
    """A candidate that changes once its drift monitor (``state``, a ``DriftState``) states that the driving left
    the training data: a window scores as ``usual`` while no drift is stated, as ``drifted`` while it is
    (``when``: 'stated', drift or the coverage warning; 'drifting', drift by the flags alone). With
    ``feature_share``, under drift a feature beyond its limit that the last span's windows passed its training
    maximum less often than that share still fires alone (``envelope``, the bench's, at 2x): only the features the
    drift concerns wait for ``drifted``'s confirmation. Causal: a window's score depends on it and the windows
    before."""

    def __init__(self, state, drifted, envelope=None, when='stated', feature_share=None):
        super(DriftGated, self).__init__([(state.usual, 2.0), (drifted, 2.0)])
        self.state, self.usual, self.drifted = state, state.usual, drifted
        self.envelope, self.when, self.feature_share = envelope, when, feature_share

    def fit(self, X):
        super(DriftGated, self).fit(X)
        if not hasattr(self.state, 'learned'):
            self.state.fit(X)
        return self

    def score(self, X):
        return self.score_at(X, np.arange(len(X)) * STRIDE)

    def score_at(self, X, ends):
        usual, drifted = part_score(self.usual, X), part_score(self.drifted, X)
        when, share = self.state.of(X, ends)
        if self.feature_share is not None and len(X):
            ratios = self.envelope.ratios(X)
            calm = np.max(np.where(share < self.feature_share, ratios, 0.0), axis=1)
            drifted = np.minimum(drifted, -calm)
        return np.where(when[self.when], drifted, usual)


class SecondLargest(object):
    """The envelope's second largest ratio: two features beyond their limits at once (``envelope``: the bench's
    ``Envelope``, fitted)."""

    zero, extreme = 0.0, -1.0

    def __init__(self, envelope):
        self.envelope = envelope

    def fit(self, X):
        return self

    def score(self, X):
        return -np.sort(self.envelope.ratios(X), axis=1)[:, -2] if len(X) else np.zeros(0)


def add_candidates(found, lof):
    """Add the candidates to ``found`` (the standard detectors by name, unfitted); ``lof(k)``: a new LOF detector
    with ``k`` neighbours (standardised as the table's ``lof``, which has 20)."""
    env, maha, second = found['envelope'], found['mahalanobis'], SecondLargest(found['envelope'])
    found['env2|maha4'] = Either([(env, 2.0), (maha, 4.0)])       # the default (cclog learn-envelope)
    found['env2|maha3'] = Either([(env, 2.0), (maha, 3.0)])
    found['env2|maha3.5'] = Either([(env, 2.0), (maha, 3.5)])
    found['env1.75|maha4'] = Either([(env, 1.75), (maha, 4.0)])
    found['env2|2nd1.5'] = Either([(env, 2.0), (second, 1.5)])
    for name, base in (('lof', found['lof']), ('knnmax', found['knn-max']), ('knnmean', found['knn-mean'])):
        for level in ((3.0, 4.0, 5.0, 6.0) if name == 'lof' else (3.0, 4.0, 5.0)):
            found['env2|maha4|%s%g' % (name, level)] = Either([(env, 2.0), (maha, 4.0), (base, level)])
    for k in (10, 35):
        other = lof(k)
        for level in (3.0, 4.0, 5.0):
            found['env2|maha4|lof%d:%g' % (k, level)] = Either([(env, 2.0), (maha, 4.0), (other, level)])
    found['env2|maha3.5|lof4'] = Either([(env, 2.0), (maha, 3.5), (found['lof'], 4.0)])
    # what the events a standard detector catches and the default misses cost: a part at level 2
    found['env2|maha2'] = Either([(env, 2.0), (maha, 2.0)])
    found['env2|maha4|knnmax2'] = Either([(env, 2.0), (maha, 4.0), (found['knn-max'], 2.0)])
    found['env2|maha4|lof2'] = Either([(env, 2.0), (maha, 4.0), (found['lof'], 2.0)])
    # the envelope above the nominal windows it opens on the Husky (2.19x) and ICE-lab (2.56x)
    for factor in (2.25, 2.6):
        found['env%g|maha4|lof6' % factor] = Either([(env, factor), (maha, 4.0), (found['lof'], 6.0)])
    # the envelope confirmed by a second opinion (the nominal windows it opens on tuc, the Husky and ICE-lab)
    for name, other, base in (('maha1', maha, 1.0), ('maha1.5', maha, 1.5), ('knnmax1', found['knn-max'], 1.0)):
        confirmed = Both([(env, 2.0), (other, base)])
        found['env2&%s|maha4|lof6' % name] = Either([(confirmed, 2.0), (maha, 4.0), (found['lof'], 6.0)])
    found['env2|maha3.5|lof6|knnmax3'] = Either([(env, 2.0), (maha, 3.5), (found['lof'], 6.0),
                                                 (found['knn-max'], 3.0)])
    # issue 45: the default (env2|maha4|lof6) while no drift is stated, another rule while it is (drift: stated;
    # sustained: stated for a whole span; drifting: by the flags alone)
    default, lof = found['env2|maha4|lof6'], found['lof']
    state = DriftState(default)
    confirmed = {level: Either([(Both([(env, 2.0), (maha, level)]), 2.0), (maha, 4.0), (lof, 6.0)])
                 for level in (0.5, 1.0, 2.0)}
    found['env2|maha4|lof6/drift:env2&maha1'] = DriftGated(state, confirmed[1.0])
    found['env2|maha4|lof6/drifting:env2&maha1'] = DriftGated(state, confirmed[1.0], when='drifting')
    found['env2|maha4|lof6/drift:env2&maha1,calm0.05'] = DriftGated(state, confirmed[1.0], env, feature_share=0.05)
    for level, drifted in confirmed.items():
        found['env2|maha4|lof6/sustained:env2&maha%g' % level] = DriftGated(state, drifted, when='sustained')
    for level in (0.5, 1.0):
        drifted = Either([(Both([(env, 2.0), (maha, level)]), 2.0), (maha, 2.0), (lof, 6.0)])
        found['env2|maha4|lof6/sustained:env2&maha%g|maha2' % level] = DriftGated(state, drifted, when='sustained')
    drifted = Either([(Both([(env, 2.0), (maha, 0.5)]), 2.0), (env, 6.0), (maha, 4.0), (lof, 6.0)])
    found['env2|maha4|lof6/sustained:env2&maha0.5|env6'] = DriftGated(state, drifted, when='sustained')
    found['env2|maha4|lof6/sustained:env3|maha2'] = DriftGated(state, Either([(env, 3.0), (maha, 2.0), (lof, 6.0)]),
                                                               when='sustained')
    return found


def dominates(a, b):
    """Whether (caught, false windows) ``a`` dominates ``b``: as many caught with fewer false windows, or more with
    as few."""
    return a[0] >= b[0] and a[1] <= b[1] and (a[0] > b[0] or a[1] < b[1])


def standing(cells, name, standard):
    """Of one robot's ``cells`` ({detector: (caught, false windows)}): (the standard detectors dominating ``name``,
    whether it catches fewer than the envelope, whether it opens more false windows than the envelope)."""
    own, env = cells[name], cells['envelope']
    return ([other for other in standard if other != name and dominates(cells[other], own)],
            own[0] < env[0], own[1] > env[1])


def drift_shares(detectors, scored):
    """{'nominal' | 'injected': (windows, under stated drift, under sustained drift)} of the first
    ``DriftGated``'s monitor among ``detectors`` (they share one), its runs labelled in order by ``scored``; {}
    without one."""
    gated = [d for d in detectors.values() if isinstance(d, DriftGated)]
    if not gated:
        return {}
    out = {}
    for phase, counts in zip(scored, gated[0].state.log):
        out[phase] = tuple(a + b for a, b in zip(out.get(phase, (0, 0, 0)), counts))
    return out


def report_drift(results, level, cell, table):
    """Per robot, the share of windows under stated drift (nominal replays, injected ones) and each drift-gated
    candidate's (caught; false windows) beside the default's rule it starts from."""
    names = [name for name in results[0]['stats'] if '/' in name]
    if not names:
        return
    rows = []
    for result in results:
        shares = result.get('drift', {})
        row = [result['robot']]
        for phase in ('nominal', 'injected'):
            counts = shares.get(phase, (0, 0, 0))
            row.append('%.1f%%, %.1f%%' % (100.0 * counts[1] / counts[0], 100.0 * counts[2] / counts[0])
                       if counts[0] else '-')
        row.append('%d; %d' % cell(result, names[0].split('/')[0], level))
        row += ['%d; %d' % cell(result, name, level) for name in names]
        rows.append(row)
    table(['robot', 'drift stated, sustained: nominal', 'injected', names[0].split('/')[0]] +
          [name.split('/')[1] for name in names], rows,
          'drift-gated candidates (level %g): per robot, windows under stated drift and (caught; false windows)'
          % level)


def report(results, pooled, level, cell, standard, table):
    """The candidates' table: ``cell(result, name, level)`` -> (caught, false windows); ``standard``: the standard
    detectors' names; ``table(headers, rows, title)`` prints it."""
    rows = []
    names = [name for name in pooled['stats'] if '|' in name] + (['cclog'] if 'cclog' in pooled['stats'] else [])
    for name in names:
        dominated, fewer, more = [], [], []
        for result in results:
            cells = {other: cell(result, other, level) for other in list(standard) + [name]}
            by, less, extra = standing(cells, name, standard)
            robot = result['robot']
            if by:
                dominated.append('%s (%s)' % (robot, ', '.join(by)))
            fewer += [robot] if less else []
            more += [robot] if extra else []
        caught, false = cell(pooled, name, level)
        rows.append([name, '%d/%d' % (caught, len(pooled['events'])), false,
                     false / pooled['hours'] if pooled['hours'] else float('nan'),
                     '; '.join(dominated) or 'none', ', '.join(fewer) or '-', ', '.join(more) or '-'])
    table(['candidate', 'caught', 'false windows', 'false/h', 'dominated at level %g on' % level,
           'fewer caught than env 2x on', 'more false than env 2x on'], rows,
          'candidates (level %g; cclog: its own threshold): pooled, and per robot' % level)
    report_drift(results, level, cell, table)
    met = [row[0] for row in rows if row[4] == 'none' and row[5] == '-' and row[6] == '-' and row[3] <= 5.0]
    print('candidates meeting all three (dominated nowhere, >= envelope 2x on every robot, <= 5 false/h pooled): %s\n'
          % (', '.join(met) or 'none'))
