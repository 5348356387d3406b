#!/usr/bin/env python3
"""CPU cost per driving message of the classifier path: row, feature window, vector, score.

    cd /work/main && source .catkin_ws/devel/setup.bash && PATH=/usr/bin:$PATH python3 bench/feature_cost.py

Replays the Husky odometry (../shared/data/real/husky_outdoor_2015.bag) several times as if it arrived at
100 Hz with the paper's 500-message window, and prints microseconds per message for each step, with a
model trained on the first half (support vectors as trained) and one with 1000 support vectors.

    python3 bench/feature_cost.py --blocks [--rounds 5]

Instead: motion rows of serialized Odometry messages per CPU second, ``row_block`` over blocks (of 64, 256:
the replay's batch, and 1024 messages) against message by message (``row_values_raw`` and ``covers``, the
``FeatureSet.row_block`` default), alternating in the same process, best of the rounds, on the Husky
odometry (its own stamps) and a 10-minute simulated run (cc_log.sim seed 1, 100 Hz, 6 anomalies); the rows
of both are checked to be the same floats.
"""
import argparse
import os
import platform
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'src'))

import common  # noqa: E402
from cc_log.storage.bag import bagio  # noqa: E402
from cc_log.learning import learning  # noqa: E402
from cc_log.base import raw_message  # noqa: E402
from cc_log.features import FeatureConfig, FeatureWindow, OdometryFeatures, window_vector  # noqa: E402
from cc_log.learning.model import AnomalyModel  # noqa: E402

BAG = os.path.normpath(os.path.join(ROOT, '..', 'shared', 'data', 'real', 'husky_outdoor_2015.bag'))
TOPIC = '/husky_velocity_controller/odom'


def per_call(function, items):
    started = time.perf_counter()
    for item in items:
        function(item)
    return (time.perf_counter() - started) / len(items) * 1e6


def block_rows(feature, buffs, stamps, size, span, by_message):
    """Rows of ``buffs`` in blocks of ``size`` (by ``FeatureSet.row_block``, the message-by-message default, when
    ``by_message``), and the process CPU seconds they took."""
    from cc_log.features import FeatureSet
    row_block = FeatureSet.row_block if by_message else type(feature).row_block
    started = time.process_time()
    rows = [row_block(feature, buffs[i:i + size], stamps[i:i + size], True, span)[0]
            for i in range(0, len(buffs), size)]
    return np.concatenate(rows), time.process_time() - started


def block_cost(rounds):
    """Rows per CPU second, row_block against message by message (see the module docstring)."""
    import io
    from cc_log import sim
    records = list(bagio.read_raw(BAG, [TOPIC]))
    husky = ([r.raw for r in records], [raw_message.stamp(r.raw, r.connection, r.stamp) for r in records])
    simulated, _ = common.sim_records(sim.SimConfig(seed=1, minutes=10, anomalies=6))
    buffs, stamps = [], []
    for record in simulated:
        if record.topic == sim.ODOM_TOPIC:
            buffer = io.BytesIO()
            record.msg.serialize(buffer)
            buffs.append(buffer.getvalue())
            stamps.append(record.stamp)
    common.header('Motion rows of serialized Odometry: row_block against message by message',
                  [common.describe_data(BAG, '(%s, %d messages)' % (TOPIC, len(husky[0]))),
                   'data: cc_log.sim BWIBot 10 min, 100 Hz, 6 anomalies, seed 1 (%d odometry messages)' % len(buffs),
                   'rounds: %d, alternating; best of each; process CPU time' % rounds])
    table = []
    for name, (buffs, stamps) in (('husky_outdoor_2015', husky), ('sim 10 min', (buffs, stamps))):
        for size in (64, 256, 1024):
            best = {}
            for _ in range(rounds):
                for by_message in (True, False):
                    feature = OdometryFeatures(FeatureConfig('motion', '500'))
                    rows, cpu = block_rows(feature, buffs, stamps, size, feature.config.span, by_message)
                    best[by_message] = min(best.get(by_message, (None, float('inf'))), (rows, cpu), key=lambda x: x[1])
            if best[True][0].view(np.int64).tolist() != best[False][0].view(np.int64).tolist():
                raise SystemExit('%s: row_block gave other floats than message by message' % name)
            one, block = best[True][1], best[False][1]
            table.append([name, len(buffs), size, '%.0f' % (len(buffs) / one), '%.0f' % (len(buffs) / block),
                          '%.1f' % (1e6 * one / len(buffs)), '%.1f' % (1e6 * block / len(buffs)),
                          '%.1fx' % (one / block)])
    common.table(['data', 'messages', 'block', 'rows/CPU s one by one', 'rows/CPU s row_block', 'us/row one by one',
                  'us/row row_block', 'speed-up'], table)
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--blocks', action='store_true', help='row_block against message by message (only)')
    parser.add_argument('--rounds', type=int, default=5)
    args = parser.parse_args(argv)
    if args.blocks:
        return block_cost(args.rounds)
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
