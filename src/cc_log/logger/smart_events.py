"""What the smart logger says about its logging windows (``SmartLogger.on_event``): ``Event`` (its kinds:
``base.event_kinds``, the writer's and the node's too), and the writer's events (``window_writer``) said as
Events. Pure."""
import collections
import math
import os
import threading

from cc_log.base import safe_input, why
from cc_log.base.event_kinds import DELETED, WRITTEN, SPLIT
from cc_log.storage import log_format

__all__ = ['Event', 'Stats', 'from_writer', 'reason_text', 'WindowTally']

Event = collections.namedtuple(
    'Event', 'kind stamp reason score threshold start end messages path bytes error trigger why copy',
    defaults=('', (), False))
Event.__doc__ = """What happened to a logging window.

kind (``base.event_kinds``): OPENED (a trigger opened a window), WRITTEN (the window file is on disk), FAILED
(writing it failed; ``error`` says why: once when a disk problem first keeps the window in memory to be
retried, and again if it is lost for good), SPLIT (``path``, a file of a window still being written, was
finished at split_mb: the window goes on in the next; start, end, messages: of the part that began it) or
DELETED (``path``, an old window file, was deleted to stay within max_disk_mb; stamp, start and end are None).
stamp: of the message that triggered (the first trigger of the window for WRITTEN and FAILED). trigger: the name
of that trigger ('classifier', 'manual', a rule's name...); reason: its reason ('classifier' for classifiers, a
rule's condition, a manual request's text); score: the lowest classifier score of the window's triggers (NaN
when none); threshold: of the classifier that fired (else of the first classifier; NaN without one). start, end:
header stamps (float s) of the first and last message (end is None for OPENED). messages, path, bytes: the
window's message count (all topics), file and size on disk (0, '' and 0 until WRITTEN). why: the features that
stood out when that trigger fired (``base.why``; () when it says none). copy: the file is a ``copy`` route's
(``base.routes``): its messages are in the window's own file too."""


def from_writer(event, threshold_of):
    """A ``window_writer`` event as an Event; ``threshold_of(trigger name)``: the threshold to report (the name
    is None for DELETED)."""
    if event.kind == DELETED:
        return Event(DELETED, None, 'max_disk_mb', float('nan'), threshold_of(None), None, None, 0, event.path,
                     0, event.error)
    window, metadata = event.job.window, event.job.metadata
    scores = [t.score for t in window.triggers if t.score is not None and not math.isnan(t.score)]
    start, end = (window.start, window.end) if len(window) else (None, None)  # (the end of a window in parts)
    first = window.triggers[0].stamp if window.triggers else start
    return Event(event.kind, first, metadata['reason'], min(scores) if scores else float('nan'),
                 threshold_of(metadata['trigger']), start, end, len(window), event.path,
                 event.bytes, event.error, metadata['trigger'], window.triggers[0].why if window.triggers else (),
                 bool(metadata.get('copy')))


def reason_text(event):
    """The reason of an Event as the ``AnomalyEvent`` and the log say it: its ``reason``, then the first of its
    ``why`` (``'classifier; why: max yaw rate 4.2 rad/s, 2.3x the most seen in training'``), through
    ``safe_input.printable`` (a reason is a service caller's text: ``~trigger_window``)."""
    first = why.texts(event.why[:1])
    return safe_input.printable('%s; why: %s' % (event.reason, first) if first else event.reason)


class WindowTally(object):
    """The windows a logger wrote, from its events (``SmartLogger.on_event(tally)``): one per window name
    (``log_format.window_key``), whatever its files (routes, parts, splits). ``windows()``: ``[{'name', 'start',
    'end', 'messages', 'files', 'path'}]`` in start order; messages and start/end over all its files (a ``copy``
    route's messages counted once, in the window's own file), ``files`` in ``log_format.file_order``, ``path`` the
    first of them."""

    def __init__(self):
        self._windows = collections.OrderedDict()

    def __call__(self, event):
        if event.kind not in (WRITTEN, SPLIT) or not event.path:
            return
        key = log_format.window_key(event.path)
        window = self._windows.setdefault(key, {'name': os.path.basename(key), 'start': None, 'end': None,
                                                'messages': 0, 'files': []})
        window['files'].append(event.path)
        if event.kind != WRITTEN:  # a split file: its messages are said with the window's last file
            return
        window['messages'] += 0 if event.copy else event.messages
        for name, pick, stamp in (('start', min, event.start), ('end', max, event.end)):
            if stamp is not None:
                window[name] = stamp if window[name] is None else pick(window[name], stamp)

    def windows(self):
        """The windows written so far (see the class)."""
        result = []
        for window in self._windows.values():
            files = sorted(window['files'], key=log_format.file_order)
            result.append(dict(window, files=files, path=files[0]))
        return sorted(result, key=lambda window: (window['start'] is None, window['start'] or 0.0))


class Stats(object):
    """Counters of the smart logger's message path (guarded by one lock); the writer keeps its own."""

    def __init__(self):
        self.lock = threading.Lock()
        self.messages_seen = 0
        self.raw_json_bytes = 0      # row-JSON bytes of every message seen
        self.windows_opened = 0
        self.fires_dropped = 0       # Fires before any driving message (no window to keep yet)
        self.messages_refused = 0    # a message type other than the topic's, or a connection header lacking a key
        self.last_refused = ''
