"""Learning: vector files, training from nominal data alone or with anomalies, the report."""
import json
import os

import numpy as np
import pytest

from cc_log.learning import learning
from cc_log.features import FeatureConfig, vector_length, vector_names
from cc_log.learning.learning import Report, evaluate, format_report, load_vectors, split_blocks, train, write_vector
from cc_log.learning.model import AnomalyModel

CONFIG = FeatureConfig('motion', '2s')
D = vector_length(CONFIG)


def nominal_stream(n, seed=0):
    """Time-ordered nominal vectors: a slowly drifting state seen through a fixed nonlinear map plus noise."""
    rng = np.random.default_rng(seed)
    latent = np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0)
    latent = np.sin(latent) + rng.normal(scale=0.05, size=(n, 3))
    mix = np.random.default_rng(100).normal(size=(3, D))
    return latent.dot(mix) + rng.normal(scale=0.05, size=(n, D))


def test_vector_files_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    written = {'nominal': rng.normal(size=(5, D)), 'bump': rng.normal(size=(3, D))}
    stamps = {'nominal': [105.5, 101.25, 103.0, 102.0, 104.0], 'bump': [7.0, 9.0, 8.0]}
    for label, X in written.items():
        for stamp, vector in zip(stamps[label], X):
            path = write_vector(str(tmp_path), label, stamp, vector, CONFIG,
                                names=vector_names(CONFIG) if label == 'bump' else None)
            assert path == os.path.join(str(tmp_path), label, '%.6f.json' % stamp)
    document = json.load(open(os.path.join(str(tmp_path), 'bump', '7.000000.json')))
    assert set(document) == {'stamp', 'features', 'names', 'config'} and document['config'] == CONFIG.to_dict()
    (tmp_path / 'nominal' / '1.0.json.tmp-123').write_text('half a fi')   # ignored
    vectors, config, found_stamps = load_vectors(str(tmp_path), with_stamps=True)
    assert config == CONFIG and sorted(vectors) == ['bump', 'nominal']
    for label, X in written.items():
        order = np.argsort(stamps[label])
        assert np.array_equal(vectors[label], X[order])        # in stamp order
        assert np.array_equal(found_stamps[label], np.sort(stamps[label]))
    assert load_vectors(str(tmp_path))[1] == CONFIG
    with pytest.raises(ValueError, match='label'):
        write_vector(str(tmp_path), '../up', 1.0, np.zeros(D), CONFIG)
    with pytest.raises(ValueError, match='finite'):
        write_vector(str(tmp_path), 'x', 1.0, np.full(D, np.nan), CONFIG)


def test_load_vectors_refuses_mixed_configs_and_missing_data(tmp_path):
    with pytest.raises(ValueError, match=str(tmp_path / 'none')):
        load_vectors(str(tmp_path / 'none'))
    (tmp_path / 'empty').mkdir()
    with pytest.raises(ValueError, match='no feature vector files'):
        load_vectors(str(tmp_path / 'empty'))
    root = str(tmp_path / 'mixed')
    write_vector(root, 'nominal', 1.0, np.zeros(D), CONFIG)
    other = write_vector(root, 'nominal', 2.0, np.zeros(D), FeatureConfig('motion', '5s'))
    with pytest.raises(ValueError) as error:
        load_vectors(root)
    assert 'differs' in str(error.value)
    assert '2.000000.json' in str(error.value) or '1.000000.json' in str(error.value)
    os.unlink(other)
    bad = os.path.join(root, 'nominal', '3.000000.json')
    open(bad, 'w').write('{"stamp": 3, "features": [1, 2')
    with pytest.raises(ValueError, match='3.000000.json'):
        load_vectors(root)
    open(bad, 'w').write(json.dumps({'stamp': 3, 'features': [1.0], 'config': CONFIG.to_dict()}))
    with pytest.raises(ValueError, match='3.000000.json'):
        load_vectors(root)


def test_split_blocks_holds_out_contiguous_blocks():
    train_index, held = split_blocks(1000, holdout=0.2, blocks=10)
    assert len(held) == 200 and len(train_index) == 800
    assert not set(train_index) & set(held) and 0 in train_index and 999 in train_index
    runs = np.split(held, np.flatnonzero(np.diff(held) != 1) + 1)
    assert len(runs) == 2 and all(len(run) == 100 for run in runs)


