"""``cclog replay --sweep``: several configurations of the smart logger over one reading of each bag.

``parse_sweep`` makes every combination of the ``KEY=V1,V2`` values, ``sweep_one`` runs one logger per
configuration over one decoded reading of a bag (windows into ``<out>/<label>/``) and judges the windows against
the bag's truth file when it has one, ``sweep_many`` does it for every bag on a ``fleet.Engine`` and
``sweep_table`` sums the bags per configuration.
"""
import collections
import os

from cc_log.base import safe_files
from cc_log.logger import smart_events
from cc_log.offline import fleet, replay

SWEEP_KEYS = ('threshold', 'pre', 'post', 'classify_every', 'retrigger')

Sweep = collections.namedtuple('Sweep', 'label cfg threshold')
Sweep.__doc__ = ('One configuration of a sweep: its label (``pre=2s,threshold=0.1``), its Config and its threshold '
                 '(None: the model\'s).')


def parse_sweep(values):
    """``['pre=100,2s', 'threshold=0,0.05']`` -> the product ``[{'pre': '100', 'threshold': '0'}, ...]`` in order;
    ValueError('sweep: ...') for an unknown key, a missing ``=`` or a key given twice."""
    import itertools
    axes = collections.OrderedDict()
    for value in values:
        key, sep, options = value.partition('=')
        key = key.strip().replace('-', '_')
        if not sep or key not in SWEEP_KEYS:
            raise ValueError('sweep: %r: expected KEY=V1,V2,... with KEY one of %s' % (value, ', '.join(SWEEP_KEYS)))
        if key in axes:
            raise ValueError('sweep: %s is given twice' % key)
        axes[key] = [item.strip() for item in options.split(',') if item.strip()]
        if not axes[key]:
            raise ValueError('sweep: %s: no value' % key)
    return [collections.OrderedDict(zip(axes, combination)) for combination in itertools.product(*axes.values())]


def sweep_label(combination):
    """``pre=2s,threshold=0.1`` (a directory name too: ``/`` cannot occur in the values)."""
    return ','.join('%s=%s' % item for item in combination.items()) or 'default'


def _thresholded(triggers, threshold):
    if threshold is not None:
        for trigger in triggers:
            if getattr(trigger, 'model', None) is not None:
                trigger.model.threshold = trigger.threshold = float(threshold)
    return triggers


def _overlaps(window, span):
    return window['start'] <= span['end'] and window['end'] >= span['start']


def sweep_one(bag_path, out_dir, sweeps):
    """Every configuration of ``sweeps`` (Sweeps) over one reading of a bag, windows into ``out_dir/<label>/``.
    Returns ``{'messages', 'seconds' (driving topic span), 'anomalies' (truth file) or None, 'rows': [{'label',
    'windows', 'kept', 'stored_bytes', 'recalled', 'false_windows'}]}``: an anomaly of ``<bag>.truth.json``
    is recalled when a window overlaps it; a window overlapping none is false."""
    from cc_log.storage.bag import bagio
    from cc_log import sim
    runs, topics, total = [], set(), 0
    bag = replay.open_bag(bag_path)  # once for every configuration's topics and checks
    try:
        for entry in sweeps:
            options, types, wanted = replay.replay_setup(entry.cfg, bag)
            _thresholded(options['triggers'], entry.threshold)
            total = max(total, replay.checked_count(bag, wanted, types))
            logger = replay.offline_logger(safe_files.inside(out_dir, entry.label, 'sweep', directory=True), options)
            tally = smart_events.WindowTally()  # windows, not files (routes, parts)
            logger.on_event(tally)
            runs.append((entry, logger, frozenset(wanted), tally))
            topics.update(wanted)
    finally:
        bag.close()
    driving = runs[0][1].driving_topic
    first = last = None
    try:
        for record in bagio.read_messages(bag_path, sorted(topics)):
            if record.topic == driving:
                first = record.stamp if first is None else first
                last = record.stamp
            for _, logger, wanted, _ in runs:
                if record.topic in wanted:
                    logger.on_message(record.topic, record.msg, record.stamp)
    finally:
        for _, logger, _, _ in runs:
            logger.close()
    truth_file = sim.truth_path(bag_path)
    truth = sim.load_truth(truth_file) if os.path.exists(truth_file) else None
    rows = []
    for entry, logger, _, tally in runs:
        windows = tally.windows()
        stats = logger.stats()
        if stats['messages_lost']:
            raise OSError('%s: %s: %s' % (logger.directory, replay.lost_text(stats),
                                          stats['last_error']))
        rows.append({'label': entry.label, 'windows': len(windows), 'kept': sum(w['messages'] for w in windows),
                     'stored_bytes': stats['stored_bytes'],
                     'recalled': None if truth is None else sum(any(_overlaps(w, a) for w in windows) for a in truth),
                     'false_windows': None if truth is None else sum(not any(_overlaps(w, a) for a in truth)
                                                                     for w in windows)})
    return {'messages': total, 'seconds': (last - first) if first is not None else 0.0,
            'anomalies': None if truth is None else len(truth), 'rows': rows}


def _sweep_task(job):
    return sweep_one(job.path, job.out, job.args[0])


def sweep_many(engine, bags, out_dir, sweeps, progress=None):
    """``sweep_one`` of every bag into ``out_dir/<output name>/``; Outcomes in the order of ``bags``."""
    return engine.run(_sweep_task, fleet.jobs(bags, out_dir, sweeps), progress)


def sweep_table(results):
    """Per configuration over the bags' ``sweep_one`` results: ``[{'label', 'windows', 'kept', 'messages',
    'stored_bytes', 'recall', 'false_per_hour'}]`` (recall and false windows per hour: None without a truth
    file for every bag)."""
    with_truth = results and all(r['anomalies'] is not None for r in results)
    hours = sum(r['seconds'] for r in results) / 3600.0
    anomalies = sum(r['anomalies'] or 0 for r in results)
    table = []
    for index, row in enumerate(results[0]['rows'] if results else ()):
        rows = [r['rows'][index] for r in results]
        line = collections.OrderedDict([
            ('label', row['label']), ('windows', sum(r['windows'] for r in rows)),
            ('kept', sum(r['kept'] for r in rows)), ('messages', sum(r['messages'] for r in results)),
            ('stored_bytes', sum(r['stored_bytes'] for r in rows)), ('recall', None), ('false_per_hour', None)])
        if with_truth:
            line['recall'] = sum(r['recalled'] for r in rows) / float(anomalies) if anomalies else None
            line['false_per_hour'] = sum(r['false_windows'] for r in rows) / hours if hours else None
        table.append(line)
    return table


__all__ = ['Sweep', 'SWEEP_KEYS', 'parse_sweep', 'sweep_label', 'sweep_one', 'sweep_many', 'sweep_table']
