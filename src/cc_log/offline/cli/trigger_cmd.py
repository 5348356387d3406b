"""``cclog trigger``: save a window now, through a running smart logger's ``~trigger_window`` (needs a roscore)."""
import argparse

from cc_log.base.safe_input import printable
from cc_log.offline.cli.common import EXIT_OK, CommandError, command_help, print_json

SERVICE = 'trigger_window'  # the smart logger's private service (cc_log/TriggerWindow)
WAIT = 10.0                 # seconds to wait for the service to answer


def add_parser(subparsers):
    """The ``cclog trigger`` sub-parser."""
    p = subparsers.add_parser('trigger', **command_help(
        'save a window now on a running smart logger (needs a roscore)',
        """
        Calls the smart logger's ~trigger_window service: a window around its newest driving message is
        saved, with the reason in its metadata, its triggers and the AnomalyEvent. The logger is the one
        running (the node offering a .../trigger_window service), or --node when several are. Needs the
        robot's ROS master (ROS_MASTER_URI). The same call without cc_log's tools:
        rosservice call /smart_logger/trigger_window "{reason: bump, before: 10, after: 5}"
        """,
        """
          cclog trigger
          cclog trigger --reason bump --before 10 --after 5
          cclog trigger --node /robot1/smart_logger --reason 'operator saw a wobble'
        """))
    p.add_argument('--node', help='the smart logger node (default: the one running)')
    p.add_argument('--reason', default='manual', help='why: kept in the window\'s metadata (default: %(default)s)')
    p.add_argument('--before', type=_duration('--before'), default=0.0, metavar='S',
                   help='seconds of the past to keep, at most what the logger holds (default: its pre)')
    p.add_argument('--after', type=_duration('--after'), default=0.0, metavar='S',
                   help='seconds of the future to keep (default: its post)')
    p.add_argument('--json', action='store_true', help='one JSON object: {service, success, message}')
    return p


def _duration(name):
    """argparse type for a duration (``spans.seconds``: ``10``, ``500ms``, ``2m``) as float seconds."""
    def parse(value):
        from cc_log.base.spans import seconds
        try:
            return seconds(value, name)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error))
    parse.__name__ = name
    return parse


def trigger_service(services, nodes, node=None):
    """The ``~trigger_window`` service to call, of the master's ``services`` (names) and ``nodes`` (names,
    for the error): ``node``'s, else the only one there is. CommandError naming what runs otherwise."""
    offered = sorted(name for name in services if name.endswith('/' + SERVICE))
    if node:
        wanted = '/' + node.strip('/') + '/' + SERVICE
        if wanted in offered:
            return wanted
        raise CommandError(printable('--node %s: no %s service there (smart loggers running: %s)' % (
            node, SERVICE, ', '.join(_node_of(name) for name in offered) or 'none')))
    if len(offered) == 1:
        return offered[0]
    if offered:
        raise CommandError(printable('several smart loggers are running (%s): choose one with --node'
                                     % ', '.join(_node_of(name) for name in offered)))
    raise CommandError(printable('no smart logger is running (no %s service; nodes running: %s)'
                                 % (SERVICE, ', '.join(sorted(nodes)) or 'none')))


def _node_of(service):
    return service[:-len('/' + SERVICE)]


def run(args):
    """Call the smart logger's ~trigger_window; 1 with its answer when it saved nothing."""
    import rosgraph
    if not rosgraph.is_master_online():
        raise CommandError('no ROS master at %s (start roscore, or set ROS_MASTER_URI to the robot\'s)'
                           % rosgraph.get_master_uri())
    publishers, subscribers, services = rosgraph.Master('/cclog_trigger').getSystemState()
    nodes = set(node for _, names in publishers + subscribers + services for node in names)
    service = trigger_service([name for name, _ in services], nodes, args.node)
    import rospy
    from cc_log.srv import TriggerWindow
    try:
        rospy.wait_for_service(service, WAIT)
        response = rospy.ServiceProxy(service, TriggerWindow)(args.reason, args.before, args.after)
    except (rospy.ROSException, rospy.ServiceException) as error:
        raise CommandError('%s: %s' % (service, error))
    if args.json:
        print_json({'service': service, 'success': response.success, 'message': response.message})
    if not response.success:
        raise CommandError('%s: %s' % (service, printable(response.message)))
    if not args.json:
        print('%s: %s' % (service, printable(response.message)))
    return EXIT_OK
