"""``cclog stats``: what the robot did and what cc_log kept."""
from cc_log.offline.cli.common import EXIT_OK, command_help, output_flags, print_json, say


def add_parser(subparsers):
    """The ``cclog stats`` sub-parser."""
    p = subparsers.add_parser('stats', **command_help(
        'distance, time moving, windows per hour, bytes vs rosbag record',
        """
        What the robot did and what cc_log kept, from the context track (DIR/context/*.bag) and the windows
        in DIR: distance driven (odometry of the context track, chords lengthened to arcs), time moving and
        stopped, windows (and per hour) by trigger, bytes stored against an estimate of what rosbag record of
        the same topics would have stored (full rates measured inside windows). --since/--until: seconds or a
        UTC time.
        """,
        """
          cclog stats ~/.ros/cc_log
          cclog stats ~/.ros/cc_log --since 2026-01-01 --until 2026-02-01T00:00:00Z --json
        """))
    p.add_argument('directory', metavar='DIR', help='a cc_log directory (windows, context/)')
    p.add_argument('--since', help='count from this stamp (seconds or UTC time)')
    p.add_argument('--until', help='count up to this stamp (seconds or UTC time)')
    p.add_argument('--odom', help='the odometry topic of the context track (default: the one with most messages)')
    output_flags(p)
    return p


def run(args):
    """Distance, time moving/stopped, windows per hour by trigger, bytes vs rosbag record (``stats``)."""
    from cc_log.offline import stats
    result = stats.run_stats(args.directory, stats.parse_time(args.since, 'since') if args.since else None,
                             stats.parse_time(args.until, 'until') if args.until else None, args.odom)
    if args.json:
        print_json(result)
    else:
        for line in stats.format_text(result):
            say(line)
    return EXIT_OK
