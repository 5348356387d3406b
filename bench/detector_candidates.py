"""The combinations measured to choose cc_log's default (``bench/detectors.py --candidates``) and, per candidate,
where a standard detector dominates it.

A candidate ``a|b|c`` flags what any of its parts flags (``Either``), each part at its base level at level 2: the
default's rule is ``env2|maha4`` (the envelope at 2x or the robust distance at level 4). ``--candidates`` prints
one table: per candidate its pooled caught and false windows per hour, the robots where a standard detector at the
table's level dominates it (catches as many with fewer false windows, or more with as few: the rule of the
``dominating cclog`` column), and the robots where it catches fewer than the envelope at 2x or opens more false
windows than it.
"""
import numpy as np


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


def part_score(detector, X):
    """``detector.score(X)``, remembered for the last ``X`` (the parts are shared by many candidates)."""
    memo = getattr(detector, '_memo', None)
    if memo is None or memo[0] is not X:
        memo = detector._memo = (X, detector.score(X))
    return memo[1]


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
    met = [row[0] for row in rows if row[4] == 'none' and row[5] == '-' and row[6] == '-' and row[3] <= 5.0]
    print('candidates meeting all three (dominated nowhere, >= envelope 2x on every robot, <= 5 false/h pooled): %s\n'
          % (', '.join(met) or 'none'))
