"""``rosrun cc_log record``: ``rosbag record``'s common flags in front of the cc_log nodes.

A script or launch file that runs ``rosbag record ...`` switches to cc_log by changing the command name:

    rosrun cc_log record -a -x '/camera/.*' -o /data/run --lz4 --split --duration 10m -L 2G --model model.json

``parse(argv)`` maps the flags (``rospy.myargv`` removes the ROS remappings first) onto the nodes' private
parameters (``node_params``) and picks the node with ``launcher.choose`` (auto: smart with a model file or a
configuration, else collect mode, saying why). Mapping:

- ``TOPIC ...``: ``~topics``; ``-a``: ``*``; ``-e``: the TOPIC arguments are regular expressions (``re:``);
  ``-x REGEX``: ``!re:REGEX`` (see ``topic_select``); topics that appear later are subscribed as they appear;
- ``-O NAME`` / ``-o PREFIX``: the directory of NAME / PREFIX is ``~directory`` (cc_log names its files
  ``cc_log_*``); ``--lz4`` and ``-j/--bz2``: ``~format`` bag-lz4 (cc_log writes LZ4; bag-lz4 is the default);
- ``--split`` with ``--duration D`` (``30``, ``30s``, ``5m``, ``2h``) or ``--size MB``: collect mode's
  ``~rotate`` (the size is raw JSON MB, about the uncompressed bag size); ``--duration`` also sets
  ``~context_rotate``;
- ``-L/--min-space SIZE`` (``1G``, ``500M``, ``100K``, bytes; rosbag's default 1G): ``~min_free_mb``;
- ``-b/--buffsize MB`` (0: no limit): ``~intake_max_mb``;
- ``--model``, ``--config``, ``--mode``, ``--context TOPICS`` (``odom:1 amcl_pose``), ``--upload CMD``: cc_log's.

Like rosbag record, the node is named ``record_<id>`` (anonymous; ``__name:=`` names it), so several
recorders run side by side, and it reads its command line only: its settings never go to the parameter server
and nothing left there is read (``_name:=value`` arguments are settings too).

Bad flags print one line (``record: error: ...``) and exit 2, like rosbag record's own.
"""
import argparse
import os
import sys
import time

from . import launcher

__all__ = ['parse', 'node_params', 'main', 'parse_size', 'parse_duration']

DEFAULT_MODEL = '~/.ros/cc_log/model.json'
DEFAULT_MIN_SPACE = '1G'
UNLIMITED_MB = 1e6  # -b 0 (rosbag: an infinite buffer)
_SIZES = {'K': 1 << 10, 'M': 1 << 20, 'G': 1 << 30, 'T': 1 << 40}
_DURATIONS = {'s': 1.0, 'm': 60.0, 'h': 3600.0}


def parse_size(value, name='min-space'):
    """Bytes of rosbag's ``1G``, ``500M``, ``100K`` or a number of bytes; ValueError('<name>: ...')."""
    text = str(value).strip().upper().rstrip('B')
    factor = _SIZES.get(text[-1:], 1)
    try:
        number = float(text[:-1] if factor != 1 else text)
    except ValueError:
        number = float('nan')
    if not number >= 0 or number == float('inf'):
        raise ValueError('%s: %r is not a size (1G, 500M, 100K or bytes)' % (name, value))
    return number * factor


def parse_duration(value, name='duration'):
    """Seconds of rosbag's ``30``, ``30s``, ``5m`` or ``2h``; ValueError('<name>: ...')."""
    text = str(value).strip().lower()
    factor = _DURATIONS.get(text[-1:], None)
    try:
        number = float(text[:-1] if factor else text) * (factor or 1.0)
    except ValueError:
        number = float('nan')
    if not number > 0 or number == float('inf'):
        raise ValueError('%s: %r is not a duration (30, 30s, 5m, 2h)' % (name, value))
    return number


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise ValueError(message)


