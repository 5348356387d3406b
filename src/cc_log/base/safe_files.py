"""Every file and directory cc_log creates: never through a link, never over another file, never world-writable.

- ``create(path)``: a new file, ``O_CREAT|O_EXCL|O_NOFOLLOW``: a file or a (planted) symbolic link at ``path``
  makes it fail with FileExistsError instead of writing where the link points.
- ``AtomicFile``: a file written under ``<path>.tmp-<pid>`` (created as above), flushed, fsynced and only then
  given its final name, so a file under a final name is always complete. Without ``overwrite`` it takes the
  first free name of ``names`` by hard link then unlink (never overwriting, even a file another process
  creates meanwhile); with ``overwrite`` it replaces ``path`` by rename (a file or link at ``path`` is
  replaced, never written through). The directory is fsynced. On any error the temporary file is removed
  and every descriptor closed.
- ``inside(root, name)``: the one guard of every path cc_log writes or deletes: ``name`` (a relative path)
  joined under ``root``, or ValueError when it would leave it (``..``, an absolute name, a link to a directory
  inside ``root``).
- ``make_dirs(path)``: the missing directories of ``path`` (parents too), each set to 2775 through an
  ``O_NOFOLLOW`` descriptor: group-writable, setgid so files inherit the group, never world-writable.

Modes: files 0664, directories 2775 whatever the umask (as BWI's logger makes them under umask 002: a lab's
users can all read and clean the logs), except that the umask may take the world-read bits; the world-write
bit is never set, even under umask 0. Existing directories are left as they are.
"""
import errno
import os
import re
import stat

FILE_MODE = 0o664
DIR_MODE = 0o2775
TMP_MARK = '.tmp-'
PID_MAX = 1 << 22  # Linux's PID_MAX_LIMIT: no process id is larger
_PID = re.compile(r'[0-9]{1,7}')
_TRIES = 100  # temporary names tried when some are taken (a leftover, a planted link)
_NO_HARD_LINKS = (errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EXDEV, errno.EMLINK)


def pid_of(text):
    """The process id a file's name or content gives (``'4242'`` of ``*.tmp-4242``, a reservation's text; str or
    bytes), or None when it names no process (not decimal digits, 0, above ``PID_MAX``): no writer of it runs."""
    if isinstance(text, (bytes, bytearray)):
        text = bytes(text).decode('ascii', 'replace')
    text = text.strip()
    pid = int(text) if _PID.fullmatch(text) else 0
    return pid if 0 < pid <= PID_MAX else None


def writer_running(pid):
    """Whether ``pid`` (``pid_of``'s; None: no process) is a running process other than this one."""
    if pid is None or pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except OSError as error:
        return error.errno == errno.EPERM
    return True


def _group_writable(fd, mode):
    """fchmod ``fd`` to ``mode``'s owner, group and special bits (setgid), whatever the umask took from them
    (so a lab's users can all read and clean the logs, as BWI's logger under umask 002), with the world bits
    the umask left, never world-write."""
    current = stat.S_IMODE(os.fstat(fd).st_mode)
    wanted = (mode & 0o7770) | (current & 0o005)
    if wanted != current:
        os.fchmod(fd, wanted)


def inside(root, name, what='path', directory=False):
    """The path of ``name`` inside the directory ``root``: ``root`` joined with the parts of ``name`` (split at
    ``/``), each a plain name (not empty, not ``.`` or ``..``, no NUL) and none but the last an existing symbolic
    link (``root`` itself may be one: it is the caller's choice, followed as given; nothing inside it is: a link at
    the last part is a name the writers replace, never write through (``create``, ``AtomicFile``), and ``unlink``
    removes the link itself; ``directory``: the path is a directory to write in, so not a link either). So the
    path stays inside ``root`` resolved once, whatever the name (a bag's, a topic's, a label).
    ValueError('<what>: <name> is outside <root>') otherwise."""
    text = os.fspath(name)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    parts = text.split('/')
    try:
        os.fsencode(text)
        plain = bool(text) and '\0' not in text and not any(part in ('', '.', '..') for part in parts)
    except UnicodeError:
        plain = False
    path = os.fspath(root)
    for part in (parts if directory else parts[:-1]) if plain else ():
        path = os.path.join(path, part)
        if os.path.islink(path):
            plain = False
            break
    if plain and not directory:
        path = os.path.join(path, parts[-1])
    if not plain:
        raise ValueError('%s: %r is outside %s' % (what, text, os.fspath(root)))
    return path


