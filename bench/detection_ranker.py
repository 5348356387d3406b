#!/usr/bin/env python3
"""A second stage beside the one-class model: a two-class ranker of simulator anomalies against nominal driving,
trained on the robot's own training part with anomalies injected into it, gating the one-class model's fires.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/detection_ranker.py                          # all runs, --train-on robot, seeds 0 1 2
    python3 bench/detection_ranker.py --runs husky_outdoor_2015 --seeds 0 --explain   # what the ranker does there

The question (issue 13): the one-class model calls driving its training never held anomalous (Husky's stops),
and no threshold separates such driving from anomaly onsets. Does a ranker that has seen anomalies, injected
into the robot's own nominal training driving, tell them apart? For each run: ``detection_runs.prepare`` (the
same model, training pieces and injection as ``detection_runs.py``); then every simulator anomaly type is
injected into each training piece with seeds RANKER_SEEDS (other seeds than the evaluation's) at the BWIBot's
and at the robot's own scale; the vectors in [onset, end + feature window] that the one-class model flags are
the positives, every vector of the nominal training pieces the negatives. A logistic regression on the
standardized vectors (balanced classes) is the ranker. The gated model fires only where the one-class model
flags a vector and the ranker gives it probability >= ``--gate`` (default 0.5). Both are then judged by
``detection_runs.evaluate_run`` on the replayed part: false windows without injection, anomalies caught (and
later than 0.5 s) with injection at the seeds given.
"""
import argparse
import copy
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402
import detection_runs as runs  # noqa: E402

from cc_log import sim  # noqa: E402

RANKER_SEEDS = tuple(range(100, 106))


class GatedModel(object):
    """A one-class model whose anomalous scores count only where the ranker agrees: elsewhere the score is
    raised to the threshold (nominal). Quacks like ``AnomalyModel`` for ``ClassifierTrigger``."""

    def __init__(self, model, ranker, gate):
        self.model, self.ranker, self.gate = model, ranker, gate
        self.config, self.info, self.names = model.config, model.info, model.names
        self.dimension = model.dimension

    @property
    def threshold(self):
        return self.model.threshold

    @threshold.setter
    def threshold(self, value):
        self.model = copy.copy(self.model)
        self.model.threshold = value

    def scores(self, vectors):
        X = np.asarray(vectors, dtype=float)
        scores = np.array(self.model.scores(X), dtype=float)
        low = scores < self.model.threshold
        if np.any(low):
            agree = self.ranker.predict_proba(X[low])[:, 1] >= self.gate
            scores[np.flatnonzero(low)[~agree]] = self.model.threshold
        return scores

    def score_each(self, vectors):
        return [float(s) for s in self.scores(np.asarray(vectors, dtype=float))]

    def is_anomalous(self, vector):
        score = float(self.scores(np.asarray(vector, dtype=float)[None, :])[0])
        return score < self.model.threshold, score


