#!/usr/bin/env python3
"""Context track and `cclog stats`: distance error against the simulator's true path, bytes and cost.

    cd <tree> && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/context_track.py            # 30-minute runs (about a minute)
    python3 bench/context_track.py --quick    # 2-minute runs

For each run (simulated BWIBot, cc_log.sim, 100 Hz odometry + 100 Hz IMU, no anomalies, seed 1): every
odometry message goes through a ContextTrack (odom:1, 600 s files, real rosbag LZ4), then `cclog stats`'s
run_stats reads the directory back. Reported: the simulator's true path length (Simulator.distance), the
distance stats reports and its error, time moving/stopped, the context track's bytes, what `rosbag record`
(uncompressed, every message of odometry and IMU) would have stored, measured by writing it, and the
context track's CPU per message fed (feeding all 100 Hz odometry, most of it thinned away).
Runs: perfect sensors (noise 0: the error is the 1 Hz sampling's) and realistic ones (noise 1: wheel-scale
error up to 2%, noise and drift: odometry's own error, which no logger can remove).
"""
import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log import sim  # noqa: E402
from cc_log.offline import stats  # noqa: E402
from cc_log.storage.context_track import ContextTrack  # noqa: E402
from cc_log.base.records import Record  # noqa: E402


def run(minutes, noise, directory):
    import genpy
    import rosbag
    simulator = sim.Simulator(sim.SimConfig(minutes=minutes, anomalies=0, noise=noise, seed=1, imu=True))
    track = ContextTrack(directory, {sim.ODOM_TOPIC: 1.0})
    full = os.path.join(directory, 'rosbag_record.bag')
    feed = 0.0
    fed = 0
    with rosbag.Bag(full, 'w') as bag:
        for topic, stamp, msg in simulator.messages():
            bag.write(topic, msg, genpy.Time.from_sec(stamp))
            if topic == sim.ODOM_TOPIC:
                begin = time.process_time()
                track.add(Record(stamp, topic, msg))
                feed += time.process_time() - begin
                fed += 1
    track.close()
    result = stats.run_stats(directory)
    return simulator, result, os.path.getsize(full), feed / fed


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true')
    args = parser.parse_args()
    started = time.time()
    minutes = 2.0 if args.quick else 30.0
    common.header('Context track and cclog stats: distance against the true path, bytes, cost',
                  ['data: cc_log.sim BWIBot, %g-minute runs, 100 Hz odometry + 100 Hz IMU, seed 1, no anomalies; '
                   'context track odom:1' % minutes])
    rows = []
    for noise in (0.0, 1.0):
        with tempfile.TemporaryDirectory(prefix='cc_log_bench_context_') as directory:
            simulator, result, full, cost = run(minutes, noise, directory)
        error = (result['distance_m'] - simulator.distance) / simulator.distance
        rows.append([noise, simulator.distance, result['distance_m'], '%+.2f%%' % (100 * error), result['moving_s'],
                     result['stopped_s'], result['context_bytes'], full, cost * 1e6])
    common.table(['sensor noise', 'true distance m', 'cclog stats m', 'error', 'moving s', 'stopped s',
                  'context track bytes', 'rosbag record bytes', 'CPU us per odometry message fed'], rows)
    print('total %.1f s' % (time.time() - started))


if __name__ == '__main__':
    main()
