#!/usr/bin/env python3
"""CPU per message of the message path by batch size: the classifier trigger alone, and the whole smart logger.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/batch_cost.py [--sizes 1,2,5,10,50,256] [--rounds 3]

The live node hands the logger what its intake drained (what arrived in up to 0.5 s: ~100 records at 100 + 100
Hz; ~10 while it drained every 50 ms), offline replay 256 records at a time; this shows what each batch size
costs per message (process CPU, best of ``--rounds``). Data: a
2-minute simulated BWIBot bag (cc_log.sim seed 1, 100 Hz odometry + IMU, no anomalies) read raw; model: motion
500-message window trained on a nominal simulated run (seed 2, 3 min); classify every 50 ms, json-xz windows
written in the calling thread.
"""
import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.storage.bag import bagio  # noqa: E402
from cc_log.learning import learning  # noqa: E402
from cc_log.base import raw_message  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.features import FeatureConfig  # noqa: E402
from cc_log.logger.smart import SmartLogger  # noqa: E402
from cc_log.triggers.classifier import ClassifierTrigger  # noqa: E402


def per_message(feed, records, size, rounds):
    """Best CPU us per message of ``feed(batches)`` over ``rounds``, ``records`` cut into batches of ``size``."""
    batches = [records[i:i + size] for i in range(0, len(records), size)]
    best = None
    for _ in range(rounds):
        started = time.process_time()
        feed(batches)
        seconds = time.process_time() - started
        best = seconds if best is None else min(best, seconds)
    return 1e6 * best / len(records)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', default='1,2,5,10,50,256')
    parser.add_argument('--rounds', type=int, default=3)
    args = parser.parse_args(argv)
    sizes = [int(size) for size in args.sizes.split(',')]
    with tempfile.TemporaryDirectory(prefix='cc_log_bench_') as tmp:
        bag = os.path.join(tmp, 'sim.bag')
        sim.simulate_to_bag(bag, sim.SimConfig(seed=1, minutes=2, anomalies=0, imu=True))
        nominal, _ = common.sim_records(sim.SimConfig(seed=2, minutes=3, anomalies=0))
        config = FeatureConfig('motion', '500')
        _, vectors = common.window_vectors(nominal, sim.ODOM_TOPIC, config, stride=10)
        model, _ = learning.train(vectors, config=config)
        records = list(bagio.read_raw(bag, [sim.ODOM_TOPIC, sim.IMU_TOPIC]))
        odometry = [r._replace(stamp=raw_message.stamp(r.raw, r.connection, r.stamp)) for r in records
                    if r.topic == sim.ODOM_TOPIC]
        common.header('Message path CPU per message by batch size',
                      ['data: cc_log.sim BWIBot 2 min, seed 1, 100 Hz odometry + IMU (%d messages); model: motion '
                       '500 trained on seed 2' % len(records), 'rounds: %d, best of each' % args.rounds])

        def classifier(batches):
            trigger = ClassifierTrigger('classifier', model, [sim.ODOM_TOPIC])
            for batch in batches:
                trigger.on_records(batch)

        def logger(batches):
            out = tempfile.mkdtemp(dir=tmp)
            smart = SmartLogger(model, out, driving_topic=sim.ODOM_TOPIC, side_topics=(sim.IMU_TOPIC,),
                                background=False)
            for batch in batches:
                smart.on_records(batch)
            smart.close()

        rows = [[size, '%.1f' % per_message(classifier, odometry, size, args.rounds),
                 '%.1f' % per_message(logger, records, size, args.rounds)] for size in sizes]
        print()
        common.table(['batch (records)', 'classifier alone, us per odometry message',
                      'smart logger (buffer, triggers, json-xz writer inline), us per message'], rows)
    return 0


if __name__ == '__main__':
    sys.exit(main())
