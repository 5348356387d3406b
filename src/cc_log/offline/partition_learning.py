"""Learning over vector directories as partitions, on a ``fleet.Engine``.

``gather_vectors`` brings every partition into this process (the exact model, identical to the one-process
path); ``train_streamed`` never holds more than one batch here: the scaler from per-partition moments,
Nystroem components from an even sample of every partition, then ``SGDOneClassSVM.partial_fit`` on batches
drawn from every partition, and the threshold from held-out partitions (or blocks).
"""
import collections
import time

import numpy as np

from cc_log.offline.fleet import Outcome, failures, peak_rss_mb

STREAM_EPOCHS = 5          # passes of partial_fit over every partition
STREAM_METHOD = 'stream'   # learn --method of train_streamed
STREAM_BATCH_ROWS = 20000  # vectors of one partial_fit batch: what this process holds at a time
HELD_PARTITIONS_FROM = 5   # from this many partitions on, whole partitions are held out for the threshold


def load_partition(directory):
    """A vector directory as a partition: ``{'vectors': {label: 2-D array}, 'config': FeatureConfig,
    'messages': vectors, 'peak_rss_mb': of the process}``."""
    from cc_log.learning import learning
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
    from cc_log.learning import learning
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
    from cc_log.learning import learning
    from cc_log.features import vector_names
    from cc_log.learning.model import AnomalyModel
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
    scale = learning.feature_scale(np.sqrt(np.maximum(squares / count - mean ** 2, 0.0)))
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


__all__ = ['load_partition', 'gather_vectors', 'partition_roles', 'train_streamed', 'STREAM_METHOD']