def create(path, mode=FILE_MODE):
    """Create the new file ``path`` for reading and writing; return its descriptor. FileExistsError when anything (a
    file, a link, even a dangling one) is there already."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, mode)
    try:
        _group_writable(fd, mode)
    except BaseException:
        os.close(fd)
        raise
    return fd


def make_dirs(path, mode=DIR_MODE):
    """Create directory ``path`` and its missing parents (2775, the umask taking world bits only); return
    ``path``. OSError when a part of it exists and is not a directory."""
    missing = []
    head = os.path.abspath(path)
    while not os.path.isdir(head):
        missing.append(head)
        parent = os.path.dirname(head)
        if parent == head:
            break
        head = parent
    for folder in reversed(missing):
        try:
            os.mkdir(folder, mode & 0o777)
        except FileExistsError:
            if os.path.isdir(folder):
                continue  # made meanwhile by someone else: theirs, left as it is
            raise
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
        try:
            _group_writable(fd, mode)
        finally:
            os.close(fd)
    return path


def fsync_directory(directory):
    """fsync a directory so that names given in it survive a power cut (no-op where unsupported or not
    readable)."""
    try:
        fd = os.open(directory or '.', os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except PermissionError:
        return
    try:
        os.fsync(fd)
    except OSError as error:
        if error.errno != errno.EINVAL:
            raise
    finally:
        os.close(fd)


def publish(tmp, names):
    """Give the file ``tmp`` the first name of ``names`` (paths in its directory) that does not exist; never
    overwrite anything; return that name. ``tmp`` loses its own name."""
    for final in names:
        if os.path.lexists(final):
            continue
        try:
            os.link(tmp, final, follow_symlinks=False)
        except FileExistsError:
            continue
        except OSError as error:
            if error.errno not in _NO_HARD_LINKS:
                raise
            os.rename(tmp, final)  # no hard links on this file system: the name was free just above
            return final
        os.unlink(tmp)
        return final
    raise FileExistsError(errno.EEXIST, 'no free name', tmp)


class AtomicFile(object):
    """``with AtomicFile(path) as stream: stream.write(...)``; afterwards ``.path`` is the final path and
    ``.size`` its size in bytes.

    ``names``: the final names to try in order (default: ``path`` alone); ``overwrite``: replace ``path``
    (by rename) instead; ``text``/``newline``: a text stream (UTF-8) instead of a binary one. The stream may be
    closed inside the block (rosbag closes the file it is given). ``keep``: a temporary file that cannot be
    published is left where it is (a leftover for ``recovery``) instead of removed: for a file written over a
    long time whose bytes are no longer held anywhere else.
    """

    def __init__(self, path, names=None, overwrite=False, text=False, newline=None, keep=False):
        self.path = path
        self.size = None
        self.tmp = None
        self._names = names
        self._overwrite = overwrite
        self._text = text
        self._newline = newline
        self._keep = keep
        self._fd = None
        self.stream = None

    def __enter__(self):
        for attempt in range(_TRIES):
            tmp = '%s%s%d%s' % (self.path, TMP_MARK, os.getpid(), '.%d' % attempt if attempt else '')
            try:
                self._fd = create(tmp)
            except FileExistsError:
                continue
            self.tmp = tmp
            break
        else:
            raise FileExistsError(errno.EEXIST, 'every temporary name is taken', self.tmp or self.path)
        try:
            if self._text:
                self.stream = os.fdopen(os.dup(self._fd), 'w', encoding='utf-8', newline=self._newline)
            else:
                self.stream = os.fdopen(os.dup(self._fd), 'w+b')
        except BaseException:
            self._discard()
            raise
        return self.stream

    def abandon(self):
        """Give up writing: close the file and leave it under its temporary name (a leftover for ``recovery``)."""
        try:
            self.stream.close()
        except OSError:
            pass
        self._release()

    def _release(self):
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def _discard(self):
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if os.path.lexists(self.tmp):
            os.unlink(self.tmp)

    def __exit__(self, kind, value, traceback):
        try:
            try:
                self.stream.close()  # flushes what is buffered
            except Exception:
                if kind is None:
                    raise
            if kind is None:
                os.fsync(self._fd)
                self.size = os.fstat(self._fd).st_size
                os.close(self._fd)
                self._fd = None
                if self._overwrite:
                    os.rename(self.tmp, self.path)
                else:
                    self.path = publish(self.tmp, self._names or [self.path])
        except BaseException:
            if self._keep:
                self._release()
            else:
                self._discard()
            raise
        if kind is not None:
            self._discard()
            return False
        fsync_directory(os.path.dirname(self.path))
        return False
