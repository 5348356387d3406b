"""Fleet scale: ``cclog collect``, ``learn`` and ``replay`` over many bags, one task per bag, on Dask.

An ``Engine`` runs the tasks in this process (``workers=0``: the one-process path), on a local Dask cluster of
``workers`` processes (default: the machine's cores) or on the cluster of a running ``dask-scheduler``. Every
task's result comes back in the order of its inputs, whatever the order they finish in; a task that fails
is one line naming its bag, and the others' results are kept. Each bag writes into its own subdirectory of the
output directory (``output_names``), so results do not depend on where or in which order tasks ran.

The task of a bag: ``collect_one`` here, ``replay.replay_one`` (the one replay of ``cclog replay``), and
``sweep.sweep_one``; learning over vector directories as partitions is ``partition_learning``.
"""
import collections
import glob
import logging
import os
import time

from cc_log.base import safe_files

BAG_SUFFIX = '.bag'
DASK_MISSING = ('Dask is not installed (the fleet commands run on it): apt-get install python3-dask '
                'python3-distributed, or ./dev.sh setup')

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
    (kept when what is left would be ``.``, ``..`` or nothing: ``...bag`` stays ``...bag``) and ``/`` as ``__``
    (``robot1/run.bag`` -> ``robot1__run``), so two robots' ``run.bag`` do not meet. Paths that would still share
    a name (``robot1/run.bag`` and ``robot1__run.bag``; ``run`` and ``run.bag``) each get ``-`` and 8 hex digits of
    their path's hash: the same name whatever the other inputs' order."""
    import hashlib
    absolute = [os.path.abspath(path) for path in paths]
    common = os.path.commonpath([os.path.dirname(path) for path in absolute]) if absolute else ''
    relative = [os.path.relpath(path, common) for path in absolute]
    names = [_without_suffix(name).replace(os.sep, '__') for name in relative]
    counts = collections.Counter(names)
    return [name if counts[name] == 1 else '%s-%s' % (name, hashlib.sha256(rel.encode('utf-8')).hexdigest()[:8])
            for name, rel in zip(names, relative)]


def _without_suffix(name):
    """``name`` without ``.bag``, unless that leaves no plain name (``...bag``, ``..bag``, ``.bag``)."""
    stem = name[:-len(BAG_SUFFIX)] if name.endswith(BAG_SUFFIX) else name
    return stem if os.path.basename(stem) not in ('', '.', '..') else name


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
    from cc_log.learning import learning
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
    from cc_log.logger import collector
    if single:
        name, config, topics = specs[0]
        result = collector.collect_bag(bag_path, topics, out_dir, label=label, window=config.window, stride=stride,
                                       feature_set=config.feature_set)
    else:
        result = collector.collect_bag(bag_path, None, out_dir, label=label, stride=stride, feature_specs=specs)
    result['messages'] = message_count(bag_path, sorted(set(t for _, _, topics in specs for t in topics)))
    return result


def _collect_task(job):
    return collect_one(job.path, job.out, *job.args)


def _replay_task(job):
    from cc_log.offline import replay
    return replay.replay_one(job.path, job.out, job.args[0], online_dir=job.out)  # bags learn independently


class Job(collections.namedtuple('Job', 'name path out args')):
    """One bag's task: its output name, its path, its output directory and the arguments of the command."""


def jobs(bags, out_dir, *args):
    """One Job per bag, each writing into ``out_dir/<output name>`` (``output_dirs``)."""
    return [Job(path, path, out, args) for out, path in zip(output_dirs(out_dir, bags), bags)]


def output_dirs(out_dir, bags):
    """The output directory of each bag: ``out_dir/<output name>``, checked inside ``out_dir``
    (``safe_files.inside``)."""
    return [safe_files.inside(out_dir, name, 'bag', directory=True) for name in output_names(bags)]


def collect_many(engine, bags, out_dir, specs, label, stride, single=True, progress=None):
    """``collect_one`` of every bag into ``out_dir/<output name>/``; Outcomes in the order of ``bags``."""
    return engine.run(_collect_task, jobs(bags, out_dir, specs, label, stride, single), progress)


def replay_many(engine, bags, out_dir, cfg, progress=None):
    """``replay.replay_one`` of every bag into ``out_dir/<output name>/``; Outcomes in the order of ``bags``.
    Classifiers that learn online learn from each bag alone, their refits in its directory: the bags run in
    parallel, so none may resume another's refit or share a file with it."""
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


__all__ = ['Engine', 'Outcome', 'Meter', 'expand_bags', 'expand_vector_dirs', 'output_names', 'output_dirs',
           'collect_one', 'collect_many', 'replay_many', 'jobs', 'failures', 'peak_rss_mb']
