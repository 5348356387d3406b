"""Fleet scale: ``cclog collect``, ``learn`` and ``replay`` over many bags, one task per bag, on Dask.

An ``Engine`` runs the tasks in this process (``workers=0``: the one-process path), on a local Dask cluster of
``workers`` processes (default: the machine's cores) or on the cluster of a running ``dask-scheduler``. Every
task's result comes back in the order of its inputs, whatever the order they finish in; a task that fails
is one line naming its bag, and the others' results are kept. Each bag writes into its own subdirectory of the
output directory (``output_names``), so results do not depend on where or in which order tasks ran.

Learning reads vector directories as partitions: ``gather_vectors`` brings them into this process (the
exact model, identical to the one-process path); ``train_streamed`` never holds more than one batch here: the
scaler from per-partition moments, Nystroem components from an even sample of every partition, then
``SGDOneClassSVM.partial_fit`` on batches drawn from every partition, and the threshold from held-out
partitions (or blocks).
"""
import collections
import glob
import logging
import os
import time

import numpy as np

BAG_SUFFIX = '.bag'
DASK_MISSING = ('Dask is not installed (the fleet commands run on it): apt-get install python3-dask '
                'python3-distributed, or ./dev.sh setup')
STREAM_EPOCHS = 5          # passes of partial_fit over every partition
STREAM_METHOD = 'stream'   # learn --method of train_streamed
STREAM_BATCH_ROWS = 20000  # vectors of one partial_fit batch: what this process holds at a time
HELD_PARTITIONS_FROM = 5   # from this many partitions on, whole partitions are held out for the threshold

Outcome = collections.namedtuple('Outcome', 'item ok value')
Outcome.__doc__ = 'What one task gave: ``value`` is its result when ``ok``, else the one-line error naming ``item``.'


# -- inputs ---------------------------------------------------------------------------------------------

def expand_bags(patterns):
    """Bag paths of ``patterns`` (files, directories searched recursively for ``*.bag``, globs), sorted
    within each pattern and without repeats; ValueError('<pattern>: ...') for a pattern matching none."""
    found = []
    for pattern in patterns:
        if os.path.isfile(pattern):
            matches = [pattern]
        elif os.path.isdir(pattern):
            matches = sorted(os.path.join(root, name) for root, _, names in os.walk(pattern)
                             for name in names if name.endswith(BAG_SUFFIX))
            if not matches:
                raise ValueError('%s: no *%s file in this directory' % (pattern, BAG_SUFFIX))
        else:
            matches = sorted(path for path in glob.glob(pattern) if os.path.isfile(path))
            if not matches:
                raise ValueError('%s: no such bag (not a file, a directory or a glob matching files)' % pattern)
        found.extend(matches)
    return _unique(found)


def expand_vector_dirs(patterns):
    """Vector directories (``<label>/<stamp>.json``) of ``patterns`` (directories or globs); a directory
    whose subdirectories are vector directories (``cclog collect`` over many bags) stands for them.
    ValueError('<pattern>: ...') when a pattern holds none."""
    found = []
    for pattern in patterns:
        matches = [pattern] if os.path.isdir(pattern) else sorted(p for p in glob.glob(pattern) if os.path.isdir(p))
        if not matches:
            raise ValueError('%s: no such directory of feature vectors' % pattern)
        for directory in matches:
            if holds_vectors(directory):
                found.append(directory)
                continue
            inner = [os.path.join(directory, name) for name in sorted(os.listdir(directory))]
            inner = [path for path in inner if os.path.isdir(path) and holds_vectors(path)]
            if not inner:
                raise ValueError('%s: no feature vector files (<label>/<stamp>.json) found' % directory)
            found.extend(inner)
    return _unique(found)


def holds_vectors(directory):
    """True when ``directory`` has a ``<label>/`` subdirectory of ``*.json`` files."""
    for label in os.listdir(directory):
        folder = os.path.join(directory, label)
        if os.path.isdir(folder) and any(name.endswith('.json') for name in os.listdir(folder)):
            return True
    return False


