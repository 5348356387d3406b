"""``cclog simulate``: a simulated BWIBot bag with labelled anomalies."""
import collections
import math
import os

from cc_log.offline.progress import bar as _bar, call as _call
from cc_log.offline.cli.common import (
    EXIT_OK, CommandError, command_help, human_bytes, non_negative_int, output_flags, parent_exists, positive_float,
    print_json)


def add_parser(subparsers):
    """The ``cclog simulate`` sub-parser."""
    p = subparsers.add_parser('simulate', **command_help(
        'a simulated BWIBot bag with labelled anomalies',
        """
        Simulate the BWIBot driving (nav_msgs/Odometry, optionally IMU, a camera and a laser scanner) with
        labelled anomalies and write a bag plus OUT.truth.json (the anomalies: time spans and types). With
        --camera and --scan, try the camera configuration (README: Cameras and lidars) with no robot.
        """,
        """
          cclog simulate --minutes 10 --anomalies 6 --seed 1 out.bag
          cclog simulate --minutes 2 --anomalies 0 --seed 7 nominal.bag --json
          cclog simulate --minutes 1 --anomalies 2 --imu --camera --scan cameras.bag
        """))
    p.add_argument('out', metavar='OUT.bag', help='bag to write (OUT.bag.truth.json next to it)')
    p.add_argument('--minutes', type=positive_float('minutes'), default=10.0, help='(default: %(default)s)')
    p.add_argument('--anomalies', type=non_negative_int('anomalies'), default=6, help='(default: %(default)s)')
    p.add_argument('--seed', type=non_negative_int('seed'), default=1, help='(default: %(default)s)')
    p.add_argument('--rate', type=positive_float('rate'), default=_sim_rate(),
                   help='odometry Hz (default: %(default)s)')
    p.add_argument('--types', metavar='A,B', help='anomaly types to draw from (default: all; soft_collision, a '
                   'collision within the base\'s own braking, only when named: give --imu --commands)')
    p.add_argument('--imu', action='store_true', help='also write sensor_msgs/Imu')
    p.add_argument('--commands', action='store_true', help='also write the planner\'s /cmd_vel and a move_base-like '
                   '/move_base/status')
    camera, scan = _sensor_help()
    p.add_argument('--camera', action='store_true', help='also write a camera: %s' % camera)
    p.add_argument('--scan', action='store_true', help='also write a laser scanner: %s' % scan)
    p.add_argument('--force', action='store_true', help='overwrite an existing bag')
    output_flags(p)
    return p


def run(args):
    """A simulated BWIBot bag with labelled anomalies, and ``<bag>.truth.json``."""
    from cc_log import sim
    parent_exists(args.out, 'out')
    if os.path.exists(args.out) and not args.force:
        raise CommandError('out: %s exists (use --force to overwrite)' % args.out)
    config = sim.SimConfig(rate=args.rate, seed=args.seed, minutes=args.minutes, anomalies=args.anomalies,
                           imu=args.imu, commands=args.commands, camera=args.camera, scan=args.scan,
                           **({'anomaly_types': args.types} if args.types else {}))
    with _bar(args, 'simulate') as bar:
        truth = _call(sim.simulate_to_bag, bar, args.out, config)
    truth_path = sim.truth_path(args.out)
    summary = collections.OrderedDict([('bag', args.out), ('truth', truth_path), ('minutes', args.minutes),
                                       ('rate', args.rate), ('seed', args.seed), ('anomalies', len(truth)),
                                       ('imu', args.imu), ('camera', args.camera), ('scan', args.scan),
                                       ('bytes', os.path.getsize(args.out)), ('truth_anomalies', truth)])
    if args.json:
        print_json(summary)
    else:
        print('%s: %.1f min at %g Hz, %d anomalies (%s), %s' % (
            args.out, args.minutes, args.rate, len(truth), truth_path, human_bytes(summary['bytes'])))
    return EXIT_OK


def _sim_rate():
    try:
        from cc_log.sim import SimConfig
        return SimConfig().rate
    except ImportError:
        return 100.0


def _sensor_help():
    """The --camera and --scan help: what the simulated sensors publish (``sim.sensors``)."""
    try:
        from cc_log.sim import sensors
    except ImportError:
        return 'sensor_msgs/Image', 'sensor_msgs/LaserScan'
    return ('sensor_msgs/Image on %s, %dx%d rgb8 at %g Hz' % (
        sensors.CAMERA_TOPIC, sensors.WIDTH, sensors.HEIGHT, sensors.CAMERA_RATE),
        'sensor_msgs/LaserScan on %s, %g degrees in %g degree steps at %g Hz' % (
        sensors.SCAN_TOPIC, round(2 * math.degrees(sensors.SCAN_HALF_ANGLE)),
        round(math.degrees(sensors.SCAN_STEP), 3), sensors.SCAN_RATE))