def test_report_counts_on_a_known_set():
    # score = exp(-|z|^2) - 0.5 around the origin: anomalous (score < 0) when |z|^2 > ln 2
    model = AnomalyModel(CONFIG, np.zeros(D), np.ones(D), 'ocsvm',
                         {'support_vectors': np.zeros((1, D)), 'dual_coef': np.ones(1), 'intercept': -0.5,
                          'gamma': 1.0}, threshold=0.0)

    def at(distances):
        X = np.zeros((len(distances), D))
        X[:, 0] = distances
        return X

    nominal = at([0.0, 0.1, 0.5, 0.8, 0.9, 2.0])      # 0.9 and 2.0 lie outside sqrt(ln 2) = 0.833
    anomalous = at([3.0, 1.0, 0.2])                    # 0.2 lies inside: missed
    report = evaluate(model, nominal, anomalous)
    assert report == Report(total=9, tp=2, fp=2, fn=1, tn=4, precision=0.5, recall=2.0 / 3)
    text = format_report(report, {'train_seconds': 1.25, 'peak_rss_mb': 80.0, 'method': 'exact', 'nu': 0.02,
                                  'gamma': 0.01, 'vectors_train': 10, 'vectors_held_out': 2, 'threshold': 0.0})
    for line in ('Total            9', 'TP               2', 'FP               2', 'FN               1',
                 'TN               4', 'Precision        50.0%', 'Recall           66.7%', 'Training time    1.25 s',
                 'Peak memory      80 MB'):
        assert line in text
    empty = evaluate(model, nominal[:2], None)
    assert empty.total == 2 and empty.tn == 2 and empty.precision != empty.precision   # nan


def test_train_on_nominal_only_flags_outliers_not_new_nominal_data():
    X = nominal_stream(3000)
    model, info = train(X, config=CONFIG)
    assert model.kind == 'ocsvm' and model.config == CONFIG and info['vectors_held_out'] == 600
    assert info['held_out_flagged'] <= 2
    fresh = nominal_stream(1000, seed=7)[:300]          # same process, another run
    rng = np.random.default_rng(3)
    outliers = X[rng.integers(0, len(X), 40)] + rng.choice([-1.0, 1.0], size=(40, 1)) * 6.0 * X.std(axis=0)
    report = evaluate(model, fresh, outliers)
    assert report.recall == 1.0
    assert report.fp <= 0.02 * len(fresh)


def test_train_with_anomalies_keeps_recall_and_improves_precision():
    X = nominal_stream(2000)
    rng = np.random.default_rng(4)
    # mild anomalies, inside the reach of the nominal-only threshold's margin
    anomalies = X[rng.integers(0, len(X), 30)] + 1.2 * X.std(axis=0) * rng.choice([-1.0, 1.0], size=(30, D))
    model, info = train(X, anomalous=anomalies, config=CONFIG)
    assert len(info['grid']) == len(learning.NU_GRID) * len(learning.GAMMA_FACTOR_GRID)
    report = evaluate(model, X, anomalies)
    assert report.recall == 1.0
    best = max(candidate['precision'] for candidate in info['grid'])
    assert info['nu'] in learning.NU_GRID and best >= 0.9


TRAIN_17512 = """
import json, sys, time
sys.path.insert(0, %r)
from test_learning import CONFIG, nominal_stream
from cc_log.learning.learning import train
X = nominal_stream(17512, seed=5)
started = time.time()
_, info = train(X, config=CONFIG)
print(json.dumps(dict(info, wall=time.time() - started), default=str))
"""


def test_training_17512_vectors_is_fast_and_small():
    # in a process of its own: its peak RSS is the training's, not that of every test run before it
    import subprocess
    import sys
    out = subprocess.run([sys.executable, '-c', TRAIN_17512 % os.path.dirname(os.path.abspath(__file__))],
                         stdout=subprocess.PIPE, check=True, timeout=300).stdout
    info = json.loads(out.decode().strip().splitlines()[-1])
    assert info['wall'] <= 10.0
    assert info['peak_rss_mb'] <= 300
    assert info['vectors_nominal'] == 17512 and info['method'] == 'exact'
    X = nominal_stream(17512, seed=5)
    ny, ny_info = train(X, config=CONFIG, method='nystroem')
    assert ny.kind == 'nystroem-sgd' and ny_info['train_seconds'] <= 10.0
    assert evaluate(ny, X[:2000], None).fp <= 0.05 * 2000


def test_a_column_that_varied_by_rounding_alone_does_not_make_rounding_anomalous():
    """Odometry whose pose is integrated from its own twist has a sideways pose error of ~4e-15 m/s: scaled by that
    spread, the rounding of coordinates further from the origin (1e-10) would be 1e5 standard deviations. Its
    scale is MIN_SCALE instead; a constant column keeps scikit-learn's 1.0; a real change still counts."""
    X = nominal_stream(600)
    rng = np.random.default_rng(1)
    X[:, 3] = rng.normal(scale=5e-15, size=len(X))
    X[:, 4] = 0.0
    model, _ = train(X, config=CONFIG)
    assert model.scale[3] == learning.MIN_SCALE and model.scale[4] == 1.0
    assert learning.feature_scale([3e-15, 0.0, 0.2]).tolist() == [learning.MIN_SCALE, 1.0, 0.2]
    typical = X[len(X) // 2].copy()
    assert not model.is_anomalous(typical)[0]
    rounded = typical.copy()
    rounded[3] += 1e-10
    assert not model.is_anomalous(rounded)[0]
    slide = typical.copy()
    slide[3] += 0.05   # a sideways pose error of 5 cm/s on a robot that never had one
    assert model.is_anomalous(slide)[0]
