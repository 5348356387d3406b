"""``cclog``: the offline cc_log tool. No roscore is needed, except by ``top`` and ``trigger`` (a live robot's).

    rosrun cc_log cclog <command> [options]      (see ``cclog <command> --help`` and docs/CLI.md)

Commands: ``collect`` (feature vectors from a bag), ``learn`` (train / evaluate a model), ``learn-envelope`` (the
physics envelope of nominal bags), ``replay`` (the
smart logger over a bag), ``info``, ``cat``, ``export`` (window files), ``codecs`` (the paper's Table 2 on
some data), ``plot`` (a timeline of a run), ``tune`` (a threshold for a false-window budget), ``simulate`` (a
simulated BWIBot bag with labelled anomalies); on a live robot, ``top`` (the running nodes) and ``trigger`` (save a
window now).

Conventions shared by every command:

- results go to stdout: readable text, or with ``--json`` one JSON object (``cat`` writes JSON lines);
- progress bars go to stderr, only when stderr is a terminal or with ``--progress``; never to stdout;
- bad input (missing file, truncated or unindexed bag, topic not in the bag, wrong message type, a model
  of another feature configuration, bad option values) prints one line
  ``cclog <command>: error: <what is wrong>`` on stderr and exits with status 1 (2 for bad command-line
  syntax, 130 when interrupted).

Library modules are imported inside the commands, so ``cclog --help`` is quick and a command only needs
what it uses (rosbag for bags, matplotlib for ``plot``).

To add a command: one module here with ``add_parser(subparsers)`` (its flags, beside its logic) and ``run(args)``
(the exit status), plus one line in ``COMMANDS``. What several commands share is in ``common``.
"""
import os
import sys

from cc_log.offline.cli import (cat_cmd, codecs_cmd, collect_cmd, export_cmd, info_cmd, learn_cmd, plot_cmd,
                                recover_cmd, replay_cmd, simulate_cmd, stats_cmd, top_cmd, trigger_cmd, tune_cmd)
from cc_log.offline.cli import learn_envelope_cmd
from cc_log.offline.cli.common import (
    PROG, EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_OK, INTERRUPT_GRACE, CommandError, Parser, command_help)

__all__ = ['main', 'build_parser', 'COMMANDS', 'CommandError', 'Interrupt', 'INTERRUPT_GRACE']

# the commands, in the order of ``cclog --help``
COMMANDS = (collect_cmd, learn_cmd, learn_envelope_cmd, tune_cmd, replay_cmd, info_cmd, cat_cmd, export_cmd,
            codecs_cmd, plot_cmd, simulate_cmd, recover_cmd, stats_cmd, top_cmd, trigger_cmd)


def build_parser():
    """The ``cclog`` argument parser: one sub-parser per module of COMMANDS."""
    parser = Parser(prog=PROG, **command_help(
        None,
        """
        cc_log offline tool: tune the anomaly logger on bags you already have. No roscore needed (but by top
        and trigger, which talk to a running logger).

        Results go to stdout (--json: one JSON object); progress bars to stderr (on a terminal or with
        --progress). Bad input prints one line "cclog <command>: error: ..." and exits 1 (2 for bad
        command-line syntax).
        """,
        """
          cclog simulate --minutes 10 --anomalies 6 --seed 1 sim.bag
          cclog collect husky.bag --topic /husky_velocity_controller/odom --out vectors
          cclog learn --train vectors --model model.json
          cclog replay husky.bag --topic /husky_velocity_controller/odom --model model.json --out logs --json
          cclog info logs
          cclog plot logs --bag husky.bag --out run.png
        """))
    parser.add_argument('--version', action='version', version='%(prog)s ' + _version())
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=Parser)
    subparsers.required = True
    for command in COMMANDS:
        command.add_parser(subparsers).set_defaults(run=command.run)
    return parser


def _version():
    from cc_log import __version__
    return __version__


# -- main -------------------------------------------------------------------------------------------------

def _one_line(error):
    text = ' '.join(part.strip() for part in str(error).strip().splitlines() if part.strip())
    return text or type(error).__name__


class Interrupt(object):
    """Ctrl-C (SIGINT) while a command runs: KeyboardInterrupt, as Python's own handler raises it. What the
    command then finishes (the window writer writing the window that was open) may take ``grace`` seconds at
    most: then a second KeyboardInterrupt stops that wait too, so the command ends within about a second.
    Files are written under a temporary name and renamed whole, so a window cut off this way leaves no
    partial file under a final name. ``grace`` None: no second interrupt (set while a Dask cluster runs: its
    workers must end before their leftovers are removed)."""

    def __init__(self, grace=INTERRUPT_GRACE):
        import threading
        self.grace = grace
        self.done = False
        self._timer = None
        self._previous = None
        self._main = threading.current_thread() is threading.main_thread()

    def __enter__(self):
        import signal
        if self._main:  # signal handlers can only be set there
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        import signal
        self.done = True
        if self._timer is not None:
            self._timer.cancel()
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        return False

    def _handle(self, signum, frame):
        import threading
        if self.done:
            return
        if self._timer is None and self.grace is not None:
            self._timer = threading.Timer(self.grace, self._again, (threading.main_thread().ident, signum))
            self._timer.daemon = True
            self._timer.start()
        raise KeyboardInterrupt

    def _again(self, thread, signum):
        import signal
        if self.grace is not None and not self.done:
            signal.pthread_kill(thread, signum)  # wakes the main thread out of a join


def main(argv=None):
    """Run ``cclog``; return the exit status."""
    parser = build_parser()
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    prog = '%s %s' % (PROG, args.command)
    try:
        with Interrupt() as args.interrupt:
            status = _run(args, prog)
    except KeyboardInterrupt:  # the second one, while the first was being reported
        status = EXIT_INTERRUPTED
    if status == EXIT_INTERRUPTED and argv is None and args.interrupt.grace is not None:
        # the program itself (not a call from Python), no Dask cluster (whose processes the teardown ends): skip
        # the interpreter's teardown, which takes seconds to free what an interrupted command held (a replay's
        # open window of 100,000s of messages); nothing is left to write
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(status)
    return status


def _run(args, prog):
    """``args.run(args)`` with its errors as one line and an exit status."""
    try:
        return args.run(args)
    except ValueError as error:  # CommandError, ModelError and every '<what>: <problem>' of the library
        sys.stderr.write('%s: error: %s\n' % (prog, _one_line(error)))
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # `cclog cat ... | head`: the reader is gone, nothing left to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except OSError as error:
        where = ' %s:' % error.filename if getattr(error, 'filename', None) else ''
        sys.stderr.write('%s: error:%s %s\n' % (prog, where, _one_line(error.strerror or error)))
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        sys.stderr.write('%s: interrupted\n' % prog)
        return EXIT_INTERRUPTED