def _unique(paths):
    seen, out = set(), []
    for path in paths:
        key = os.path.realpath(path)
        if key not in seen:
            seen.add(key)
            out.append(path)
    return out


def output_names(paths):
    """One distinct subdirectory name per input: its path below the inputs' common directory, ``.bag`` dropped
    and ``/`` as ``__`` (``robot1/run.bag`` -> ``robot1__run``), so two robots' ``run.bag`` do not meet. Paths
    that would still share a name (``robot1/run.bag`` and ``robot1__run.bag``; ``run`` and ``run.bag``) each get
    ``-`` and 8 hex digits of their path's hash: the same name whatever the other inputs' order."""
    import hashlib
    absolute = [os.path.abspath(path) for path in paths]
    common = os.path.commonpath([os.path.dirname(path) for path in absolute]) if absolute else ''
    relative = [os.path.relpath(path, common) for path in absolute]
    names = [(name[:-len(BAG_SUFFIX)] if name.endswith(BAG_SUFFIX) else name).replace(os.sep, '__')
             for name in relative]
    counts = collections.Counter(names)
    return [name if counts[name] == 1 else '%s-%s' % (name, hashlib.sha256(rel.encode('utf-8')).hexdigest()[:8])
            for name, rel in zip(names, relative)]


# -- the engine -----------------------------------------------------------------------------------------

def _one_line(error):
    text = ' '.join(part.strip() for part in str(error).strip().splitlines() if part.strip())
    if isinstance(error, OSError) and getattr(error, 'strerror', None) and getattr(error, 'filename', None):
        text = '%s: %s' % (error.filename, error.strerror)
    return text or type(error).__name__


def _named(item, error):
    """``<bag>: <what is wrong>`` (the bag named once)."""
    text = error if isinstance(error, str) else _one_line(error)
    if not isinstance(error, (ValueError, OSError, str)):
        text = '%s: %s' % (type(error).__name__, text)
    name = item if isinstance(item, str) else getattr(item, 'name', str(item))
    return text if text.startswith(name) else '%s: %s' % (name, text)


def _guarded(function, item):
    """Run one task; a failure becomes ``(False, line)`` so that it never takes the other tasks with it."""
    try:
        return True, function(item)
    except Exception as error:  # noqa: BLE001 -- any failure of one bag is reported, the others go on
        return False, _named(item, error)


def peak_rss_mb():
    """Peak resident memory of this process (MB): ``learning.peak_rss_mb``."""
    from cc_log.core import learning
    return learning.peak_rss_mb()


