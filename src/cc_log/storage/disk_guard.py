"""Disk limits of a logging directory: a quota for cc_log's window files and a floor of free space.

``DiskGuard(directory, max_disk_mb, min_free_mb, max_files=0, prefix=log_format.PREFIX)`` (MB = 10^6 bytes; 0
turns a limit off):

- ``max_disk_mb``: after each window file is written, ``enforce_quota(keep=path)`` deletes the *oldest*
  cc_log window files (regular files whose final names are of cc_log's grammar only, ``window_names.own_name``:
  never a link, which is neither followed nor counted; oldest by the time they
  were written, ``st_mtime_ns``, ties by name: not by the message stamps in their names, which jump back
  with a bag replayed or a simulation reset) until the files of the directory fit the quota. The file just
  written is never deleted, so the newest window is kept even when it alone is larger than the quota.
  When a write finds too little space, ``enforce_quota(reserve=bytes)`` makes room for the next file the
  same way (oldest first) until the files and ``reserve`` fit the quota. Nothing else in the directory is
  ever deleted: not other files, not crash leftovers (``*.tmp-*``), not feature vectors. A file counts the bytes
  allocated to it (``st_blocks``), not its apparent size: a sparse file of a terabyte costs what it holds. A file
  deleted that this guard was not told of (``keep``, ``wrote``: a file of another run, or one put there) is counted
  in ``foreign_deleted`` and listed in ``last_foreign``, so the deletion can say so.
- ``max_files`` (rosbag record's ``--max-splits``): the same quota in files: ``enforce_quota`` also deletes the
  oldest until at most ``max_files`` are left (the file just written kept).
- ``prefix``: what the names of the files counted begin with (``log_format.file_prefix``; ``~name_prefix``):
  files of another prefix are neither counted nor deleted.
- ``min_free_mb``: ``check()`` says whether writing may go on: ``False`` while the file system holds less
  than ``min_free_mb`` free. The caller then keeps windows in memory (bounded) and tries again later;
  writing resumes by itself once space returns.

``is_retryable(error)``: whether an OSError from a write is worth retrying later (disk full, quota,
permissions, read-only, I/O errors, directory gone) rather than a bug; ``is_out_of_space(error)``: whether
it says the disk (or the user's disk quota) is full.

Pure (os only); ``statvfs`` can be replaced for tests.
"""
import errno
import os
import stat

from cc_log.base import safe_files
from cc_log.storage import log_format, window_names

__all__ = ['DiskGuard', 'MB', 'is_retryable', 'is_out_of_space', 'allocated_bytes', 'RETRYABLE_ERRNOS']

MB = 1000 ** 2
RETRYABLE_ERRNOS = frozenset(getattr(errno, name) for name in (
    'ENOSPC', 'EDQUOT', 'EACCES', 'EPERM', 'EROFS', 'EIO', 'ENOENT', 'ENOTDIR', 'EEXIST', 'EAGAIN', 'EINTR',
    'EMFILE', 'ENFILE', 'ENOMEM', 'EBUSY', 'ESTALE') if hasattr(errno, name))
_OUT_OF_SPACE = frozenset(getattr(errno, name) for name in ('ENOSPC', 'EDQUOT') if hasattr(errno, name))


def is_retryable(error):
    """True for an OSError that may go away (disk full, permissions, read-only or missing directory...)."""
    return isinstance(error, OSError) and (error.errno in RETRYABLE_ERRNOS or error.errno is None)


def is_out_of_space(error):
    """True for an OSError saying the file system (or the user's disk quota) is full."""
    return isinstance(error, OSError) and error.errno in _OUT_OF_SPACE


def allocated_bytes(status):
    """The bytes a file holds on disk (``os.lstat``'s ``st_blocks``, 512-byte units), not its apparent size."""
    return status.st_blocks * 512


def _limit(value, name):
    try:
        number = float(value or 0)
    except (TypeError, ValueError):
        raise ValueError('%s: %r is not a number of MB' % (name, value))
    if not number >= 0 or number == float('inf'):
        raise ValueError('%s: %r must be a number >= 0 (0: no limit)' % (name, value))
    return int(number * MB)


