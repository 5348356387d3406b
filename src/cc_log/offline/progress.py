"""Progress bars of the ``cclog`` commands on stderr, drawn by tqdm (Debian's ``python3-tqdm``).

``label [#####.....]  50%  1976/3952  00:01`` with a total, ``label  1976  00:01`` without one, and a spinner
``label |  00:01`` for a step with no progress hook (``busy()``). Bars are shown only when stderr is a
terminal or with ``--progress``; a disabled bar costs nothing and writes nothing.
"""
import inspect
import sys
import threading

WITH_TOTAL = '{desc} [{bar:28}] {percentage:3.0f}%  {n_fmt}/{total_fmt}  {elapsed}'
WITHOUT_TOTAL = '{desc}  {n_fmt}  {elapsed}'
SPINNER = '|/-\\'


class Progress(object):
    """A progress bar with ``update(amount)``, ``set(done, total)`` (a ``progress(done, total)`` callback),
    ``busy()`` (a spinner until ``close()``) and a settable ``label``; a context manager that closes it."""

    def __init__(self, label, total=None, enabled=False, stream=None, interval=0.1):
        self.enabled = bool(enabled)
        self.interval = interval
        self._label = label
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = None
        self._spins = 0
        self._bar = None
        if self.enabled:
            from tqdm import tqdm
            self._bar = tqdm(total=total, desc=label, file=stream if stream is not None else sys.stderr,
                             mininterval=interval, ascii='.#', bar_format=_format(total), dynamic_ncols=False)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    @property
    def label(self):
        """The text before the bar."""
        return self._label

    @label.setter
    def label(self, text):
        self._label = text
        if self._bar is not None:
            with self._lock:
                self._bar.set_description_str(text, refresh=False)

    def update(self, amount=1):
        """Count ``amount`` more items done."""
        if self._bar is not None:
            with self._lock:
                self._bar.update(amount)

    def set(self, done, total=None):
        """Set the count (and the total) directly; usable as a ``progress(done, total)`` callback."""
        if self._bar is None:
            return
        with self._lock:
            if total is not None and total != self._bar.total:
                self._bar.total = total
                self._bar.bar_format = _format(total)
            self._bar.update(done - self._bar.n)

    def busy(self):
        """Animate a spinner from a background thread until ``close()`` (work without a progress hook)."""
        if self._bar is not None and self._thread is None:
            self._thread = threading.Thread(target=self._spin, name='cclog progress')
            self._thread.daemon = True
            self._thread.start()
        return self

    def _spin(self):
        while not self._stop.wait(self.interval):
            with self._lock:
                self._spins += 1
                self._bar.bar_format = '{desc} %s  {elapsed}' % SPINNER[self._spins % len(SPINNER)]
                self._bar.refresh()

    def close(self):
        """Stop the spinner, draw the final state and end the line (once)."""
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._thread = None
        if self._bar is not None:
            with self._lock:
                try:
                    self._bar.close()
                except (OSError, ValueError):
                    pass
            self._bar = None


def _format(total):
    return WITH_TOTAL if total else WITHOUT_TOTAL


def wanted(args):
    """``--progress`` / ``--no-progress``, else only when stderr is a terminal."""
    if getattr(args, 'progress', None) is not None:
        return args.progress
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def bar(args, label, total=None):
    """A Progress for a command's parsed ``args`` (enabled as ``wanted`` says)."""
    return Progress(label, total, enabled=wanted(args))


def call(function, progress, *positional, **keywords):
    """Call a library function, passing ``progress=<callback(done, total)>`` when it takes one; else spin."""
    try:
        takes = 'progress' in inspect.signature(function).parameters
    except (TypeError, ValueError):
        takes = False
    if takes:
        keywords['progress'] = progress.set
    else:
        progress.busy()
    return function(*positional, **keywords)