class Engine(object):
    """Where tasks run: this process (``workers=0``), a local Dask cluster of ``workers`` processes (None: the
    machine's cores), or the cluster of the scheduler at ``scheduler`` (``tcp://host:8786``). A context
    manager: the local cluster lives until it is left. ValueError with one line when Dask is missing or the
    scheduler cannot be reached."""

    def __init__(self, workers=None, scheduler=None):
        if workers is not None and workers < 0:
            raise ValueError('workers: must be 0 (this process) or more, got %r' % workers)
        self.workers = workers
        self.scheduler = scheduler
        self.client = None
        self._cluster = None

    @property
    def local(self):
        """True when every task runs in this process."""
        return self.workers == 0 and self.scheduler is None

    def describe(self):
        """``'this process'``, ``'local Dask cluster, 2 workers'`` or ``'Dask scheduler tcp://...'``."""
        if self.local:
            return 'this process'
        if self.scheduler:
            return 'Dask scheduler %s, %d workers' % (self.scheduler, self.worker_count())
        return 'local Dask cluster, %d workers' % self.worker_count()

    def worker_count(self):
        """How many processes run tasks."""
        if self.client is None:
            return 1
        return len(self.client.scheduler_info().get('workers', {}))

    def __enter__(self):
        if self.local:
            return self
        try:
            import distributed
        except ImportError:
            raise ValueError(DASK_MISSING)
        if self.scheduler:
            try:
                self.client = distributed.Client(self.scheduler, timeout=10, set_as_default=False)
            except (OSError, TimeoutError) as error:
                raise ValueError('scheduler: cannot reach %s (%s)' % (self.scheduler, _one_line(error)))
        else:
            count = self.workers or os.cpu_count() or 1
            # no dashboard; its HTTP server (health routes) on a free port: a busy 8787 warned on stderr
            self._cluster = distributed.LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                                                     dashboard_address=':0', scheduler_kwargs={'dashboard': False},
                                                     silence_logs=logging.ERROR)
            self.client = distributed.Client(self._cluster, set_as_default=False)
        return self

    def __exit__(self, *exc):
        if self.client is not None:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()
        self.client = self._cluster = None
        return False

    def run(self, function, items, progress=None):
        """``function(item)`` for every item, as one task each; returns Outcomes in the order of ``items``.
        ``progress(done, total, result)`` is called as each task ends (result: its value, None on failure)."""
        items = list(items)
        outcomes = [None] * len(items)

        def finished(index, ok, value):
            outcomes[index] = Outcome(items[index], ok, value)
            if progress is not None:
                progress(sum(o is not None for o in outcomes), len(items), value if ok else None)

        if self.local:
            for index, item in enumerate(items):
                finished(index, *_guarded(function, item))
            return outcomes
        import distributed
        futures = self.client.map(_guarded, [function] * len(items), items, pure=False)
        where = {future.key: index for index, future in enumerate(futures)}
        for future in distributed.as_completed(futures, loop=self.client.loop):
            index = where[future.key]
            try:
                ok, value = future.result()
            except Exception as error:  # noqa: BLE001 -- a worker lost (killed, out of memory): this task only
                ok, value = False, _named(items[index], error)
            finished(index, ok, value)
        return outcomes

    # handles: data left where a task made it (a worker's memory), for learning over partitions

    def place(self, function, items):
        """``function(item)`` for every item, its result kept where it was computed; returns handles."""
        if self.local:
            return [function(item) for item in items]
        return self.client.map(function, list(items), pure=False)

    def each(self, function, handles, *args):
        """``function(data, *args)`` on every handle's data, where it lives; returns the values here."""
        if self.local:
            return [function(data, *args) for data in handles]
        return self.client.gather(self.client.map(function, handles, *[[a] * len(handles) for a in args],
                                                  pure=False))

    def fetch(self, handle):
        """The data of one handle, here."""
        return handle if self.local else handle.result()


# -- collect and replay, one bag each ---------------------------------------------------------------------

def message_count(bag_path, topics):
    """Messages of ``topics`` in a bag (from its index)."""
    from cc_log.storage.bag import bagio
    bag = bagio.open_bag(bag_path)
    try:
        return bag.get_message_count(list(topics))
    finally:
        bag.close()


def collect_one(bag_path, out_dir, specs, label, stride, single=True):
    """``collector.collect_bag`` of one bag into ``out_dir`` with ``specs`` (``[(name, FeatureConfig, topics)]``;
    ``single``: the one feature set of ``--topic``, written straight into ``out_dir/<label>``); its result
    plus ``messages`` (read from the bag)."""
    from cc_log.core import collector
    if single:
        name, config, topics = specs[0]
        result = collector.collect_bag(bag_path, topics, out_dir, label=label, window=config.window, stride=stride,
                                       feature_set=config.feature_set)
    else:
        result = collector.collect_bag(bag_path, None, out_dir, label=label, stride=stride, feature_specs=specs)
    result['messages'] = message_count(bag_path, sorted(set(t for _, _, topics in specs for t in topics)))
    return result


