"""``cclog recover``: crash leftovers turned back into window files."""
import os

from cc_log.offline.cli.common import (
    EXIT_OK, EXIT_BAD_INPUT, CommandError, command_help, named_prefix, output_flags, print_json, say)


def add_parser(subparsers):
    """The ``cclog recover`` sub-parser."""
    p = subparsers.add_parser('recover', **command_help(
        'turn crash leftovers (*.tmp-<pid>) back into window files',
        """
        A logger killed while writing a window leaves cc_log_*.tmp-<pid>. recover gives a complete leftover
        its final name, rebuilds a cut-off bag-lz4 window from every message it still holds
        (..._recovered.bag; the leftover is kept as *.unrecovered-<pid> when some of its bytes could not be
        decoded), removes empty leftovers and duplicates of final files, and reports the rest, which it
        keeps. A directory's context/ subdirectory (the context track) is recovered with it. The smart node does
        the same at start. Exit status 1 when anything could not be recovered.
        """,
        """
          cclog recover ~/.ros/cc_log
          cclog recover ~/.ros/cc_log/cc_log_20150521T191138.027Z_classifier.bag.tmp-4242 --json
          cclog recover /data/run      # the leftovers of rosrun cc_log record -o /data/run (/data/run_*)
        """))
    p.add_argument('paths', nargs='+', metavar='DIR|FILE|PREFIX',
                   help='window directories, leftover files, or DIR/PREFIX (record -o\'s): the leftovers of PREFIX_*')
    output_flags(p)
    return p


def _with_context(directory):
    """``directory`` and its context track's subdirectory when it has one: a logging directory's leftovers."""
    from cc_log.storage import context_track
    context = os.path.join(directory, context_track.SUBDIRECTORY)
    return [directory, context] if os.path.isdir(context) else [directory]


def run(args):
    """Leftovers of a crash (``cc_log_*.tmp-<pid>``) turned back into window files, or reported."""
    from cc_log.storage import recovery
    outcomes = []
    for path in args.paths:
        prefixed = named_prefix(path)
        if os.path.isdir(path):
            for directory in _with_context(path):
                outcomes.extend(recovery.recover_directory(directory))
        elif os.path.exists(path):
            outcomes.append(recovery.recover(path, recovery.prefix_of(path)))
        elif prefixed and any(recovery.scan(directory, prefixed[1]) for directory in _with_context(prefixed[0])):
            for directory in _with_context(prefixed[0]):
                outcomes.extend(recovery.recover_directory(directory, prefixed[1]))
        else:
            raise CommandError('%s: no such file or directory' % path)
    if args.json:
        print_json({'leftovers': [outcome._asdict() for outcome in outcomes]})
    else:
        for outcome in outcomes:
            target = ' -> %s (%d messages)' % (outcome.path, outcome.messages) if outcome.path else ''
            say('%-13s %s%s: %s' % (outcome.status, outcome.leftover, target, outcome.detail))
        if not outcomes:
            print('no leftovers')
        elif len(outcomes) > 1:
            print('%d leftovers: %d messages recovered, %d bytes could not be' % (
                len(outcomes), sum(o.messages for o in outcomes), sum(o.lost_bytes for o in outcomes)))
    return EXIT_BAD_INPUT if recovery.incomplete(outcomes) else EXIT_OK
