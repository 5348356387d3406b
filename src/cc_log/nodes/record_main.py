"""``rosrun cc_log record``: ``rosbag record``'s common flags in front of the cc_log nodes.

A script or launch file that runs ``rosbag record ...`` switches to cc_log by changing the command name:

    rosrun cc_log record -a -x '/camera/.*' -o /data/ --lz4 -L 2G --model model.json --context 'odom:1 amcl_pose'

``parse(argv)`` maps the flags (``rospy.myargv`` removes the ROS remappings first) onto the nodes' private
parameters (``node_params``) and picks the node with ``launcher.choose`` (auto: smart with a model file or a
configuration, else collect mode, saying why) in a ``Plan``. Mapping:

- ``TOPIC ...``: ``~topics``; ``-a``: ``*``; ``-e``: the TOPIC arguments are regular expressions (``re:``);
  ``-x REGEX``: ``!re:REGEX`` (see ``topic_select``); topics that appear later are subscribed as they appear;
  ``--node NODE``: the topics NODE subscribes to, asked of the master at start;
- ``-o PREFIX``: files ``PREFIX_<UTC>_<reason>.bag`` (rosbag: ``PREFIX_<date>.bag``): ``~directory`` the directory
  of PREFIX and ``~name_prefix`` its file-name part (``-o /data/run``: ``/data/run_<UTC>_<reason>.bag``, the
  context track's ``/data/context/run_context_<UTC>.bag``); ``-o DIRECTORY/`` (a trailing ``/``): the directory,
  files named ``cc_log_<UTC>_<reason>.bag``; listing, recovery, the quota and uploads follow the prefix and leave
  other files alone. ``-O NAME``: rosbag writes exactly ``NAME.bag``; cc_log writes one file per window, so
  NAME's stem is the prefix (``-O /data/run.bag`` as ``-o /data/run``), said in one line at start;
- ``--lz4``: ``~format`` bag-lz4; ``-j/--bz2``: accepted, the files are LZ4 all the same (said in one warning line
  at start: cc_log's windows are written as the bytes came, in LZ4 chunks);
- ``--split --duration D`` (``30``, ``30s``, ``5m``, ``2h``): a new file every D, collect mode's ``~rotate``
  and the context track's ``~context_rotate`` (smart mode without ``--context`` refuses it: its files are
  the anomaly windows); ``--duration D`` without ``--split``: stop after D, as rosbag; ``-l NUM``: stop once
  each named topic had NUM messages (``Watch``);
- ``--split --size SIZE`` (rosbag's MB of 1048576 bytes: ``100``; or with a unit: ``1G``, ``500MB``): smart mode's
  ``~split_mb``: a window's file goes on in a new one (``<name>.002.bag``, ...) once it holds SIZE, at the next
  part of the window; refused in collect mode (its files rotate with ``--split --duration``);
- ``--size SIZE`` without ``--split``: rosbag stops recording once its bag holds SIZE; cc_log keeps recording
  within SIZE instead: the quota ``~max_disk_mb`` (the oldest files deleted first), since a logger that stopped
  once its disk share is full would miss every later anomaly, the ones an operator looks for;
- ``--max-splits N``: ``~max_files``: at most N files (window and context files), the oldest deleted first by the
  same quota as ``~max_disk_mb`` (rosbag keeps the newest N split files; cc_log's windows are files of their own,
  so it holds with or without ``--split``);
- ``--chunksize KB``: ``~chunk_kb``, the uncompressed size at which the LZ4 bags close a chunk (rosbag's 768);
- ``--tcpnodelay``: ``~tcp_nodelay``: subscribed with TCP_NODELAY;
- ``-q/--quiet``: ``~quiet``: the node logs warnings and errors only (no INFO lines);
- ``-L/--min-space SIZE`` (``1G``, ``500M``, ``100K``, bytes; rosbag's default 1G): ``~min_free_mb``;
- ``-b/--buffsize MB`` (0: no limit): ``~intake_max_mb``;
- ``-p/--publish``: the directory on ``begin_write`` once the node has subscribed (``Watch``);
- ``--udp``, ``--repeat-latched``: refused, one line saying why (``REFUSED``);
- ``--model``, ``--config``, ``--mode``, ``--context TOPICS`` (``odom:1 amcl_pose``), ``--upload CMD``: cc_log's.

Like rosbag record, the node is named ``record_<id>`` (anonymous; ``__name:=`` names it), so several
recorders run side by side, and it reads its command line only: its settings never go to the parameter server
and nothing left there is read (``_name:=value`` arguments are settings too).

Bad flags print one line (``record: error: ...``) and exit 2, like rosbag record's own.
"""
import argparse
import collections
import os
import re
import sys
import threading
import time

