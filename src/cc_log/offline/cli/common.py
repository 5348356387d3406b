"""What the ``cclog`` commands share: exit statuses, CommandError, output helpers, argparse types and
flags, reading window files, and running a command over many bags (fleet)."""
import argparse
import collections
import json
import math
import os
import sys
import textwrap

from cc_log.base.safe_input import printable
from cc_log.offline import export
from cc_log.offline.progress import bar as _bar
from cc_log.base.errors import CommandError

PROG = 'cclog'
EXIT_OK = 0
EXIT_BAD_INPUT = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
INTERRUPT_GRACE = 0.5  # seconds Ctrl-C leaves a command to finish what it is writing before it stops anyway


# -- output -----------------------------------------------------------------------------------------------

plain = export.plain


def print_json(document):
    """``document`` as one line of JSON on stdout."""
    sys.stdout.write(json.dumps(plain(document), allow_nan=False, sort_keys=False) + '\n')


def say(text):
    """Print a line of a report made of names read from files (see ``printable``)."""
    print(printable(text))


def human_bytes(count):
    """``1536`` -> ``'1.5 kB'`` (powers of 1000, as in the paper's tables)."""
    count = float(count)
    for unit in ('B', 'kB', 'MB', 'GB'):
        if abs(count) < 1000 or unit == 'GB':
            return ('%d %s' % (count, unit)) if unit == 'B' else ('%.1f %s' % (count, unit))
        count /= 1000.0


def size_ratio(raw, stored):
    """How many times smaller ``stored`` bytes are than ``raw`` (None for nothing stored)."""
    return float(raw) / stored if stored else None


def stamp_text(stamp):
    """A stamp as seconds with milliseconds, or ``-``."""
    return '%.3f' % stamp if stamp is not None else '-'


def existing_file(path, what='file'):
    """``path``; CommandError when it does not exist or is a directory."""
    if not os.path.exists(path):
        raise CommandError('%s: no such %s' % (path, what))
    if os.path.isdir(path):
        raise CommandError('%s: is a directory, not a %s' % (path, what))
    return path


def writable_dir(path, name):
    """Create directory ``path`` if needed; CommandError('<name>: ...') when that is impossible."""
    from cc_log.base import safe_files
    if os.path.exists(path) and not os.path.isdir(path):
        raise CommandError('%s: %s exists and is not a directory' % (name, path))
    try:
        safe_files.make_dirs(path)
    except OSError as error:
        raise CommandError('%s: cannot create %s (%s)' % (name, path, error.strerror or error))
    return path


def parent_exists(path, name):
    """``path``; CommandError('<name>: ...') when the directory it would be written in does not exist."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CommandError('%s: directory %s does not exist' % (name, folder))
    return path


def span(name):
    """argparse type for a count (``500``) or a duration (``5s``) checked by Span.parse."""
    def parse(value):
        from cc_log.base.spans import Span
        try:
            Span.parse(value, name)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error))
        return value
    parse.__name__ = name
    return parse


def spans(name):
    """argparse type for a comma-separated list of counts or durations (``1s,2s,5s``), each checked by Span.parse."""
    single = span(name)

    def parse(value):
        return [single(item.strip()) for item in value.split(',')]
    parse.__name__ = name
    return parse


def positive_float(name, zero=False):
    """argparse type for a finite number > 0 (>= 0 with ``zero``)."""
    def parse(value):
        try:
            number = float(value)
        except ValueError:
            number = float('nan')
        if not (math.isfinite(number) and (number >= 0 if zero else number > 0)):
            kind = 'non-negative' if zero else 'positive'
            raise argparse.ArgumentTypeError('%s: %r must be a %s number' % (name, value, kind))
        return number
    parse.__name__ = name
    return parse


def non_negative_int(name, minimum=0):
    """argparse type for a whole number >= ``minimum``."""
    def parse(value):
        try:
            number = int(value)
        except ValueError:
            raise argparse.ArgumentTypeError('%s: %r is not a whole number' % (name, value))
        if number < minimum:
            raise argparse.ArgumentTypeError('%s: %r must be at least %d' % (name, value, minimum))
        return number
    parse.__name__ = name
    return parse


# -- parsers ----------------------------------------------------------------------------------------------

class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``cclog replay: error: ... (see cclog replay --help)``, status 2."""

    def error(self, message):
        self.exit(EXIT_USAGE, '%s: error: %s (see %s --help)\n' % (self.prog, message, self.prog))


