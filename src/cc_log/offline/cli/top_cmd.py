"""``cclog top``: the running cc_log nodes, per topic, live (needs a roscore)."""
from cc_log.offline.cli.common import CommandError, command_help


def add_parser(subparsers):
    """The ``cclog top`` sub-parser."""
    p = subparsers.add_parser('top', **command_help(
        'the running cc_log nodes per topic, live (needs a roscore)',
        """
        Every cc_log node's state from its /diagnostics, refreshed every second until Ctrl-C: its level and
        message, windows opened and saved, the last trigger, the writer's queue and messages lost; per topic,
        messages and MB per second and messages dropped because the writer fell behind. Needs the robot's
        ROS master (ROS_MASTER_URI).
        """,
        """
          cclog top
          cclog top --once
        """))
    p.add_argument('--once', action='store_true', help='print the view once every node was heard, then exit')
    p.add_argument('--timeout', type=float, default=10.0, metavar='S',
                   help='with --once: seconds to wait for a first node (default: %(default)s)')
    p.set_defaults(paths=None)
    return p


def run(args):
    """Watch /diagnostics; 1 when no cc_log node was heard."""
    import rosgraph
    from cc_log.offline import top
    if not rosgraph.is_master_online():
        raise CommandError('no ROS master at %s (start roscore, or set ROS_MASTER_URI to the robot\'s)'
                           % rosgraph.get_master_uri())
    return top.watch(once=args.once, timeout=args.timeout)
