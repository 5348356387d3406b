"""Window names: one grammar for every file of a window, its name chosen once and reserved in its directory.

A window's *name* is ``PREFIX``, the UTC time of its first stamp and the name of its first trigger
(``base_name``), with ``_<N>`` added when that name is taken in its directory (``reserve_name``:
``<name>.reserved`` created with ``O_EXCL``, so two writers, even in two processes, never share a name; a
``WindowName`` holds it for all the jobs of one window). Every file of the window is that name, then its route
(``+<route>``, ``base.routes``), then its number among that route's files (``.<NNN>``: a window split at
``split_mb`` or written a file per part), then its format's extension (``piece_name``); ``parse_piece``
(``re.fullmatch``) reads it back, and every reader groups files by it (``window_key``), so names sort by time::

    cc_log_20150521T191138.027Z_classifier.bag                  (a window in one file)
    cc_log_20150521T191138.027Z_classifier+numeric.json.xz      (its route numeric)
    cc_log_20150521T191138.027Z_classifier.002.bag              (the second file of a window split at split_mb)
    cc_log_20150521T191138.027Z_classifier+numeric.002.json.xz  (the second part of its route's json-xz files)
    cc_log_20150521T191138.027Z_classifier_1.bag                (another window of that name and time)

Names written before this scheme (``<name>_part2``, ``<name>+numeric_part2``, ``<name>_collect_part1``,
``<name>+numeric_1``) are still read: ``_part<N>`` as the number ``N``. ``prefix`` (default ``PREFIX``; another
from ``~name_prefix``, ``file_prefix``) is a parameter of the functions that make or read a name; those that group
a window's files (``window_key``, ``file_order``, ``split_number``) read any prefix. Pure (the file system only).
"""
import collections
import datetime
import os
import re

from cc_log.base import routes, safe_files, safe_input
from cc_log.storage import formats
from cc_log.storage.window_info import trigger_name

PREFIX = 'cc_log_'  # what every file name begins with (``file_prefix``: another, from ``~name_prefix``)
ANY_PREFIX = None  # ``parse_piece``'s prefix for a name of any prefix
TMP_MARK = safe_files.TMP_MARK
KEPT_MARK = '.unrecovered-'  # a leftover kept after a partial recovery: <final name>.unrecovered-<pid>

#: A window's name and the names of its pieces (one grammar, parsed by ``parse_piece``; ``prefix``: ``PREFIX``,
#: or any for ``ANY_PREFIX``: the shortest that a stamp follows).
#: Legacy pieces (``_part<N>``, ``_collect_part<N>``, ``+<route>_<N>``) are read, never written.
_PIECE = (r'(?P<name>%s(?P<stamp>[0-9]{8}T[0-9]{6}\.[0-9]{3}Z)_(?P<reason>[A-Za-z0-9-]+)(?:_(?P<serial>[0-9]+))?)'
          r'(?:_part(?P<old_part>[0-9]+)(?:_[0-9]+)?)?'
          r'(?:\+(?P<route>[A-Za-z0-9-]{1,40})(?:_part(?P<old_route_part>[0-9]+))?(?:_[0-9]+)?)?'
          r'(?:\.(?P<number>[0-9]{3,}))?'
          r'(?P<recovered>_recovered(?:_[0-9]+)?)?')
_PATTERNS = {}
#: A context-track file's name (``context_track.file_name``, then ``final_names``' number, then recovery's mark).
_CONTEXT = r'%scontext_[0-9]{8}T[0-9]{6}\.[0-9]{3}Z(?:_[0-9]+)?(?:_recovered(?:_[0-9]+)?)?'
_CONTEXTS = {}
_KEPT_PID = re.compile(r'[0-9]+(?:\.[0-9]+)?')  # after a kept leftover's KEPT_MARK: its pid, a number
RESERVED_MARK = '.reserved'  # ``<name>.reserved``: a window's name taken while its pieces are written

Piece = collections.namedtuple('Piece', 'name route number')
Piece.__doc__ = """What a file's name says of it: ``name``, its window's name; ``route``, its route's name (None: the
window's own file); ``number``, its number among the files of that route (a window split at ``split_mb`` or
written a file per part: 1, 2, ...; 0 for a window's only file)."""


