"""Ground truth of the simulated and injected anomalies.

Ground truth is a list of dicts ``{'type', 'start', 'end'}``: the messages changed by an anomaly are those
with ``start <= stamp < end``; ``end`` is the stamp of the first nominal message after it (the message
whose difference to its predecessor still shows the end of the anomaly, e.g. the jump back). The simulator
announces each anomaly on ``/sim/anomaly`` (``truth_event``); a bag's truth is kept in a JSON sidecar file
next to it (``truth_path``, ``write_truth``, ``load_truth``; its format tag is ``TRUTH_FORMAT``).
"""
import collections
import json

from std_msgs.msg import String

from cc_log.base.safe_files import AtomicFile
from cc_log.sim.messages import ODOM_TOPIC

TRUTH_FORMAT = 'cc_log.sim.truth/1'


def truth_entry(kind, start, end):
    """One anomaly of the ground truth: {'type', 'start', 'end'} (``end`` None while it lasts)."""
    return collections.OrderedDict((('type', kind), ('start', start), ('end', end)))


def truth_event(event, entry):
    """The std_msgs/String (JSON) announcing that an anomaly started ('start', end null) or ended ('end')."""
    data = collections.OrderedDict((('event', event), ('type', entry['type']), ('start', entry['start']),
                                    ('end', entry['end'] if event == 'end' else None)))
    return String(data=json.dumps(data))


def truth_path(bag_path):
    """The sidecar ground-truth file of a bag: ``<bag>.truth.json``."""
    return bag_path + '.truth.json'


def _atomic_write(path, data):
    with AtomicFile(path, overwrite=True) as stream:
        stream.write(data)


def write_truth(path, truth, topic=ODOM_TOPIC, config=None, source='cc_log.sim'):
    """Write a ground-truth sidecar: {"format", "source", "topic", "config", "anomalies": [...]}."""
    document = collections.OrderedDict((
        ('format', TRUTH_FORMAT), ('source', source), ('topic', topic),
        ('config', config.to_dict() if hasattr(config, 'to_dict') else config),
        ('anomalies', [truth_entry(e['type'], e['start'], e['end']) for e in truth])))
    _atomic_write(path, (json.dumps(document, indent=1) + '\n').encode('utf-8'))
    return path


def load_truth(path):
    """The anomalies of a ground-truth sidecar (or of a bare JSON list): [{'type', 'start', 'end'}]."""
    with open(path) as stream:
        document = json.load(stream)
    entries = document['anomalies'] if isinstance(document, dict) else document
    return [truth_entry(e['type'], float(e['start']), float(e['end'])) for e in entries]
