#!/usr/bin/env python3
"""Memory of the live smart node with a logging window open the whole time: RSS while odometry plus IMU
stream in for 60 s at each rate (default 100 + 100 Hz and 1 kHz + 1 kHz), for each ``~max_buffer_mb``, and
the bytes held per buffered message.

    cd <tree> && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/memory_live.py                     # 60 s at 100 and 1000 Hz with ~max_buffer_mb 64
    python3 bench/memory_live.py --budgets 256,0 --rates 1000 --seconds 30
    python3 bench/memory_live.py --quick             # 4 s with a 16 MB budget (tests)
    python3 bench/memory_live.py --format bag-lz4    # windows written as bags (json-xz by default)

What it starts (cost_live.roscore_session: own sessions, a roscore on a free port, all stopped by their ids):
- the smart node (``rosrun cc_log smart_logger.py``, ``--format``, ``odom:=/odom _topics:=/imu``) with a model whose
  threshold calls every message anomalous, so one window stays open from the first second to the last and is
  written in parts (``~max_window`` 100000 messages would split it only after 100 s);
- a publisher (this script with --publisher): nav_msgs/Odometry on /odom and sensor_msgs/Imu on /imu, each
  at --rate Hz paced in wall time, header stamps of now; it also listens to /diagnostics and reports the
  node's last counters and the largest ``buffered bytes (estimated)`` and ``writer queue`` it saw.

RSS = VmRSS of the node from /proc every second (peak = VmHWM at the end). Bytes per buffered message: the
node's own estimate (``buffered bytes (estimated)`` / ``messages buffered`` on /diagnostics, at the largest
estimate seen) and, measured, the RSS growth over the run / the messages buffered then.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402
from cost_live import memory_mb, roscore_session, wait_subscribers  # noqa: E402

DEFAULT_BUDGETS = '64'
DEFAULT_RATES = '100,1000'
CHECKPOINTS = (10, 30, 60)


# -- the publisher child -------------------------------------------------------------------------------

def publisher(args):
    import rospy
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Imu
    rospy.init_node('cc_log_bench_memory_publisher', disable_signals=True)
    state = {'intake_max': 0, 'buffered_max': 0, 'buffered_messages': 0, 'writer_queue_max': 0, 'values': {}}

    def on_diagnostics(array):
        for status in array.status:
            values = {kv.key: kv.value for kv in status.values}
            if 'messages seen' in values:
                state['values'] = values
                buffered = int(values.get('buffered bytes (estimated)', 0))
                if buffered > state['buffered_max']:
                    state['buffered_max'] = buffered
                    state['buffered_messages'] = int(values.get('messages buffered', 0))
                state['writer_queue_max'] = max(state['writer_queue_max'], int(values.get('writer queue', 0)))
                state['intake_max'] = max(state['intake_max'], int(values.get('intake queue', 0)))
    rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics)
    odom_pub = rospy.Publisher('/odom', Odometry, queue_size=10000)
    imu_pub = rospy.Publisher('/imu', Imu, queue_size=10000)
    deadline = time.time() + 20.0
    while (odom_pub.get_num_connections() < 1 or imu_pub.get_num_connections() < 1) and time.time() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)
    odom, imu = Odometry(), Imu()
    odom.header.frame_id, odom.child_frame_id, imu.header.frame_id = 'odom', 'base_link', 'imu'
    odom.pose.pose.orientation.w = imu.orientation.w = 1.0
    imu.linear_acceleration.z = 9.81
    sent, start = 0, time.time()
    end = start + args.seconds
    while time.time() < end:
        due = int((time.time() - start) * args.rate) + 1
        while sent < due:
            stamp = rospy.Time.from_sec(start + sent / args.rate)
            odom.header.seq = imu.header.seq = sent
            odom.header.stamp = imu.header.stamp = stamp
            odom.pose.pose.position.x = 0.001 * sent
            odom.twist.twist.linear.x = 1.0 + 0.1 * math.sin(sent * 0.005)
            odom.twist.twist.angular.z = imu.angular_velocity.z = 0.1 * math.cos(sent * 0.003)
            odom_pub.publish(odom)
            imu_pub.publish(imu)
            sent += 1
        time.sleep(0.001)
    publish_seconds = time.time() - start
    drain_end = time.time() + 10.0
    while time.time() < drain_end and int(state['values'].get('messages seen', 0)) < 2 * sent:
        time.sleep(0.1)
    values = state['values']
    print(json.dumps({'sent': sent, 'publish_seconds': publish_seconds, 'seen': int(values.get('messages seen', 0)),
                      'lost': int(values.get('messages lost', 0)), 'windows': int(values.get('windows saved', 0)),
                      'buffered_max': state['buffered_max'], 'buffered_messages': state['buffered_messages'],
                      'writer_queue_max': state['writer_queue_max'],
                      'intake_max': state['intake_max']}))
    rospy.signal_shutdown('done')
    return 0


# -- the runs ------------------------------------------------------------------------------------------

def always_anomalous_model(path):
    """A model trained on random vectors with a threshold that calls every message anomalous."""
    import numpy as np
    from cc_log.learning import learning
    from cc_log.features import FeatureConfig, vector_length
    config = FeatureConfig('motion', '20')
    model, _ = learning.train(np.random.RandomState(0).normal(size=(60, vector_length(config))), None, config)
    model.threshold = 1e9
    return model.save(path)


def run(procs, tmp, model, budget, rate, args):
    """One run of the node with ``~max_buffer_mb`` = budget at ``rate`` Hz per topic; returns the figures."""
    out_dir = os.path.join(tmp, 'windows_%g_%g' % (budget, rate))
    node = procs.start('smart_node_%g_%g' % (budget, rate), [
        'rosrun', 'cc_log', 'smart_logger.py', '_model:=' + model, '_directory:=' + out_dir, 'odom:=/odom',
        '_topics:=/imu', '_pre:=2s', '_post:=2s', '_max_buffer_mb:=%g' % budget, '_diagnostic_period:=0.5',
        '_format:=' + args.format])
    wait_subscribers('/odom', 1)
    wait_subscribers('/imu', 1)
    child = subprocess.Popen([sys.executable, os.path.abspath(__file__), '--publisher', '--rate', str(rate),
                              '--seconds', str(args.seconds)], env=procs.env, stdout=subprocess.PIPE,
                             universal_newlines=True)
    samples = []
    started = None
    while child.poll() is None:
        if started is None:
            started = time.time()  # the publisher's own start is within ~1 s of this
        samples.append((time.time() - started, memory_mb(node.pid, 'VmRSS')))
        time.sleep(1.0)
    result = json.loads(child.stdout.read().strip().splitlines()[-1])
    result['peak'] = memory_mb(node.pid)
    result['samples'] = samples
    result['budget'] = budget
    result['rate'] = rate
    procs.stop(node)
    return result


def at(samples, second):
    """RSS at the sample nearest ``second`` s after publishing started (None when the run was shorter)."""
    near = [rss for t, rss in samples if t <= second + 1.5]
    return near[-1] if near and samples[-1][0] >= second - 1 else None


QUICK = {'seconds': 4.0, 'budgets': '16', 'rates': '1000'}  # --quick


def parse(argv):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--rates', default=DEFAULT_RATES, help='messages per second on each topic, one run each')
    parser.add_argument('--rate', type=float, default=1000.0, help=argparse.SUPPRESS)  # the publisher's
    parser.add_argument('--budgets', default=DEFAULT_BUDGETS, help='~max_buffer_mb values, one run each (0: none)')
    parser.add_argument('--format', default='json-xz', choices=('json-xz', 'bag-lz4'), help='of the windows')
    parser.add_argument('--quick', dest='preset', action='store_const', const=QUICK, default={},
                        help='a 4 s run with a 16 MB budget')
    parser.add_argument('--publisher', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    vars(args).update(args.preset)
    return args


def main(argv=None):
    started = time.time()
    args = parse(argv)
    if args.publisher:
        return publisher(args)
    budgets = [float(b) for b in args.budgets.split(',') if b]
    rates = [float(r) for r in args.rates.split(',') if r]
    common.header('Memory of the live smart node with a window open all the time', [
        'data: synthetic nav_msgs/Odometry and sensor_msgs/Imu, each at every rate for %g s, header stamps of now; '
        'model: motion 20-message window with a threshold that calls every message anomalous; %s, pre/post 2 s'
        % (args.seconds, args.format),
        'runs: ~max_buffer_mb %s at %s Hz per topic' % (', '.join('%g' % b for b in budgets),
                                                        ', '.join('%g' % r for r in rates))])
    results = []
    with roscore_session('cc_log_bench_memory_') as (procs, tmp):
        model = always_anomalous_model(os.path.join(tmp, 'model.json'))
        for budget in budgets:
            for rate in rates:
                results.append(run(procs, tmp, model, budget, rate, args))
    rows = []
    for r in results:
        rss = [at(r['samples'], second) for second in CHECKPOINTS]
        held = r['buffered_messages']
        grown = (r['samples'][-1][1] - r['samples'][0][1]) * 1e6 if len(r['samples']) > 1 else float('nan')
        rows.append(['%g' % r['budget'] if r['budget'] else 'none (0)', '%g' % r['rate'], r['sent'], r['seen'],
                     r['lost'], r['windows']]
                    + ['%.0f' % value if value is not None else '-' for value in rss]
                    + ['%.0f' % r['peak'], '%.0f' % (r['buffered_max'] / 1e6), held,
                       '%.0f' % (r['buffered_max'] / held) if held else '-',
                       '%.0f' % (grown / held) if held else '-', r['writer_queue_max'], r['intake_max']])
    common.table(['~max_buffer_mb', 'Hz per topic', 'published per topic', 'seen', 'lost', 'windows']
                 + ['RSS MB at %d s' % second for second in CHECKPOINTS]
                 + ['peak RSS MB', 'max buffered MB (estimate)', 'messages buffered then',
                    'bytes per buffered message (estimate)', 'RSS growth per buffered message', 'max writer queue',
                    'max intake queue'], rows,
                 'The smart node, one window open throughout (RSS sampled every second from the first message):')
    for r in results:
        if r['budget']:
            end_rss = r['samples'][-1][1] if r['samples'] else float('nan')
            print('target RSS stays within ~max_buffer_mb %g + 100 MB with a window open %g s: end %.0f MB, peak '
                  '%.0f MB -> %s' % (r['budget'], args.seconds, end_rss, r['peak'],
                                     'met' if r['peak'] <= r['budget'] + 100 and not r['lost'] else 'NOT met'))
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