def file_prefix(name_prefix, name='name_prefix'):
    """What every file name begins with for ``name_prefix`` (``cc_log``, or ``run`` of rosbag's ``-o /data/run``):
    ``<name_prefix>_``. ValueError('<name>: ...') unless it is a plain part of a file name (no ``/``, no control
    character, not starting with ``.``, at most 100 characters)."""
    if (not isinstance(name_prefix, str) or not name_prefix or name_prefix.startswith('.') or '/' in name_prefix
            or len(name_prefix) > 100 or any(ord(c) < 32 or ord(c) == 127 for c in name_prefix)):
        raise ValueError('%s: %s must be a plain part of a file name (no "/", no control character, not starting '
                         'with ".", at most 100 characters)' % (name, safe_input.brief(name_prefix)))
    return name_prefix + '_'


def _reason_text(window):
    reason = trigger_name(window.triggers[0]) if window.triggers else 'window'
    text = re.sub(r'[^A-Za-z0-9-]+', '-', reason).strip('-')
    return text or 'window'


def base_name(window, prefix=PREFIX):
    """The name proposed for a window: ``<prefix><UTC of its first stamp>_<name of its first trigger>``; the name
    it gets (``reserve_name``) may have ``_<N>`` added, the first free one in its directory. ``prefix``:
    ``file_prefix``'s."""
    moment = datetime.datetime(1970, 1, 1) + datetime.timedelta(seconds=float(window.start))
    stamp = moment.strftime('%Y%m%dT%H%M%S.') + '%03dZ' % (moment.microsecond // 1000)
    return prefix + stamp + '_' + _reason_text(window)


def piece_name(name, route=None, number=0):
    """The file name (without extension) of a piece of the window ``name``: ``<name>[+<route>][.<number>]``."""
    return name + (routes.SEPARATOR + route if route else '') + (split_suffix(number) if number else '')


def split_suffix(number):
    """What follows a window's name (and route) in the name of its file ``number`` (1, 2, ...): ``.002``."""
    return '.%03d' % number


def parse_piece(name, prefix=PREFIX):
    """The ``Piece`` a file name (with or without its format's extension) names, or None for a name that is
    not a cc_log window piece of ``prefix`` (``ANY_PREFIX``: of any; ``re.fullmatch``: nothing may follow, not even
    a newline)."""
    pattern = _PATTERNS.get(prefix)
    if pattern is None:
        pattern = _PATTERNS[prefix] = re.compile(_PIECE % ('.*?' if prefix is ANY_PREFIX else re.escape(prefix)))
    match = pattern.fullmatch(_stem(name))
    if match is None:
        return None
    number = match.group('number') or match.group('old_part') or match.group('old_route_part') or 0
    return Piece(match.group('name'), match.group('route'), int(number))


def own_name(name, prefix=PREFIX):
    """Whether ``name`` (a file name with its format's extension; ``<final name>.unrecovered-<pid>[.<n>]`` too, a
    kept leftover) is one cc_log gives: a window's piece (``parse_piece``) or a context-track file
    (``<prefix>context_<UTC>``, numbered or recovered) of ``prefix``. What a quota may count and delete."""
    final, kept, pid = name.partition(KEPT_MARK)
    if TMP_MARK in final or formats.by_extension(final) is None or (kept and not _KEPT_PID.fullmatch(pid)):
        return False
    pattern = _CONTEXTS.get(prefix)
    if pattern is None:
        pattern = _CONTEXTS[prefix] = re.compile(_CONTEXT % re.escape(prefix))
    return parse_piece(final, prefix) is not None or pattern.fullmatch(_stem(final)) is not None


def _stem(name):
    module = formats.by_extension(name)
    return name[:-len(module.EXTENSION)] if module else name


def split_number(path):
    """The number of a window's file among those of its route (``<name>.002.bag``: 2); 0 for a window's only
    file."""
    piece = parse_piece(os.path.basename(path), ANY_PREFIX)
    return piece.number if piece else 0


def file_order(path):
    """Where a file goes among its window's (``window_sets``): the window's own first, then each route, each
    of them by number."""
    piece = parse_piece(os.path.basename(path), ANY_PREFIX)
    if piece is None:
        return (False, '', 0)
    return (piece.route is not None, piece.route or '', piece.number)


def window_key(path):
    """What the files of one window share: its directory and name (``parse_piece``, of any prefix); a file whose
    name is not a window piece's is a window of its own (its path without extension)."""
    directory, name = os.path.split(path)
    piece = parse_piece(name, ANY_PREFIX)
    return os.path.join(directory, piece.name if piece else _stem(name))


def reserve_name(directory, proposed, prefix=PREFIX):
    """Take the first free name of ``proposed``, ``proposed_1``, ``proposed_2``, ... in ``directory``: its
    ``<name>.reserved`` created (``O_EXCL``: one writer wins, in any process), then no other file holding that
    name (``prefix``: of the names). Returns ``(name, path of the reservation)``; ``release_name`` removes it once
    the window's pieces are written. OSError when the directory cannot be written."""
    safe_files.make_dirs(directory)
    for candidate in final_names(directory, proposed, ''):
        name = os.path.basename(candidate)
        reservation = candidate + RESERVED_MARK
        try:
            fd = safe_files.create(reservation)
        except FileExistsError:
            continue
        try:
            os.write(fd, b'%d\n' % os.getpid())  # whose it is: ``recovery`` removes one of a process gone
        except OSError:
            pass  # a full disk: the empty file reserves the name as well (an inode, no data block)
        finally:
            os.close(fd)
        if not _held_by_others(directory, name, prefix):
            return name, reservation
        release_name(reservation)


def _held_by_others(directory, name, prefix=PREFIX):
    """Whether a file of ``directory`` other than ``name``'s reservation holds the window name ``name``."""
    for entry in os.listdir(directory):
        if not entry.startswith(name) or entry == name + RESERVED_MARK:  # (cheap first: a directory may be long)
            continue
        for mark in (TMP_MARK, KEPT_MARK):
            entry = entry.split(mark, 1)[0]
        piece = parse_piece(entry, prefix)
        if piece is not None and piece.name == name:
            return True
    return False


def reservations(directory, prefix=PREFIX):
    """``[(path, pid or None)]`` of the names of ``prefix`` reserved in ``directory`` (``reserve_name``), sorted
    (pid None: the file says none, written on a full disk)."""
    try:
        names = sorted(name for name in os.listdir(directory)
                       if name.startswith(prefix) and name.endswith(RESERVED_MARK))
    except OSError:
        return []
    found = []
    for name in names:
        path = os.path.join(directory, name)
        try:
            with open(path, 'rb') as stream:
                text = stream.read(32).strip()
        except OSError:
            continue
        found.append((path, safe_files.pid_of(text)))
    return found


def release_name(reservation):
    """Remove a name's reservation (``reserve_name``); the pieces written keep the name taken."""
    try:
        os.unlink(reservation)
    except FileNotFoundError:
        pass


class WindowName(object):
    """The name of one window, shared by every job of it (its parts, its routes): ``proposed`` (None: the
    ``base_name`` of its first job's window, with ``prefix``) until ``take`` reserves it in a directory
    (``reserve_name``) on the first piece's write; ``release`` once its last piece is written."""

    __slots__ = ('proposed', 'name', 'reservation', 'prefix')

    def __init__(self, proposed=None, name=None, prefix=PREFIX):
        self.proposed, self.name, self.reservation, self.prefix = proposed, name, None, prefix

    def take(self, directory, window):
        """The window's name, reserved now if it was not yet."""
        if self.name is None:
            self.name, self.reservation = reserve_name(directory, self.proposed or base_name(window, self.prefix),
                                                       self.prefix)
        return self.name

    def release(self):
        """Give up the reservation (idempotent)."""
        if self.reservation is not None:
            release_name(self.reservation)
            self.reservation = None


def final_names(directory, base, extension):
    """The names a window file may take, in order: ``base + extension``, then ``base_1``, ``base_2``, ... (each
    inside ``directory``: ``safe_files.inside``, ValueError otherwise)."""
    counter = 0
    while True:
        yield safe_files.inside(directory, base + ('_%d' % counter if counter else '') + extension, 'window')
        counter += 1