def replay_setup(cfg, bag_path=None):
    """The logger options, topic types and topics (driving first) of a replay with configuration ``cfg``; topic
    patterns (``*``, ``re:``, ``!``) select among the topics of ``bag_path`` (none without a bag)."""
    from cc_log.core import config as config_mod
    from cc_log.core import smart
    from cc_log.core.model import AnomalyModel
    triggers = cfg.build_triggers(AnomalyModel.load, config_mod.installed_class)
    options = cfg.logger_options(triggers)
    if options['side_topics'] is None:
        options['side_topics'] = bag_topics(bag_path, cfg.selection.select) if bag_path else []
    types = smart.topic_types(triggers)
    topics = [options['driving_topic']] + [t for t in sorted(set(options['side_topics']).union(types))
                                           if t != options['driving_topic']]
    return options, types, topics


def replay_one(bag_path, out_dir, cfg, progress=None, make_dir=None):
    """The smart logger of configuration ``cfg`` over one bag into ``out_dir`` (``smart.replay_into``);
    its summary plus ``driving_topic``, ``format``, ``messages`` and ``drift`` (a ``drift.DriftMonitor`` of each
    classifier). ``progress(done, total)``; ``make_dir(path)`` creates ``out_dir`` once the bag is checked
    (default: ``safe_files.make_dirs``)."""
    from cc_log.core import drift, safe_files, smart
    options, types, topics = replay_setup(cfg, bag_path)
    total = check_bag_topics(bag_path, topics, types)
    (make_dir or safe_files.make_dirs)(out_dir)
    logger = _offline_logger(out_dir, options)
    monitors = drift.monitor_classifiers(logger.classifiers)
    summary = smart.replay_into(logger, bag_path, None if progress is None
                                else (lambda done: progress(done, total)))
    summary.update(driving_topic=options['driving_topic'], format=cfg.format, messages=total, drift=monitors)
    return summary


def bag_topics(bag_path, select):
    """``select(sorted topics of the bag)``."""
    from cc_log.storage.bag import bagio
    bag = bagio.open_bag(bag_path)
    try:
        return select(sorted(bagio.topics_of(bag)))
    finally:
        bag.close()


def check_bag_topics(bag_path, topics, types):
    """A readable bag holding ``topics`` of the ``types`` given (``{topic: type}``); how many messages they have."""
    from cc_log.storage.bag import bagio
    bag = bagio.open_bag(bag_path)
    try:
        for topic in topics:
            bagio.check_topic(bag, topic, types.get(topic))
        return bag.get_message_count(topics)
    finally:
        bag.close()


def _offline_logger(out_dir, options):
    from cc_log.core import smart
    from cc_log.storage import window_writer
    retry = window_writer.OFFLINE_RETRY_SECONDS
    return smart.SmartLogger(None, out_dir, retry_period=window_writer.OFFLINE_RETRY_PERIOD,
                             give_up_after=retry, close_retry=retry, **options)


# -- sweep: several configurations over one reading of each bag --------------------------------------------

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


