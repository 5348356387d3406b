#!/usr/bin/env python3
"""CPU cost per driving message of the classifier path: row, feature window, vector, score.

    cd /work/main && source .catkin_ws/devel/setup.bash && PATH=/usr/bin:$PATH python3 bench/feature_cost.py

Replays the Husky odometry (../shared/data/real/husky_outdoor_2015.bag) several times as if it arrived at
100 Hz with the paper's 500-message window, and prints microseconds per message for each step, with a
model trained on the first half (support vectors as trained) and one with 1000 support vectors.
"""
import os
import platform
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'src'))

from cc_log import bagio, learning  # noqa: E402
from cc_log.features import FeatureConfig, FeatureWindow, OdometryFeatures, window_vector  # noqa: E402
from cc_log.model import AnomalyModel  # noqa: E402

BAG = os.path.normpath(os.path.join(ROOT, '..', 'shared', 'data', 'real', 'husky_outdoor_2015.bag'))
TOPIC = '/husky_velocity_controller/odom'


def per_call(function, items):
    started = time.perf_counter()
    for item in items:
        function(item)
    return (time.perf_counter() - started) / len(items) * 1e6


def main():
    config = FeatureConfig('motion', '500')
    msgs = [record.msg for record in bagio.read_messages(BAG, [TOPIC])]
    stamps = [i * 0.01 for i in range(len(msgs) * 3)]       # 100 Hz
    msgs = msgs * 3
    features = OdometryFeatures(config)
    rows = []
    t_row = per_call(lambda i: rows.append(features.row(msgs[i], stamps[i])), range(len(msgs)))
    ring = FeatureWindow(config)
    t_add = per_call(lambda i: ring.add(stamps[i], rows[i]), range(len(rows)))
    t_ring_vector = per_call(lambda _: ring.vector(), range(2000))
    held = list(ring.rows())
    t_list_vector = per_call(lambda _: window_vector(held, config), range(1000))
    _, X = bagio.feature_vectors(BAG, TOPIC, FeatureConfig('motion', '2s'))
    model, info = learning.train(X[:len(X) // 2], config=FeatureConfig('motion', '2s'))
    vector = X[-1]
    t_score = per_call(lambda _: model.score(vector), range(5000))
    big = AnomalyModel(model.config, model.mean, model.scale, 'ocsvm',
                       {'support_vectors': np.random.default_rng(0).normal(size=(1000, len(vector))),
                        'dual_coef': np.ones(1000), 'intercept': -1.0, 'gamma': 0.01}, 0.0)
    t_score_big = per_call(lambda _: big.score(vector), range(2000))
    print('machine: %s, %s, Python %s, numpy %s' % (platform.node(), platform.machine(), platform.python_version(),
                                                    np.__version__))
    print('%-52s %8.1f us' % ('OdometryFeatures.row', t_row))
    print('%-52s %8.1f us' % ('FeatureWindow.add', t_add))
    print('%-52s %8.1f us' % ('FeatureWindow.vector (500 rows)', t_ring_vector))
    print('%-52s %8.1f us' % ('window_vector(list of 500 rows)', t_list_vector))
    print('%-52s %8.1f us' % ('AnomalyModel.score (%d support vectors)' % info['support_vectors'], t_score))
    print('%-52s %8.1f us' % ('AnomalyModel.score (1000 support vectors)', t_score_big))
    fast = t_row + t_add + t_ring_vector + t_score
    slow = t_row + t_list_vector + t_score
    print('per message, ring path: %.0f us = %.2f%% of one core at 100 Hz' % (fast, fast / 100.0))
    print('per message, list path: %.0f us = %.2f%% of one core at 100 Hz' % (slow, slow / 100.0))
    return 0


if __name__ == '__main__':
    sys.exit(main())