def ranker_of(model, pieces, topic, config, inject, robot_scale):
    """The logistic ranker of one run: positives from anomalies injected into ``pieces`` (flagged by
    ``model``), negatives every nominal vector of ``pieces``; and the counts."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler
    reach = config.span.seconds
    negatives, positives = [], []
    for piece in pieces:
        negatives.append(runs.vectors_of(piece, config)[1])
        for scale in (None, robot_scale):
            how = dict(topic=topic, warmup=3.0, gap=2.0)
            if scale is not None:
                how.update(scale=scale, limits=scale)
            for kind in sim.ANOMALY_TYPES:
                for seed in RANKER_SEEDS:
                    try:
                        injected, truth = sim.inject_anomalies(piece, [kind], seed=seed, **how)
                    except ValueError:
                        continue
                    stamps, V = runs.vectors_of(injected, config)
                    entry = truth[0]
                    inside = (stamps >= entry['start']) & (stamps <= entry['end'] + reach)
                    if np.any(inside):
                        flagged = V[inside][np.asarray(model.scores(V[inside])) < model.threshold]
                        positives.append(flagged)
    X_neg, X_pos = np.vstack(negatives), np.vstack([p for p in positives if len(p)])
    X = np.vstack([X_neg, X_pos])
    y = np.concatenate([np.zeros(len(X_neg)), np.ones(len(X_pos))])
    ranker = make_pipeline(StandardScaler(), LogisticRegression(C=1.0, class_weight='balanced', max_iter=2000))
    ranker.fit(X, y)
    return ranker, len(X_neg), len(X_pos)


def explain(name, topic, stop, train_on, top=4):
    """Lines on a run's ranker: its largest weights (standardized features) and, for each false window of the
    one-class model on the replayed part, the ranker's median and largest probability over the vectors the
    one-class model flags in it."""
    records, first, rest, model, _, inject = runs.prepare(name, topic, stop, 'ours', 0.5, train_on=train_on)
    pieces = runs.training_pieces(name, first, train_on)
    ranker = ranker_of(model, pieces, topic, model.config, inject, sim.nominal_envelope(first, topic))[0]
    weights = ranker[-1].coef_[0]
    lines = ['%s ranker weights: %s' % (name, ', '.join('%s %.1f' % (model.names[i], weights[i])
                                                        for i in np.argsort(-np.abs(weights))[:top]))]
    stamps, V = runs.vectors_of(rest, model.config)
    flagged = np.asarray(model.scores(V)) < model.threshold
    probability = ranker.predict_proba(V)[:, 1]
    for a, b in runs.windows_of(runs.fires(model, rest, topic, 'event')):
        inside = flagged & (stamps >= a) & (stamps <= b)
        if np.any(inside):
            lines.append('%s false window %.1f-%.1f s: %d flagged vectors, ranker probability median %.2f, max %.2f'
                         % (name, a - records[0].stamp, b - records[0].stamp, int(inside.sum()),
                            float(np.median(probability[inside])), float(np.max(probability[inside]))))
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', help='comma-separated run names (default: all of detection_runs.RUNS)')
    parser.add_argument('--seeds', default='0,1,2')
    parser.add_argument('--train-on', default='robot', choices=runs.TRAIN_ON)
    parser.add_argument('--gate', type=float, default=0.5, help='ranker probability needed to fire (default 0.5)')
    parser.add_argument('--explain', action='store_true',
                        help='then, per run, the ranker\'s largest weights and its probabilities in each false window')
    args = parser.parse_args(argv)
    started = time.time()
    seeds = [int(s) for s in args.seeds.split(',')]
    chosen = [run for run in runs.RUNS if not args.runs or run[0] in args.runs.split(',')]
    common.header('Detection with a second-stage ranker', [common.describe_data(runs.bag_path(name))
                                                           for name, _, _ in chosen] + [
        'setting ours (motion %s, retrigger event); trained on %s; evaluation seeds %s (BWIBot scale); ranker '
        'seeds %s (both scales); gate %.2f' % (runs.WINDOW, args.train_on, args.seeds,
                                               ','.join(map(str, RANKER_SEEDS)), args.gate)])
    prepare = runs.prepare
    rows, totals = [], {'plain': [0, 0, 0, 0, 0.0], 'gated': [0, 0, 0, 0, 0.0]}
    for name, topic, stop in chosen:
        built = {}

        def gated_prepare(*a, **k):
            records, first, rest, model, vectors, inject = prepare(*a, **k)
            if 'ranker' not in built:
                pieces = runs.training_pieces(name, first, k.get('train_on'))
                built['ranker'] = ranker_of(model, pieces, topic, model.config, inject,
                                            sim.nominal_envelope(first, topic))
            return records, first, rest, GatedModel(model, built['ranker'][0], args.gate), vectors, inject

        row = [name]
        for label, hook in (('plain', prepare), ('gated', gated_prepare)):
            runs.prepare = hook
            try:
                r = runs.evaluate_run(name, topic, stop, 'ours', seeds, 0.5, train_on=args.train_on)
            finally:
                runs.prepare = prepare
            caught, total, late = sum(r['caught'].values()), sum(r['total'].values()), sum(r['late'].values())
            row += [r['false_nominal'], '%d/%d (%d)' % (caught, total, late)]
            t = totals[label]
            t[0] += r['false_nominal']
            t[1] += caught
            t[2] += total
            t[3] += late
            t[4] += r['replay_s']
        _, negatives, positives = built['ranker']
        rows.append(row + [negatives, positives])
        print('%s done (%.0f s)' % (name, time.time() - started), flush=True)
    hours = totals['plain'][4] / 3600.0
    rows.append(['**all** (%.3f h)' % hours] + sum(
        [['%d (%.1f/h)' % (t[0], t[0] / hours), '%d/%d (%d)' % (t[1], t[2], t[3])]
         for t in (totals['plain'], totals['gated'])], []) + ['', ''])
    print()
    common.table(['run', 'false windows', 'caught (late)', 'gated: false windows', 'gated: caught (late)',
                  'ranker negatives', 'ranker positives'], rows,
                 'One-class model alone and gated by the ranker (replayed part; false windows without injection):')
    if args.explain:
        print()
        for name, topic, stop in chosen:
            for line in explain(name, topic, stop, args.train_on):
                print(line)
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
