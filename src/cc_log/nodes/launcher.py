"""The node behind ``launch/record.launch``: smart mode when there is a model, else collect mode, saying why.

``record_node.py --mode=auto|smart|collect --model=PATH [--config=FILE] [ROS arguments]``: ``auto``
(record.launch's default) runs the smart logger (``smart_node``) when ``PATH`` is a file or a configuration is
given, and the collect logger (``collect_node``) otherwise, which then says on the log and on /diagnostics
that it collects feature vectors because it has no model yet. Both read their private parameters as usual
(record.launch sets those of both).
"""
import argparse
import importlib
import os
import sys

from cc_log.logger import options

__all__ = ['choose', 'main', 'run', 'script_main', 'plain']

MODES = ('auto', 'smart', 'collect')
HELP_FLAGS = ('-h', '--help')
ROS_USAGE = '[_param:=value ...] [topic:=remapped ...] [__name:=NAME] [__ns:=NAMESPACE]'


def plain(text):
    """A docstring as a terminal shows it: no RST double backticks."""
    return text.replace('``', '')


def _help(argv, usage, doc):
    """Print the help and return True when ``argv`` (after the program name) asks for it."""
    if not any(arg in HELP_FLAGS for arg in argv[1:]):
        return False
    sys.stdout.write('usage: rosrun cc_log %s %s\n\n%s\n' % (os.path.basename(argv[0]), usage, plain(doc).strip()))
    return True


def script_main(module_name, argv=None):
    """A node script's entry: ``-h``/``--help`` prints the node's documentation (its module docstring) and
    returns 0 without starting the node; otherwise ``cc_log.<module_name>.main(argv)``."""
    argv = sys.argv if argv is None else argv
    module = importlib.import_module('cc_log.nodes.' + module_name)
    node = getattr(module, 'OPTIONS_NODE', None)
    doc = module.__doc__ + ('\nEvery parameter:\n%s\n' % '\n'.join(options.describe(node)) if node else '')
    if _help(argv, ROS_USAGE, doc):
        return 0
    return module.main(argv)


def choose(mode, model, config=''):
    """``(module name, note)``: ``'smart_node'`` or ``'collect_node'`` for ``mode``, ``model`` (a path) and
    ``config`` (a configuration file: its triggers make ``auto`` smart); ``note`` says why collect mode runs
    in ``auto`` mode. ValueError('mode: ...') for an unknown mode."""
    if mode not in MODES:
        raise ValueError('mode: %r is not one of: %s' % (mode, ', '.join(MODES)))
    path = os.path.expanduser(model or '')
    if mode == 'smart' or (mode == 'auto' and (config or (path and os.path.isfile(path)))):
        return 'smart_node', ''
    if mode == 'collect':
        return 'collect_node', ''
    return 'collect_node', ('no model yet (%s): collecting feature vectors for one (train it with cclog learn)'
                            % (path or 'no ~model given'))


def main(argv=None):
    """Run the chosen node; its exit status (1 with one line for a bad mode)."""
    argv = sys.argv if argv is None else argv
    if _help(argv, '--mode=auto|smart|collect --model=PATH [--config=FILE] ' + ROS_USAGE,
             __doc__ + '\nThe parameters are those of smart_logger.py and collect_logger.py (--help).'):
        return 0
    import rospy
    parser = argparse.ArgumentParser(prog='record_node.py', add_help=False)
    parser.add_argument('--mode', default='auto')
    parser.add_argument('--model', default='')
    parser.add_argument('--config', default='')
    mine, rest = parser.parse_known_args(rospy.myargv(argv)[1:])
    ros_args = [arg for arg in argv[1:] if arg not in rospy.myargv(argv)]
    try:
        module, note = choose(mine.mode, mine.model, mine.config)
    except ValueError as error:
        sys.stderr.write('record_node.py: %s\n' % error)
        return 1
    return run(module, [argv[0]] + rest + ros_args, note)


def run(module, argv, note=''):
    """Run the node ``module`` (``choose``) with ``argv``; its exit status."""
    if module == 'smart_node':
        from cc_log.nodes import smart_node
        return smart_node.main(argv)
    from cc_log.nodes import collect_node
    return collect_node.main(argv, note=note)
