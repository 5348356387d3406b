"""The records every part of cc_log passes around: a message (``Record``), why a window was kept (``Trigger``) and
a window of records (``LogWindow``)."""
import collections
import itertools

Record = collections.namedtuple('Record', 'stamp topic msg cost raw connection', defaults=(0, None, None))
Record.__doc__ = """One message: its stamp (float seconds), topic, message object and estimated memory in
bytes (``cost``; 0: not known, WindowBuffer estimates it); ``raw`` and ``connection``: its serialized bytes and
connection header (a dict: type, md5sum, message_definition, and live also callerid and latching), alongside
or instead of the decoded ``msg`` (None until something reads a field: ``raw_message.decoded``)."""


def records_of(stamps, topics, msgs, costs, raws, connections):
    """The list of ``Record``s of these columns (iterables, one item per record), built without a Python call per
    record."""
    return list(map(tuple.__new__, itertools.repeat(Record), zip(stamps, topics, msgs, costs, raws, connections)))


Trigger = collections.namedtuple('Trigger', 'stamp reason score name why', defaults=(None, ()))
Trigger.__doc__ = """Why a window was opened or extended: stamp of the message, reason, score (a classifier's; None or
NaN when none), the name of the trigger (None: the reason is the name, as in files written before names) and
``why``: the features that stood out (the Fire's, ``base.why``; () when none)."""


class LogWindow(object):
    """A logging window: records in stamp order and the triggers that opened and extended it.

    A window too long or too large to be held whole is handed on in parts (``part`` 1, 2, ...), all with the
    same ``key``, the last one ``final`` (it may hold no record: the window ended right after a part)."""

    def __init__(self, records, triggers, part=0, final=True, key=None):
        self.records = records
        self.triggers = triggers
        self.part = part    # 0 for a whole window; 1, 2, ... for the parts of a long one
        self.final = final  # the last (or only) part of its window
        self.key = key      # the same for every part of one window (None: not known)

    @property
    def start(self):
        """Stamp of the first record."""
        return self.records[0].stamp

    @property
    def end(self):
        """Stamp of the last record."""
        return self.records[-1].stamp

    @property
    def topics(self):
        """Topics in the window, in order of first appearance."""
        return list(collections.OrderedDict.fromkeys(record.topic for record in self.records))

    def __len__(self):
        return len(self.records)

    def __repr__(self):
        return 'LogWindow(%d records, %.3f..%.3f, %d triggers)' % (
            len(self.records), self.start, self.end, len(self.triggers))