from cc_log.logger import options
from cc_log.base import safe_input
from cc_log.base.spans import megabytes, seconds
from cc_log.nodes import launcher
from cc_log.storage.directory import LoggingDirectory, cc_log_home

__all__ = ['parse', 'node_params', 'main', 'parse_size', 'parse_split_size', 'parse_duration', 'Plan', 'Watch']

DEFAULT_MODEL = 'model.json'  # in cc_log's directory of ROS's home: directory.cc_log_home
DEFAULT_MIN_SPACE = '1G'
UNLIMITED_MB = 1e6  # -b 0 (rosbag: an infinite buffer)
REFUSED = {
    'udp': 'not supported: rospy subscribes over TCPROS only (it has no UDPROS)',
    'repeat_latched': 'not supported: a window already begins with the newest message of each latched topic '
                      'before it (and the context track keeps latched topics given to --context)',
}
REFUSED_FLAGS = ((('--udp',), 'udp', 0), (('--repeat-latched',), 'repeat_latched', 0))
BZ2_NOTE = '-j/--bz2: cc_log writes LZ4 bags (the messages as they came, in LZ4 chunks), not BZ2'
DESCRIPTION = "rosbag record's flags in front of the cc_log nodes: smart windows around anomalies with a\n" \
    "model, else collect mode."
EPILOG = """example:
  rosrun cc_log record /odom /imu/data -o /data/ --split --duration 10m -L 2G --model model.json
  rosrun cc_log record -a -o /data/ --split --size 1024 --config robot.yaml   # window files of about 1 GiB
  rosrun cc_log record /odom -o /data/run --max-splits 20   # /data/run_<UTC>_<reason>.bag, the newest 20 kept

-o PREFIX: files PREFIX_<UTC>_<reason>.bag (-o DIRECTORY/: cc_log_<UTC>_<reason>.bag in it); -O NAME: NAME's
stem as the prefix (cc_log writes one file per window). --size SIZE without --split: a quota (_max_disk_mb),
the oldest files deleted, rather than stopping (a smart logger that stopped would miss every later anomaly).
--max-splits N: at most N files, the oldest deleted. -j: LZ4 all the same (said at start). -q: warnings and
errors only. Refused with one line saying why: --split --size in collect mode, --udp (rospy has no UDPROS),
--repeat-latched (windows begin with each latched topic's newest message already).
ROS arguments (__name:=, remappings, _param:=value) work as for any node."""


def parse_size(value, name='min-space'):
    """Bytes of rosbag's ``1G``, ``500M``, ``100K`` (powers of 1024) or a number of bytes, or any size of
    ``spans.megabytes`` (``2GB``, ``1.5GiB``); ValueError('<name>: ...')."""
    return round(megabytes(value, name, bare='b') * 1e6)


def parse_split_size(value, name='--size'):
    """MB (10^6 bytes, ``~split_mb``) of rosbag record's ``--size``: a bare number is MB of 1048576 bytes, as
    rosbag reads it (``100``: 104.8576), or any size of ``spans.megabytes`` (``1G``, ``500MB``); > 0.
    ValueError('<name>: ...')."""
    size = megabytes(value, name, bare='mib')
    if not size > 0:
        raise ValueError('%s: %s must be a size > 0' % (name, value))
    return size