def _parser():
    parser = _Parser(prog='rosrun cc_log record', description=__doc__.split('\n\n')[0])
    parser.add_argument('topics', nargs='*', metavar='TOPIC', help='topics (regular expressions with -e)')
    parser.add_argument('-a', '--all', action='store_true', help='every topic, also those that appear later')
    parser.add_argument('-e', '--regex', action='store_true', help='TOPIC arguments are regular expressions')
    parser.add_argument('-x', '--exclude', action='append', default=[], metavar='REGEX', help='leave out topics')
    parser.add_argument('-O', '--output-name', metavar='NAME', help='its directory is where files go')
    parser.add_argument('-o', '--output-prefix', metavar='PREFIX', help='its directory is where files go')
    parser.add_argument('--lz4', action='store_true', help='LZ4 (cc_log writes LZ4 bags in any case)')
    parser.add_argument('-j', '--bz2', action='store_true', help='accepted; cc_log writes LZ4')
    parser.add_argument('--split', action='store_true', help='split files at --size or --duration')
    parser.add_argument('--size', type=float, metavar='MB', help='with --split: new file after this many MB')
    parser.add_argument('--duration', metavar='DURATION', help='with --split: new file after 30, 30s, 5m, 2h')
    parser.add_argument('-L', '--min-space', default=DEFAULT_MIN_SPACE, metavar='SIZE',
                        help='stop writing below this much free disk (default 1G)')
    parser.add_argument('-b', '--buffsize', type=float, metavar='MB', help='input queue in MB (0: no limit)')
    parser.add_argument('-q', '--quiet', action='store_true', help='accepted')
    parser.add_argument('--model', default=DEFAULT_MODEL, help='model file: smart windows when it exists')
    parser.add_argument('--config', default='', help='configuration file (YAML)')
    parser.add_argument('--mode', default='auto', choices=launcher.MODES)
    parser.add_argument('--context', default='', metavar='TOPICS', help='context track: "odom:1 amcl_pose"')
    parser.add_argument('--upload', default='', metavar='CMD', help='run with the path of each closed file')
    return parser


def parse(argv):
    """``(module, params, note)`` for the flags ``argv`` (no program name, no ROS remappings);
    ValueError with one line for bad flags."""
    args = _parser().parse_args(argv)
    if not (args.all or args.topics or args.config):
        raise ValueError('no topics given: TOPIC ..., -a or -e REGEX ... (or --config)')
    if args.split and args.size is None and args.duration is None:
        raise ValueError('--split needs --size or --duration')
    module, note = launcher.choose(args.mode, args.model, args.config)
    return module, node_params(args), note


def node_params(args):
    """The nodes' private parameters for parsed flags."""
    topics = ['*'] if args.all else []
    topics += [('re:' + topic) if args.regex else topic for topic in args.topics]
    topics += ['!re:' + pattern for pattern in args.exclude]
    params = {'format': 'bag-lz4', 'min_free_mb': parse_size(args.min_space) / 1e6}
    if topics:
        params['topics'] = topics
    output = args.output_name or args.output_prefix
    if output:
        directory = output if output.endswith(os.sep) else os.path.dirname(output)
        params['directory'] = os.path.abspath(directory or '.')
    if args.split and args.duration is not None:
        params['rotate'] = '%gs' % parse_duration(args.duration)
    elif args.split:
        if not args.size > 0:
            raise ValueError('size: %r must be a positive number of MB' % args.size)
        params['rotate'] = '%gMB' % args.size
    if args.duration is not None:
        params['context_rotate'] = parse_duration(args.duration)
    if args.buffsize is not None:
        if args.buffsize < 0:
            raise ValueError('buffsize: %r must be a number of MB >= 0 (0: no limit)' % args.buffsize)
        params['intake_max_mb'] = args.buffsize or UNLIMITED_MB
    for key, value in (('model', args.model), ('config', args.config), ('context_topics', args.context),
                       ('upload_command', args.upload)):
        if value:
            params[key] = os.path.expanduser(value) if key in ('model', 'config') else value
    return params


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
    from . import node_common
    argv = sys.argv if argv is None else argv
    mine = rospy.myargv(argv)
    try:
        module, params, note = parse(mine[1:])
        settings, ros_args = command_line_settings([arg for arg in argv[1:] if arg not in mine])
    except ValueError as error:
        sys.stderr.write('record: error: %s\n' % ' '.join(str(error).split()))
        return 2
    params.update(settings)
    if not any(arg.startswith('__name:=') for arg in ros_args):
        ros_args.append('__name:=' + anonymous_name())
    node_common.read_settings_only(params)
    return launcher.run(module, [argv[0]] + ros_args, note)