class DiskGuard(object):
    """Quota and free-space floor of one logging directory (see the module docstring).

    Counters: ``deleted`` (files deleted by the quota), ``deleted_bytes``, ``last_deleted`` (path),
    ``foreign_deleted`` (of them, files not written by this guard's writer: ``written_here``); ``paused`` (the
    last ``check`` found too little free space).
    """

    def __init__(self, directory, max_disk_mb=0, min_free_mb=0, statvfs=os.statvfs, max_files=0,
                 prefix=log_format.PREFIX):
        self.directory = str(directory)
        self.prefix = prefix
        self.directories = [self.directory]  # the quota counts the cc_log files of each (add the context track's)
        self.max_bytes = _limit(max_disk_mb, 'max_disk_mb')
        self.min_free_bytes = _limit(min_free_mb, 'min_free_mb')
        if isinstance(max_files, bool) or not isinstance(max_files, int) or max_files < 0:
            raise ValueError('max_files: %r must be a whole number >= 0 (0: no limit)' % (max_files,))
        self.max_files = max_files
        self._statvfs = statvfs
        self.deleted = 0
        self.deleted_bytes = 0
        self.last_deleted = ''
        self.foreign_deleted = 0
        self.last_foreign = []  # the paths of the last ``enforce_quota`` that this guard's writer did not write
        self.paused = False
        self._written = set()  # absolute paths of the files written by this guard's writer (``wrote``, ``share``)

    @property
    def active(self):
        """Whether any limit is set."""
        return bool(self.max_bytes or self.min_free_bytes or self.max_files)

    @property
    def has_quota(self):
        """Whether ``enforce_quota`` may delete files (``max_disk_mb`` or ``max_files``)."""
        return bool(self.max_bytes or self.max_files)

    def quota_text(self):
        """The quota in words: ``max_disk_mb 500``, ``max_files 3`` or both."""
        return ' and '.join(text for text, value in (('max_disk_mb %g' % (self.max_bytes / float(MB)),
                                                      self.max_bytes), ('max_files %d' % self.max_files,
                                                                        self.max_files)) if value)

    def free(self):
        """Bytes free for an unprivileged user on the directory's file system (None if unknown)."""
        try:
            status = self._statvfs(self.directory)
        except OSError:
            return None
        return status.f_bavail * status.f_frsize

    def window_files(self):
        """``(path, bytes)`` of the files the quota counts, oldest written first (``st_mtime_ns``, ties by name):
        the cc_log window files (final names only) and the leftovers a partial recovery kept
        (``*.unrecovered-<pid>``), which are as old as the crash that left them; regular files of cc_log's names
        only (``window_names.own_name``; a link is never followed), bytes as allocated (``allocated_bytes``)."""
        files = []
        for directory in self.directories:
            for name in map(os.path.basename, log_format.window_files(directory, self.prefix) +
                            log_format.kept_leftovers(directory, self.prefix)):
                if not window_names.own_name(name, self.prefix):
                    continue
                try:
                    path = safe_files.inside(directory, name, 'quota')
                    status = os.lstat(path)
                except (OSError, ValueError):
                    continue
                if stat.S_ISREG(status.st_mode):
                    files.append((status.st_mtime_ns, path, allocated_bytes(status)))
        files.sort()
        return [(path, size) for _, path, size in files]

    def usage(self):
        """Bytes of the files the quota counts (``window_files``)."""
        return sum(size for _, size in self.window_files())

    def wrote(self, path):
        """``path`` was written by this guard's writer (``enforce_quota`` notes its ``keep`` so)."""
        self._written.add(os.path.abspath(path))

    def share(self, other):
        """One quota for this guard's writer and ``other``'s (the context track's): each counts the other's
        directory, and a file either wrote is written here for both."""
        self.directories.append(other.directory)
        other.directories.append(self.directory)
        other._written = self._written

    def written_here(self, path):
        """Whether ``path`` was written by this guard's writer (``wrote``); False for a file of another run or one
        put in the directory by something else."""
        return os.path.abspath(path) in self._written

    def check(self):
        """``(True, '')`` when writing may go on, else ``(False, why)``; sets ``paused``."""
        if not self.min_free_bytes:
            self.paused = False
            return True, ''
        free = self.free()
        if free is not None and free < self.min_free_bytes:
            self.paused = True
            return False, ('%.1f MB free on %s, below min_free_mb %g: writing paused'
                           % (free / float(MB), self.directory, self.min_free_bytes / float(MB)))
        self.paused = False
        return True, ''

    def enforce_quota(self, keep=(), reserve=0):
        """Delete the oldest window files (by time written) until the rest, plus ``reserve`` bytes still to
        be written, fit ``max_disk_mb`` and they are at most ``max_files``; never the paths in ``keep`` (a path
        or a list: files just written, noted as this writer's, ``wrote``). Returns the deleted paths (oldest first);
        those not written by this guard's writer are also in ``last_foreign``."""
        if not self.has_quota:
            return []
        keep = {keep} if isinstance(keep, str) else set(keep)
        keep = {os.path.abspath(path) for path in keep}
        self.last_foreign = []
        for path in keep:
            self.wrote(path)
        files = self.window_files()
        limit = max(0, self.max_bytes - max(0, int(reserve))) if self.max_bytes else float('inf')
        total, count = sum(size for _, size in files), len(files)
        deleted = []
        for path, size in files:  # oldest first
            if total <= limit and (not self.max_files or count <= self.max_files):
                break
            if os.path.abspath(path) in keep:
                continue
            try:
                os.unlink(path)  # (a path of ``window_files``: through ``safe_files.inside``)
            except FileNotFoundError:
                total, count = total - size, count - 1
                continue
            except OSError:
                continue
            total, count = total - size, count - 1
            deleted.append(path)
            self.deleted += 1
            self.deleted_bytes += size
            self.last_deleted = path
            if self.written_here(path):
                self._written.discard(os.path.abspath(path))
            else:
                self.foreign_deleted += 1
                self.last_foreign.append(path)
        return deleted