def parse_duration(value, name='duration'):
    """Seconds of rosbag's ``30``, ``30s``, ``5m`` or ``2h`` (``spans.seconds``, > 0); ValueError('<name>: ...')."""
    return seconds(value, name, positive=True)


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise ValueError(message)


class _Refuse(argparse.Action):
    """A rosbag record flag with no meaning here: one line saying why, at once."""

    def __call__(self, parser, namespace, values, option_string=None):
        raise ValueError('%s: %s' % (option_string, REFUSED[self.dest]))


def _parser():
    parser = _Parser(prog='rosrun cc_log record', description=DESCRIPTION, epilog=EPILOG,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('topics', nargs='*', metavar='TOPIC', help='topics (regular expressions with -e)')
    parser.add_argument('-a', '--all', action='store_true', help='every topic, also those that appear later')
    parser.add_argument('-e', '--regex', action='store_true', help='TOPIC arguments are regular expressions')
    parser.add_argument('-x', '--exclude', action='append', default=[], metavar='REGEX', help='leave out topics')
    parser.add_argument('--node', metavar='NODE', help='the topics NODE subscribes to (asked of the master at start)')
    names = parser.add_mutually_exclusive_group()
    names.add_argument('-o', '--output-prefix', metavar='PREFIX',
                       help='files PREFIX_<UTC>_<reason>.bag; with a trailing / a directory (files cc_log_*)')
    names.add_argument('-O', '--output-name', metavar='NAME',
                       help="NAME's stem as the prefix of every file (cc_log writes one file per window)")
    parser.add_argument('--lz4', action='store_true', help='LZ4 (cc_log writes LZ4 bags in any case)')
    parser.add_argument('-j', '--bz2', action='store_true', help='accepted; cc_log writes LZ4 (says so at start)')
    parser.add_argument('--split', action='store_true', help='with --duration: a new file every DURATION; with '
                        '--size: a window goes on in a new file once its file holds SIZE')
    parser.add_argument('--size', metavar='SIZE', help='with --split (smart mode): split window files at SIZE MB '
                        '(1048576 bytes, as rosbag), or 1G, 500MB, ...; without --split: keep the files within '
                        'SIZE, the oldest deleted (a quota: a smart logger does not stop)')
    parser.add_argument('--max-splits', type=int, metavar='N', help='keep the newest N files, the oldest deleted')
    parser.add_argument('--chunksize', type=int, metavar='KB', help='LZ4 chunks of KB uncompressed (default 768)')
    parser.add_argument('--tcpnodelay', action='store_true', help='subscribe with TCP_NODELAY')
    parser.add_argument('--duration', metavar='DURATION',
                        help='30, 30s, 5m, 2h: with --split, a new file every DURATION; without, stop after it')
    parser.add_argument('-l', '--limit', type=int, metavar='NUM', help='stop once each TOPIC has NUM messages')
    parser.add_argument('-L', '--min-space', default=DEFAULT_MIN_SPACE, metavar='SIZE',
                        help='stop writing below this much free disk (default 1G)')
    parser.add_argument('-b', '--buffsize', type=float, metavar='MB', help='input queue in MB (0: no limit)')
    parser.add_argument('-q', '--quiet', action='store_true', help='warnings and errors only')
    parser.add_argument('-p', '--publish', action='store_true',
                        help='publish the directory on begin_write (std_msgs/String, latched) once recording')
    for flags, dest, nargs in REFUSED_FLAGS:
        parser.add_argument(*flags, dest=dest, nargs=nargs, action=_Refuse, help=argparse.SUPPRESS)
    parser.add_argument('--model', help='model file: smart windows when it exists (default: $ROS_HOME/cc_log/%s, '
                        'ROS_HOME being ~/.ros when unset, unless --config names the triggers)' % DEFAULT_MODEL)
    parser.add_argument('--config', default='', help='configuration file (YAML)')
    parser.add_argument('--mode', default='auto', choices=launcher.MODES)
    parser.add_argument('--context', default='', metavar='TOPICS', help='context track: "odom:1 amcl_pose"')
    parser.add_argument('--upload', default='', metavar='CMD', help='run with the path of each closed file')
    return parser


Plan = collections.namedtuple('Plan', 'module params note stop publish said', defaults=((),))
Plan.__doc__ = """What ``record`` runs: the node module, its settings, why collect mode runs (or ''), ``stop``:
``{'seconds': D}`` (``--duration`` without ``--split``) and/or ``{'limit': N, 'topics': [...]}`` (``-l``),
``publish``: whether to announce on ``begin_write`` (``-p``) (see ``Watch``), and ``said``: ``(warning, line)``
pairs printed at start (how a flag of rosbag's is taken; lines that are not warnings are left out by ``-q``)."""


def parse(argv, subscriptions=None):
    """The ``Plan`` for the flags ``argv`` (no program name, no ROS remappings); ValueError with one line for
    bad flags. ``subscriptions(node)``: the topics ``node`` subscribes to (``--node``; asked of the master)."""
    args = _parser().parse_args(argv)
    if args.node:
        if subscriptions is None:
            raise ValueError('--node: no master to ask for the topics of %s' % args.node[:200])
        found = subscriptions(args.node)
        if not found:
            raise ValueError('--node: %s subscribes to no topic (or is not running)' % args.node[:200])
        args.topics = list(args.topics) + [re.escape(topic) if args.regex else topic  # patterns match whole names
                                           for topic in found]
    if not (args.all or args.topics or args.config):
        raise ValueError('no topics given: TOPIC ..., -a, -e REGEX ... or --node NODE (or --config)')
    if args.split and args.duration is None and args.size is None:
        raise ValueError('--split needs --duration or --size')
    if args.model is None and not args.config:  # the default model; a configuration names its own triggers
        args.model = cc_log_home(DEFAULT_MODEL)
    module, note = launcher.choose(args.mode, args.model, args.config)
    if args.split and args.duration is not None and module == 'smart_node' and not args.context:
        raise ValueError('--split --duration: smart mode writes one file per anomaly window; --split --duration '
                         'splits collect mode\'s files (--mode collect) or the context track (--context TOPICS); '
                         '--split --size splits window files at a size')
    if args.size is not None and args.split and module == 'collect_node':
        raise ValueError('--size: collect mode rotates its files with --split --duration (or _rotate:=20MB of raw '
                         'message bytes); --split --size splits the windows of smart mode (--model, --config)')
    stop = {}
    if args.duration is not None and not args.split:
        stop['seconds'] = parse_duration(args.duration)
    if args.limit is not None:
        if args.limit < 1:
            raise ValueError('--limit: %d must be a number of messages >= 1' % args.limit)
        if args.all or args.regex or not args.topics:
            raise ValueError('--limit: needs the topics named (TOPIC ...), not -a, -e or --config')
        stop.update(limit=args.limit, topics=list(args.topics))
    params = node_params(args)
    said = [(True, BZ2_NOTE)] if args.bz2 else []
    if args.output_name:
        said.append((False, '-O %s: cc_log writes one file per window: %s_<UTC>_<reason>.bag' % (
            args.output_name[:200], os.path.join(params['directory'], params['name_prefix']))))
    return Plan(module, params, note, stop, args.publish, tuple(said))


def node_params(args):
    """The nodes' private parameters for parsed flags."""
    topics = ['*'] if args.all else []
    topics += [('re:' + topic) if args.regex else topic for topic in args.topics]
    topics += ['!re:' + pattern for pattern in args.exclude]
    params = {'format': 'bag-lz4', 'min_free_mb': parse_size(args.min_space) / 1e6}
    if topics:
        params['topics'] = topics
    if args.output_prefix or args.output_name:
        params.update(output_names(args.output_prefix, args.output_name))
    if args.split and args.duration is not None:
        params['rotate'] = '%gs' % parse_duration(args.duration)
        params['context_rotate'] = parse_duration(args.duration)
    if args.split and args.size is not None:
        params['split_mb'] = parse_split_size(args.size)
    elif args.size is not None:  # rosbag stops at SIZE; cc_log keeps recording within it (see the docstring)
        params['max_disk_mb'] = parse_split_size(args.size)
    if args.max_splits is not None:
        if args.max_splits < 1:
            raise ValueError('--max-splits: %d must be a number of files >= 1' % args.max_splits)
        params['max_files'] = args.max_splits
    if args.chunksize is not None:
        if args.chunksize < 1:
            raise ValueError('--chunksize: %d must be a number of KB >= 1' % args.chunksize)
        params['chunk_kb'] = args.chunksize
    for flag, key in ((args.tcpnodelay, 'tcp_nodelay'), (args.quiet, 'quiet')):
        if flag:
            params[key] = True
    if args.buffsize is not None:
        if args.buffsize < 0:
            raise ValueError('buffsize: %r must be a number of MB >= 0 (0: no limit)' % args.buffsize)
        params['intake_max_mb'] = args.buffsize or UNLIMITED_MB
    for key, value in (('model', args.model), ('config', args.config), ('context_topics', args.context),
                       ('upload_command', args.upload)):
        if value:
            params[key] = os.path.expanduser(value) if key in ('model', 'config') else value
    return params


def output_names(prefix, name):
    """``{'directory': ..., 'name_prefix': ...}`` of rosbag record's ``-o PREFIX`` (``/data/run``: /data and
    ``run``; ``/data/``: /data, cc_log's own prefix) or ``-O NAME`` (``/data/run.bag``: /data and ``run``);
    ValueError('-o: ...') for a prefix that is not a plain part of a file name."""
    flag, given = ('-o', prefix) if prefix else ('-O', name)
    directory, part = os.path.split(given)
    if flag == '-O' and part.endswith('.bag'):
        part = part[:-len('.bag')]
    if not part:  # -o DIRECTORY/
        if flag == '-O':
            raise ValueError('-O: %s names a directory, not a file' % safe_input.brief(given))
        return {'directory': os.path.abspath(directory)}
    return {'directory': os.path.abspath(directory or '.'), 'name_prefix': options.get('name_prefix').parse(part, flag)}


def master_subscriptions(node):
    """The topics ``node`` subscribes to, by the master's system state (``--node``)."""
    import rosgraph
    import rospy
    name = rospy.names.resolve_name(node, '/')
    try:
        _, subscribers, _ = rosgraph.Master('/record').getSystemState()
    except Exception as error:  # the master is down or unreachable: one line
        raise ValueError('--node: cannot ask the master: %s' % ' '.join(str(error).split())[:200])
    return sorted(topic for topic, nodes in subscribers if name in nodes)


class Watch(object):
    """What ``record`` does beside the node, as rosbag record: stop after ``seconds`` of ROS time (``--duration``
    without ``--split``) or once each of ``topics`` had ``limit`` messages (``-l``; counted on the node's own
    subscriptions, so faster topics may have a few more by then), and with ``begin_write`` (``-p``) publish
    that text (the directory files go to) on ``begin_write`` (std_msgs/String, latched) once the node has
    subscribed. ``start()`` runs it on a daemon thread."""

    def __init__(self, seconds=None, limit=None, topics=(), begin_write=None):
        self.seconds = seconds
        self.limit = limit
        self.topics = list(topics)
        self.begin_write = begin_write
        self._publisher = None
        self.counts = {}
        self._lock = threading.Lock()

    def start(self):
        thread = threading.Thread(target=self._run, name='cc_log record watch')
        thread.daemon = True
        thread.start()
        return thread

    def _count(self, _msg, topic):
        with self._lock:
            self.counts[topic] = self.counts.get(topic, 0) + 1

    def _reached(self):
        with self._lock:
            return all(self.counts.get(topic, 0) >= self.limit for topic in self.topics)

    @staticmethod
    def _stop(reason):
        import rospy
        rospy.loginfo('record: %s: stopping', reason)
        rospy.signal_shutdown(reason)

    def _subscribed(self):
        from rospy.impl.registration import get_topic_manager
        manager = get_topic_manager()
        return bool(manager.get_subscriptions()) and all(manager.has_subscription(t) for t in self.topics)

    def _run(self):
        import rospy
        while not (rospy.core.is_initialized() and rospy.rostime.is_rostime_initialized()):
            if rospy.core.is_shutdown_requested():
                return
            time.sleep(0.05)
        self.topics = [rospy.resolve_name(topic) for topic in self.topics]
        while not rospy.is_shutdown() and not self._subscribed():
            time.sleep(0.05)  # count on the node's subscriptions, not before them
        if self.begin_write is not None:
            from std_msgs.msg import String
            self._publisher = rospy.Publisher('begin_write', String, queue_size=1, latch=True)
            self._publisher.publish(String(self.begin_write))
        for topic in self.topics if self.limit is not None else ():
            rospy.Subscriber(topic, rospy.AnyMsg, self._count, topic)
        deadline = None
        while not rospy.is_shutdown() and (self.seconds is not None or self.limit is not None):
            now = rospy.get_time()
            if self.seconds is not None and now > 0:
                deadline = deadline or now + self.seconds
                if now >= deadline:
                    return self._stop('--duration %gs reached' % self.seconds)
            if self.limit is not None and self._reached():
                return self._stop('--limit %d reached on %s' % (self.limit, ', '.join(self.topics)))
            time.sleep(0.05)


def _directory_in_use(params):
    """The directory the node will write to (``LoggingDirectory``: ``~directory`` or its fallbacks), or the
    one asked for when none can be used (the node then says why)."""
    try:
        return LoggingDirectory(params.get('directory')).path
    except OSError:
        return params.get('directory', '')


def anonymous_name(base='record'):
    """``record_<pid>_<ms>``, rosbag record's anonymous node name: several recorders run side by side."""
    return '%s_%d_%d' % (base, os.getpid(), int(time.time() * 1000))


def command_line_settings(ros_args):
    """``(settings, rest)``: the private ``_name:=value`` arguments of ``ros_args`` as a dict (YAML values, as
    rospy reads them) and the other ROS arguments; ValueError with one line for a value rospy cannot read."""
    from rospy.client import load_command_line_node_params
    from rospy.exceptions import ROSInitException
    try:
        settings = load_command_line_node_params(['record'] + list(ros_args))
    except ROSInitException as error:
        raise ValueError(' '.join(str(error).split()))
    rest = [arg for arg in ros_args if not (arg.startswith('_') and not arg.startswith('__') and ':=' in arg)]
    return settings, rest


def main(argv=None):
    """Run the chosen node with the mapped settings; its exit status. Like rosbag record it reads its command
    line only: the settings are handed to the node in this process (``node_common.read_settings_only``),
    never set on the parameter server, and ``_name:=value`` arguments override them."""
    import rospy
    from cc_log.nodes import node_common
    argv = sys.argv if argv is None else argv
    mine = rospy.myargv(argv)
    try:
        plan = parse(mine[1:], master_subscriptions)
        settings, ros_args = command_line_settings([arg for arg in argv[1:] if arg not in mine])
    except ValueError as error:
        sys.stderr.write('record: error: %s\n' % ' '.join(str(error).split()))
        return 2
    plan.params.update(settings)
    for warning, line in plan.said:
        if warning or not plan.params.get('quiet'):
            sys.stderr.write('record: %s%s\n' % ('warning: ' if warning else '', line))
    if not any(arg.startswith('__name:=') for arg in ros_args):
        ros_args.append('__name:=' + anonymous_name())
    node_common.read_settings_only(plan.params)
    if plan.stop or plan.publish:
        Watch(begin_write=_directory_in_use(plan.params) if plan.publish else None, **plan.stop).start()
    return launcher.run(plan.module, [argv[0]] + ros_args, plan.note)
