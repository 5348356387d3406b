#!/usr/bin/env python3
"""The intake's receive alone, live: CPU of a process that runs only an ``Intake`` (a sink that counts) subscribed
to a rospy publisher of 640x480 rgb8 images (0.9 MB) at 30 Hz and odometry at 300 Hz (~28 MB/s), with
cc_log's own reader (``~fast_receive``, nodes/tcpros_receive) and with rospy's receive (``fast_receive`` off),
alternating, on a roscore of its own.

    cd <tree> && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/intake_receive.py              # 2 rounds of 10 s each way
    python3 bench/intake_receive.py --rounds 3 --seconds 20

Figure: the subscriber process's CPU time (``time.process_time``) over ``--seconds`` of messages, % of a core.
"""
import argparse
import os
import socket
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

IMAGE_EVERY = 10  # an image after every tenth odometry message
RATE = 300        # odometry messages per second


def publish():
    import rospy
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Image
    rospy.init_node('intake_receive_publisher')
    images = rospy.Publisher('/bench/image', Image, queue_size=100)
    odometry = rospy.Publisher('/bench/odom', Odometry, queue_size=100)
    image = Image(height=480, width=640, encoding='rgb8', step=1920, data=bytes(921600))
    rate, count = rospy.Rate(RATE), 0
    while not rospy.is_shutdown():
        if count % IMAGE_EVERY == 0:
            images.publish(image)
        odometry.publish(Odometry())
        count += 1
        rate.sleep()


def subscribe(fast, seconds):
    """Print ``messages CPU-seconds wall-seconds`` of ``seconds`` of receiving (after the first messages)."""
    import rospy
    from cc_log.nodes import intake

    class Sink(object):
        count = 0

        def on_records(self, records):
            Sink.count += len(records)
    rospy.init_node('intake_receive_subscriber', anonymous=True)
    receiver = intake.Intake(Sink(), '/bench/odom', ['/bench/image'], fast_receive=fast)
    while Sink.count < 10 and not rospy.is_shutdown():
        time.sleep(0.01)
    count, cpu, wall = Sink.count, time.process_time(), time.monotonic()
    time.sleep(seconds)
    print('%d %.4f %.4f' % (Sink.count - count, time.process_time() - cpu, time.monotonic() - wall))
    receiver.stop()


def free_port():
    with socket.socket() as sock:
        sock.bind(('localhost', 0))
        return sock.getsockname()[1]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rounds', type=int, default=2, help='rounds, each way once per round')
    parser.add_argument('--seconds', type=float, default=10.0, help='of receiving, each way each round')
    args = parser.parse_args(argv)
    env = dict(os.environ, ROS_MASTER_URI='http://localhost:%d' % free_port())
    master = subprocess.Popen(['roscore', '-p', env['ROS_MASTER_URI'].rsplit(':', 1)[1]], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    me = os.path.abspath(__file__)
    try:
        time.sleep(3.0)  # roscore's start (rosmaster answers from here on)
        publisher = subprocess.Popen([sys.executable, me, '--publish'], env=env, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        common.header('The intake\'s receive alone', ['images 0.9 MB at %d Hz + odometry at %d Hz from a rospy '
                                                      'publisher; %g s each way, %d rounds'
                                                      % (RATE // IMAGE_EVERY, RATE, args.seconds, args.rounds)])
        rows = []
        for number in range(args.rounds):
            for way in ('fast', 'rospy'):
                out = subprocess.run([sys.executable, me, '--subscribe', way, str(args.seconds)], env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, universal_newlines=True,
                                     timeout=args.seconds + 120).stdout.split()
                messages, cpu, wall = int(out[0]), float(out[1]), float(out[2])
                rows.append([number + 1, {'fast': 'cc_log reader (~fast_receive)', 'rospy': "rospy's receive"}[way],
                             messages, '%.3f' % cpu, '%.2f%%' % (100 * cpu / wall), '%.1f' % (1e6 * cpu / messages)])
        publisher.terminate()
        publisher.wait()
        common.table(['round', 'receive', 'messages', 'process CPU s', 'CPU % of a core', 'us per message'], rows,
                     'Subscriber process CPU (an Intake and a counting sink only):')
    finally:
        master.terminate()
        master.wait()
    return 0


if __name__ == '__main__':
    if '--publish' in sys.argv:
        publish()
    elif '--subscribe' in sys.argv:
        where = sys.argv.index('--subscribe')
        subscribe(sys.argv[where + 1] == 'fast', float(sys.argv[where + 2]))
    else:
        sys.exit(main())