def command_help(summary, description, examples):
    """Keyword arguments of a parser: its line in ``cclog --help`` (``summary``; None for cclog itself), its
    description and its examples."""
    options = dict(description=textwrap.dedent(description).strip(),
                   epilog='examples:\n' + textwrap.indent(textwrap.dedent(examples).strip('\n'), '  '),
                   formatter_class=argparse.RawDescriptionHelpFormatter)
    if summary is not None:
        options['help'] = summary
    return options


def output_flags(parser, json_help=True):
    """--json (unless ``json_help`` is false) and --progress / --no-progress, the last flags of every command."""
    if json_help:
        parser.add_argument('--json', action='store_true', help='print one JSON object on stdout')
    group = parser.add_mutually_exclusive_group()
    group.add_argument('--progress', dest='progress', action='store_true', default=None,
                       help='progress bar on stderr even when it is not a terminal')
    group.add_argument('--no-progress', dest='progress', action='store_false',
                       help='no progress bar, even on a terminal')


def fleet_flags(parser):
    """--workers and --scheduler of the commands that take many bags."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument('--workers', type=non_negative_int('workers'), metavar='N',
                       help='many bags: a local Dask cluster of N worker processes (default: the cores); 0: run '
                       'every bag in this process')
    group.add_argument('--scheduler', metavar='ADDRESS',
                       help='many bags: the Dask cluster of this scheduler (tcp://host:8786) instead')


def retrigger_modes():
    """The --retrigger choices (``cc_log.triggers.RETRIGGER_MODES``)."""
    from cc_log.triggers import RETRIGGER_MODES
    return RETRIGGER_MODES


# -- reading window files ---------------------------------------------------------------------------------

def named_prefix(path):
    """``(directory, file prefix)`` of a path that is a prefix of file names as rosbag record's ``-o`` takes it
    (``/data/run``: /data and ``run_``, the files of ``record -o /data/run``), or None when ``path`` is not one (it
    exists, or its directory does not, or its name is not a plain part of a file name)."""
    from cc_log.storage import log_format
    directory, part = os.path.split(path)
    if os.path.exists(path) or not part or not os.path.isdir(directory or '.'):
        return None
    try:
        return directory or '.', log_format.file_prefix(part)
    except ValueError:
        return None


def window_paths(paths):
    """Window files named by ``paths`` (files as given; directories: their window files, by time; a prefix as
    ``record -o`` takes it, ``/data/run``: the window files ``/data/run_*``, by time).

    CommandError for a path that does not exist or a directory without window files.
    """
    from cc_log.storage import log_format
    found = []
    for path in paths:
        prefixed = named_prefix(path)
        files = log_format.window_files(*prefixed) if prefixed else []
        if files:
            found.extend(files)
            continue
        if not os.path.exists(path):
            raise CommandError('%s: no such file or directory' % path)
        if os.path.isdir(path):
            files = log_format.window_files(path)
            if not files:
                raise CommandError('%s: no cc_log window files (cc_log_*.json.xz / cc_log_*.bag) in this directory'
                                   % path)
            found.extend(files)
        else:
            found.append(path)
    return found


def read_windows(args, paths, label):
    """Yield ``(path, metadata, records)`` of every window named by ``paths``, with a progress bar: a window
    written as several files (routes) is read as one (``log_format.read_window_set``; ``path``: its own file,
    ``metadata['files']``: all of them)."""
    from cc_log.storage import log_format
    sets = log_format.window_sets(window_paths(paths))
    with _bar(args, label, len(sets)) as bar:
        for files in sets:
            metadata, records = log_format.read_window_set(files)
            yield files[0], metadata, records
            bar.update()


def selected_records(args):
    """All records of the window files named by ``args.paths`` (``--topic`` filter), in stamp order."""
    return selected_windows(args)[0]


def selected_windows(args):
    """``(records, windows)``: ``selected_records`` and the ``(path, metadata)`` of every window read
    (``read_windows``)."""
    topics = set(args.topic) if args.topic else None
    records, windows = [], []
    for path, metadata, window in read_windows(args, args.paths, 'read'):
        records.extend(record for record in window if topics is None or record.topic in topics)
        windows.append((path, metadata))
    records.sort(key=lambda record: record.stamp)
    if not records:
        raise CommandError('topic: no messages of %s in %s' % (', '.join(sorted(topics)), ', '.join(args.paths))
                           if topics else '%s: no messages' % ', '.join(args.paths))
    return records, windows


def driving_topic(args, type_name):
    """``args.topic``, or, when it is not given, the one topic of ``type_name`` in the bag ``args.bag`` (said on
    stderr in one line); CommandError naming the candidates otherwise."""
    if args.topic is not None:
        return args.topic
    from cc_log.storage.bag import bagio
    try:
        bag = bagio.open_bag(args.bag)
        try:
            topic = bagio.only_topic_of_type(bag, type_name)
        finally:
            bag.close()
    except ValueError as error:
        raise CommandError('topic: %s' % error)
    sys.stderr.write("%s %s: driving topic %s (the bag's only %s topic; --topic chooses another)\n"
                     % (PROG, args.command, printable(topic), type_name))
    return topic


def configuration(args, flat):
    """The Config of ``--config`` (if given) with the options of ``flat`` (None: not given) and the single
    classifier of ``--model``/``--topic`` over it."""
    from cc_log.logger import config as config_mod
    data = config_mod.load_file(existing_file(args.config, 'configuration file')) if args.config else {}
    side = flat.pop('side_topics', None)
    classifier = flat.pop('classifier', {})
    data = config_mod.with_flat(data, flat)
    if side:
        topics = data.get('topics') or []
        data['topics'] = (topics.replace(',', ' ').split() if isinstance(topics, str) else list(topics)) + side
    data = config_mod.with_classifier(data, **classifier)
    return config_mod.Config.from_dict(data, args.config or 'options')


# -- many bags (fleet) ------------------------------------------------------------------------------------

def fleet_wanted(args, paths, single_dir=None):
    """True for the fleet path: several inputs, a directory (unless ``single_dir(path)`` says it is one input)
    or a glob, or --workers / --scheduler given."""
    import glob
    return (len(paths) > 1 or glob.has_magic(paths[0]) or args.workers is not None or args.scheduler is not None
            or (os.path.isdir(paths[0]) and not (single_dir and single_dir(paths[0]))))


def fleet_engine(args):
    """The fleet Engine of --workers / --scheduler."""
    from cc_log.offline import fleet
    return fleet.Engine(args.workers, args.scheduler)


def run_fleet(args, label, work):
    """``work(engine, progress)`` -> Outcomes on the engine of --workers / --scheduler with a bar of bags;
    returns ``(outcomes, summary)``; each failed bag is one line on stderr."""
    from cc_log.offline import fleet
    engine = fleet_engine(args)
    interrupt = getattr(args, 'interrupt', None)
    if interrupt is not None and not engine.local:
        interrupt.grace = None  # Ctrl-C: let the cluster close (its workers end) however long it takes
    with engine, _bar(args, label) as bar:
        meter = fleet.Meter(lambda done, total, text: (setattr(bar, 'label', '%s (%s)' % (label, text)),
                                                       bar.set(done, total)))
        outcomes = work(engine, meter.update)
        summary = meter.summary(engine)
    for line in fleet.failures(outcomes):
        sys.stderr.write('%s %s: error: %s\n' % (PROG, label, line))
    return outcomes, summary


def fleet_rows(outcomes, fields):
    """Per bag: ``{'bag', 'directory', <fields of its result>}`` or ``{'bag', 'error'}``."""
    rows = []
    for outcome in outcomes:
        row = collections.OrderedDict([('bag', outcome.item.path), ('directory', outcome.item.out)])
        if outcome.ok:
            row.update((field, outcome.value[field]) for field in fields)
        else:
            row['error'] = outcome.value
        rows.append(row)
    return rows


def fleet_end(args, summary, rows, text):
    """Print the JSON document or the text lines of a fleet run; exit status 1 when a bag failed."""
    failed = sum('error' in row for row in rows)
    summary['bags'] = rows
    summary['failed'] = failed
    if args.json:
        print_json(summary)
    else:
        print('\n'.join(text))
        print('%d bags (%d failed), %d messages in %.1f s: %.0f messages/s (%s)' % (
            len(rows), failed, summary['messages'], summary['seconds'], summary['messages_per_second'],
            summary['engine']))
    return EXIT_BAD_INPUT if failed else EXIT_OK
