"""Where window files go: the explicit path, else ``$ROS_HOME/cc_log`` (``~/.ros/cc_log`` without ROS_HOME),
else ``/tmp/cc_log``.

As in the BWI logging nodes, a robot keeps logging when the configured directory cannot be used: the
first directory that can be created and written to wins. ``fallback`` tells the caller to warn.
"""
import os
import tempfile

from cc_log.base import safe_files

TMP_DIRECTORY = os.path.join(tempfile.gettempdir(), 'cc_log')
DIR_MODE = safe_files.DIR_MODE  # group-writable, setgid, never world-writable (parents made too)


def ros_home():
    """ROS's home directory, as ROS decides it (``rospkg.get_ros_home``): ``$ROS_HOME``, else ``~/.ros``."""
    return os.path.abspath(os.path.expanduser(os.environ.get('ROS_HOME') or os.path.join('~', '.ros')))


def cc_log_home(*parts):
    """cc_log's directory in ROS's home (``$ROS_HOME/cc_log``, ``~/.ros/cc_log``), or ``parts`` under it: the
    default window directory, model and demo output."""
    return os.path.join(ros_home(), 'cc_log', *parts)


def _usable(path):
    """None when ``path`` is (made) a writable directory, else why not."""
    try:
        safe_files.make_dirs(path)
        # access() can lie (root, read-only mounts, ACLs): create and remove a file.
        fd, probe = tempfile.mkstemp(prefix='.cc_log-probe-', dir=path)
        os.close(fd)
        os.unlink(probe)
    except OSError as error:
        return error.strerror or str(error)
    return None


class LoggingDirectory(object):
    """The directory window files are written to.

    ``path``: the explicit directory (None or '' for none). ``.path`` is the one chosen, ``.tried`` the
    ``(path, reason)`` pairs that failed before it, ``.fallback`` whether it is not the first candidate.
    Raises OSError naming every path tried when none can be written.
    """

    def __init__(self, path=None):
        candidates = []
        if path:
            candidates.append(os.path.abspath(os.path.expanduser(str(path))))
        for default in (cc_log_home(), TMP_DIRECTORY):
            default = os.path.abspath(default)
            if default not in candidates:
                candidates.append(default)
        self.requested = candidates[0] if path else None
        self.tried = []
        for candidate in candidates:
            reason = _usable(candidate)
            if reason is None:
                self.path = candidate
                self.fallback = candidate != candidates[0]
                return
            self.tried.append((candidate, reason))
        raise OSError('no writable logging directory; tried: %s'
                      % '; '.join('%s (%s)' % (candidate, reason) for candidate, reason in self.tried))

    def __str__(self):
        return self.path

    def __repr__(self):
        return 'LoggingDirectory(%r)' % self.path

    def __fspath__(self):
        return self.path