def _window_recorder(windows):
    from cc_log.core import smart

    def record(event):
        if event.kind == smart.WRITTEN:
            windows.append({'start': event.start, 'end': event.end, 'messages': event.messages})
    return record


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
    for entry in sweeps:
        options, types, wanted = replay_setup(entry.cfg, bag_path)
        _thresholded(options['triggers'], entry.threshold)
        total = max(total, check_bag_topics(bag_path, wanted, types))
        logger = _offline_logger(os.path.join(out_dir, entry.label), options)
        windows = []
        logger.on_event(_window_recorder(windows))
        runs.append((entry, logger, frozenset(wanted), windows))
        topics.update(wanted)
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
    for entry, logger, _, windows in runs:
        stats = logger.stats()
        if stats['messages_lost']:
            raise OSError('%s: %d window(s) (%d messages) not written: %s' % (
                os.path.join(out_dir, entry.label), stats['windows_lost'], stats['messages_lost'],
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
    return engine.run(_sweep_task, jobs(bags, out_dir, sweeps), progress)


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


def _collect_task(job):
    return collect_one(job.path, job.out, *job.args)


def _replay_task(job):
    return replay_one(job.path, job.out, job.args[0])


class Job(collections.namedtuple('Job', 'name path out args')):
    """One bag's task: its output name, its path, its output directory and the arguments of the command."""


def jobs(bags, out_dir, *args):
    """One Job per bag, each writing into ``out_dir/<output name>``."""
    return [Job(path, path, os.path.join(out_dir, name), args) for name, path in zip(output_names(bags), bags)]


def collect_many(engine, bags, out_dir, specs, label, stride, single=True, progress=None):
    """``collect_one`` of every bag into ``out_dir/<output name>/``; Outcomes in the order of ``bags``."""
    return engine.run(_collect_task, jobs(bags, out_dir, specs, label, stride, single), progress)


def replay_many(engine, bags, out_dir, cfg, progress=None):
    """``replay_one`` of every bag into ``out_dir/<output name>/``; Outcomes in the order of ``bags``."""
    return engine.run(_replay_task, jobs(bags, out_dir, cfg), progress)


class Meter(object):
    """Progress of a whole job: ``12/40 bags, 1.2 M messages, 45000 msg/s``; ``update`` is an Engine.run
    ``progress`` callback, ``report(done, total, text)`` shows it."""

    def __init__(self, report):
        self.report = report
        self.messages = 0
        self.started = time.time()

    def update(self, done, total, result):
        if result is not None:
            self.messages += int(result.get('messages', 0))
        self.report(done, total, self.text(done, total))

    def rate(self):
        """Messages per second since the start."""
        return self.messages / max(time.time() - self.started, 1e-9)

    def text(self, done, total):
        return '%d/%d bags, %d messages, %.0f msg/s' % (done, total, self.messages, self.rate())

    def summary(self, engine):
        """``{'engine', 'seconds', 'messages', 'messages_per_second'}`` of the job so far."""
        return collections.OrderedDict([('engine', engine.describe()), ('seconds', time.time() - self.started),
                                        ('messages', self.messages), ('messages_per_second', self.rate())])


def failures(outcomes):
    """The one-line errors of the Outcomes that failed."""
    return [outcome.value for outcome in outcomes if not outcome.ok]


# -- learning over partitions -----------------------------------------------------------------------------

def load_partition(directory):
    """A vector directory as a partition: ``{'vectors': {label: 2-D array}, 'config': FeatureConfig,
    'messages': vectors, 'peak_rss_mb': of the process}``."""
    from cc_log.core import learning
    vectors, config = learning.load_vectors(directory)
    return {'vectors': vectors, 'config': config, 'messages': sum(len(v) for v in vectors.values()),
            'peak_rss_mb': peak_rss_mb()}


def _check_configs(outcomes):
    config, first = None, None
    for outcome in outcomes:
        if config is None:
            config, first = outcome.value['config'], outcome.item
        elif outcome.value['config'] != config:
            raise ValueError('%s: config %s differs from %s in %s' % (
                outcome.item, outcome.value['config'].to_dict(), config.to_dict(), first))
    return config


def gather_vectors(engine, directories, progress=None):
    """Load every vector directory as a task and join them here, partition after partition: ``(vectors,
    config, peak_rss_mb)`` as ``learning.load_vectors`` gives for one directory (peak: the largest of the
    loading processes). ValueError naming the first directory that cannot be read (and how many could not)."""
    outcomes = engine.run(load_partition, directories, progress)
    bad = failures(outcomes)
    if bad:
        raise ValueError('%s%s' % (bad[0], ' (and %d other directories)' % (len(bad) - 1) if len(bad) > 1 else ''))
    config = _check_configs(outcomes)
    labels = sorted(set(label for outcome in outcomes for label in outcome.value['vectors']))
    vectors = {label: np.concatenate([o.value['vectors'][label] for o in outcomes if label in o.value['vectors']])
               for label in labels}
    return vectors, config, max(o.value['peak_rss_mb'] for o in outcomes)


class _Load(collections.namedtuple('_Load', 'load item role')):
    """One partition to make (a named tuple: Dask would take a plain ``(function, ...)`` tuple for a task)."""


def _load_with_role(job):
    partition = job.load(job.item)
    partition['role'] = job.role
    return partition


def partition_roles(count, holdout):
    """``'held'`` for about ``holdout`` of ``count`` partitions spread over them (the threshold then sees runs
    the model never saw), ``'train'`` for the others; with fewer than HELD_PARTITIONS_FROM partitions every one
    is ``'split'`` into time blocks as ``learning.split_blocks`` cuts one."""
    if count < HELD_PARTITIONS_FROM:
        return ['split'] * count
    held = set(min(count - 1, int((k + 0.5) * count / max(1, int(round(holdout * count)))))
               for k in range(max(1, int(round(holdout * count)))))
    return ['held' if index in held else 'train' for index in range(count)]


def _nominal_split(partition, holdout, blocks):
    from cc_log.core import learning
    X = partition['vectors'].get('nominal')
    role = partition.get('role', 'split')
    if X is None or len(X) < 4:
        return np.empty((0, 0)), np.empty((0, 0))
    if role != 'split':
        empty = X[:0]
        return (X, empty) if role == 'train' else (empty, X)
    train_index, held_index = learning.split_blocks(len(X), holdout, blocks)
    return X[train_index], X[held_index]


def _moments(partition, holdout, blocks):
    X, _ = _nominal_split(partition, holdout, blocks)
    if not len(X):
        return 0, 0.0, 0.0
    return len(X), X.sum(axis=0), np.square(X).sum(axis=0)


def _sample(partition, holdout, blocks, count):
    X, _ = _nominal_split(partition, holdout, blocks)
    return X[np.linspace(0, len(X) - 1, min(count, len(X))).astype(int)] if len(X) else X


def _held_scores(partition, holdout, blocks, model):
    _, held = _nominal_split(partition, holdout, blocks)
    return model.scores(held) if len(held) else np.empty(0)


def _batch_rows(partition, holdout, blocks, seed, index, batches):
    """Batch ``index`` of ``batches`` of a partition's training rows, shuffled with ``seed``."""
    X = _nominal_split(partition, holdout, blocks)[0]
    return X[np.random.RandomState(seed).permutation(len(X))[index::batches]] if len(X) else X


def _partition_rss(partition):
    return peak_rss_mb()  # of the process holding the partition


def train_streamed(engine, load, items, nu=None, gamma=None, components=None, epochs=STREAM_EPOCHS, seed=0,
                   holdout=None, blocks=None, batch_rows=STREAM_BATCH_ROWS, progress=None):
    """Train a ``nystroem-sgd`` model over partitions without holding them all in one process.

    ``load(item)`` makes one partition (``load_partition``'s dict) where it runs; it stays there. The scaler
    comes from the partitions' moments, the Nystroem components from an even sample of every partition's
    training blocks, the linear one-class SVM from ``SGDOneClassSVM.partial_fit`` on batches of about
    ``batch_rows`` vectors, each a shuffled share of every partition (``epochs`` passes), the threshold
    (``learning.nominal_threshold``) from the scores of held-out vectors: whole partitions (``partition_roles``),
    or with few partitions every partition's held-out blocks. Returns ``(AnomalyModel, info)``;
    ``info['peak_rss_mb']`` is this process's, ``info['worker_peak_rss_mb']`` the largest of the partitions' processes.
    """
    from sklearn.kernel_approximation import Nystroem
    from sklearn.linear_model import SGDOneClassSVM
    from cc_log.core import learning
    from cc_log.features import vector_names
    from cc_log.core.model import AnomalyModel
    started = time.time()
    holdout = learning.DEFAULT_HOLDOUT if holdout is None else holdout
    blocks = learning.DEFAULT_BLOCKS if blocks is None else blocks
    components = learning.NYSTROEM_COMPONENTS if components is None else components
    handles = engine.place(_load_with_role, [_Load(load, item, role)
                                             for item, role in zip(items, partition_roles(len(items), holdout))])
    configs = engine.each(_partition_config, handles)
    config = _check_configs([Outcome(item, True, {'config': c}) for item, c in zip(items, configs)])
    moments = engine.each(_moments, handles, holdout, blocks)
    count = sum(m[0] for m in moments)
    if count < 10:
        raise ValueError('nominal: need at least 10 training vectors over all partitions, got %d' % count)
    total = sum(m[1] for m in moments if m[0])
    squares = sum(m[2] for m in moments if m[0])
    mean = total / count
    scale = np.sqrt(np.maximum(squares / count - mean ** 2, 0.0))
    scale[scale < 10 * np.finfo(float).eps] = 1.0  # constant columns, as StandardScaler
    dimension = len(mean)
    nu = learning.DEFAULT_NU if nu is None else float(nu)
    gamma = learning.DEFAULT_GAMMA_FACTOR / dimension if gamma is None else float(gamma)
    per_partition = int(np.ceil(4.0 * components / len(handles)))
    sample = np.concatenate([s for s in engine.each(_sample, handles, holdout, blocks, per_partition) if len(s)])
    sample = (sample - mean) / scale
    chosen = sample[np.random.RandomState(seed).permutation(len(sample))[:components]]
    nystroem = Nystroem(kernel='rbf', gamma=gamma, n_components=len(chosen), random_state=seed).fit(chosen)
    sgd = SGDOneClassSVM(nu=nu, random_state=seed, learning_rate='optimal')
    # every batch takes a share of every partition (one run after another would pull the model to the last)
    batches = max(1, int(np.ceil(count / float(batch_rows))))
    for epoch in range(epochs):
        for index in range(batches):
            parts = [rows for rows in engine.each(_batch_rows, handles, holdout, blocks, seed + epoch, index, batches)
                     if len(rows)]
            if parts:
                rows = np.concatenate(parts)
                sgd.partial_fit(nystroem.transform((rows - mean) / scale))
            if progress is not None:
                progress(epoch * batches + index + 1, epochs * batches, None)
    names = vector_names(config)
    kernel = {'components': nystroem.components_, 'normalization': nystroem.normalization_,
              'coef': sgd.coef_.ravel(), 'offset': float(np.ravel(sgd.offset_)[0]), 'gamma': gamma}
    model = AnomalyModel(config, mean, scale, 'nystroem-sgd', kernel, 0.0, names)
    held = np.concatenate(engine.each(_held_scores, handles, holdout, blocks, model))
    threshold = learning.nominal_threshold(held)
    model.threshold = float(threshold)
    info = {'method': 'nystroem-sgd-streamed', 'requested_method': STREAM_METHOD, 'partitions': len(handles),
            'vectors_train': int(count), 'vectors_held_out': int(len(held)), 'vectors_nominal': int(count + len(held)),
            'vectors_anomalous': 0, 'features': dimension, 'config': config.to_dict(), 'nu': nu, 'gamma': gamma,
            'components': int(len(chosen)), 'epochs': epochs, 'batches': batches, 'threshold': float(threshold),
            'threshold_rule': 'held-out nominal: q%g - %g * (median - q%g)' % (
                learning.DEFAULT_QUANTILE, learning.DEFAULT_MARGIN, learning.DEFAULT_QUANTILE),
            'held_out_flagged': int(np.sum(held < threshold)),
            'held_out_score_min': float(np.min(held)) if len(held) else None,
            'held_out_score_median': float(np.median(held)) if len(held) else None,
            'train_seconds': time.time() - started, 'peak_rss_mb': peak_rss_mb(),
            'worker_peak_rss_mb': max(engine.each(_partition_rss, handles))}
    model.info = {key: value for key, value in info.items() if value is not None}
    return model, info


def _partition_config(partition):
    return partition['config']


__all__ = ['Engine', 'Outcome', 'Meter', 'expand_bags', 'expand_vector_dirs', 'output_names', 'collect_one',
           'collect_many', 'replay_one', 'replay_many', 'replay_setup', 'parse_sweep', 'sweep_one', 'sweep_many',
           'sweep_table', 'Sweep', 'gather_vectors', 'train_streamed',
           'load_partition', 'failures']
