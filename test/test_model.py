"""The model: numpy scoring equals scikit-learn, the JSON file round-trips, anything else is refused."""
import json
import os
import pickle

import numpy as np
import pytest
from sklearn.kernel_approximation import Nystroem
from sklearn.linear_model import SGDOneClassSVM
from sklearn.preprocessing import StandardScaler
from sklearn.svm import OneClassSVM

from cc_log.features import FeatureConfig, vector_length, vector_names
from cc_log.learning.model import FLOOR_FRACTION, AnomalyModel, ModelError

from conftest import approx_floats

CONFIG = FeatureConfig('motion', '5s')
D = vector_length(CONFIG)


def data(n=400, seed=0):
    fixed = np.random.default_rng(100)                 # the same process for every seed
    mix, scale = fixed.normal(size=(4, D)), fixed.uniform(0.1, 20, D)
    rng = np.random.default_rng(seed)
    latent = rng.normal(size=(n, 4))
    X = np.tanh(latent.dot(mix)) * scale + rng.normal(scale=0.05, size=(n, D))
    X[:, 5] = 3.0   # a constant column: scale 1 in sklearn
    return X


@pytest.fixture(scope='module')
def fitted():
    X = data()
    scaler = StandardScaler().fit(X)
    svm = OneClassSVM(kernel='rbf', nu=0.05, gamma=0.7 / D).fit(scaler.transform(X))
    threshold = float(np.quantile(svm.decision_function(scaler.transform(data(200, seed=1))), 0.3))
    model = AnomalyModel(CONFIG, scaler.mean_, scaler.scale_, 'ocsvm',
                         {'support_vectors': svm.support_vectors_, 'dual_coef': svm.dual_coef_.ravel(),
                          'intercept': float(svm.intercept_[0]), 'gamma': 0.7 / D},
                         threshold=threshold, names=vector_names(CONFIG), info={'note': 'test', 'n': np.int64(3)})
    return X, scaler, svm, model


def test_score_equals_sklearn_decision_function(fitted):
    X, scaler, svm, model = fitted
    Y = np.vstack([data(200, seed=1), data(50, seed=2) * 3.0])
    expected = svm.decision_function(scaler.transform(Y))
    got = np.array([model.score(y) for y in Y])
    assert np.abs(got - expected).max() < 1e-9
    assert np.abs(model.scores(Y) - expected).max() < 1e-9
    assert expected.min() < model.threshold < expected.max()   # both decisions occur
    for y, e in zip(Y, expected):
        assert model.is_anomalous(y) == (e < model.threshold, pytest.approx(e, abs=1e-9))


def test_nystroem_sgd_score_equals_sklearn():
    X = data(600)
    scaler = StandardScaler().fit(X)
    Z = scaler.transform(X)
    nystroem = Nystroem(kernel='rbf', gamma=0.5 / D, n_components=80, random_state=0).fit(Z)
    sgd = SGDOneClassSVM(nu=0.05, random_state=0).fit(nystroem.transform(Z))
    model = AnomalyModel(CONFIG, scaler.mean_, scaler.scale_, 'nystroem-sgd',
                         {'components': nystroem.components_, 'normalization': nystroem.normalization_,
                          'coef': sgd.coef_.ravel(), 'offset': float(sgd.offset_[0]), 'gamma': 0.5 / D}, 0.0)
    Y = np.vstack([data(100, seed=3), data(20, seed=4) * 2.0])
    expected = sgd.decision_function(nystroem.transform(scaler.transform(Y)))
    assert np.abs(model.scores(Y) - expected).max() < 1e-9
    assert abs(model.score(Y[-1]) - expected[-1]) < 1e-9


def test_save_load_round_trip(fitted, tmp_path):
    _, _, _, model = fitted
    path = str(tmp_path / 'model.json')
    assert model.save(path) == path
    assert os.listdir(str(tmp_path)) == ['model.json']     # no temporary file left
    document = json.load(open(path))
    assert document['format'] == 'cc_log-model' and document['version'] == 1
    assert document['config'] == CONFIG.to_dict() and document['kind'] == 'ocsvm'
    loaded = AnomalyModel.load(path)
    assert loaded.config == CONFIG and loaded.threshold == model.threshold and loaded.names == model.names
    assert loaded.info == {'note': 'test', 'n': 3}
    for key, value in model.kernel.items():  # every float back bit for bit
        assert np.array_equal(loaded.kernel[key], value), key
    assert np.array_equal(loaded.mean, model.mean) and np.array_equal(loaded.scale, model.scale)
    Y = data(50, seed=5)
    assert loaded.scores(Y) == approx_floats(model.scores(Y))  # arrays elsewhere in memory: BLAS may round apart


def expect_refused(path, what):
    with pytest.raises(ModelError) as error:
        AnomalyModel.load(str(path))
    message = str(error.value)
    assert message.startswith(str(path) + ': ') and what in message, message


def test_pickle_and_joblib_payloads_are_refused(fitted, tmp_path):
    _, _, svm, model = fitted
    path = tmp_path / 'model.pkl'
    with open(str(path), 'wb') as stream:
        pickle.dump(svm, stream)
    expect_refused(path, 'pickle')
    joblib = pytest.importorskip('joblib')
    path = tmp_path / 'model.joblib'
    joblib.dump(model.to_dict(), str(path))
    expect_refused(path, 'pickle')
    path = tmp_path / 'compressed.joblib'
    joblib.dump(svm, str(path), compress=3)
    expect_refused(path, 'not a cc_log model')


def test_foreign_garbled_and_invalid_json_refused(fitted, tmp_path):
    _, _, _, model = fitted
    good = model.to_dict()

    def write(name, text):
        path = tmp_path / name
        path.write_text(text)
        return path

    expect_refused(write('foreign.json', json.dumps({'weights': [1, 2, 3]})), 'not a cc_log model')
    expect_refused(write('list.json', '[1, 2]'), 'not a cc_log model')
    expect_refused(write('garbled.json', json.dumps(good)[:-40]), 'invalid JSON')
    expect_refused(tmp_path / 'missing.json', 'cannot read')

    def variant(name, change, what):
        document = json.loads(json.dumps(good))
        change(document)
        expect_refused(write(name, json.dumps(document)), what)

    variant('version.json', lambda d: d.update(version=2), 'version')
    variant('kind.json', lambda d: d.update(kind='isolation-forest'), 'kind')
    variant('config.json', lambda d: d['config'].update(feature_set='fancy'), 'feature_set')
    variant('mean.json', lambda d: d['scaler'].update(mean=d['scaler']['mean'][:-1]), 'scaler.mean')
    variant('scale.json', lambda d: d['scaler']['scale'].__setitem__(0, 0.0), 'scale')
    variant('coef.json', lambda d: d['kernel'].update(dual_coef=d['kernel']['dual_coef'][1:]), 'dual_coef')
    variant('sv.json', lambda d: d['kernel']['support_vectors'][0].append(1.0), 'support_vectors')
    variant('sv_cols.json', lambda d: d['kernel'].update(
        support_vectors=[row[:-1] for row in d['kernel']['support_vectors']]), 'support_vectors')
    variant('gamma.json', lambda d: d['kernel'].update(gamma='0.1'), 'gamma')
    variant('bool.json', lambda d: d.update(threshold=True), 'threshold')
    variant('nokernel.json', lambda d: d.pop('kernel'), 'kernel')
    variant('extra.json', lambda d: d['kernel'].update(code='__import__("os")'), 'unknown')
    variant('names.json', lambda d: d.update(names=['a']), 'names')
    nan_text = json.dumps(good).replace('"threshold":', '"threshold": NaN, "x":', 1)
    expect_refused(write('nan.json', nan_text), 'NaN')
    inf_text = json.dumps(good, allow_nan=True).replace('"intercept": ', '"intercept": -Infinity, "y": ', 1)
    expect_refused(write('inf.json', inf_text), 'Infinity')


def test_check_config(fitted):
    _, _, _, model = fitted
    model.check_config(FeatureConfig('motion', '5000ms'))
    model.check_config(CONFIG.to_dict())
    for other in (FeatureConfig('motion', '2s'), FeatureConfig('motion', '500'), FeatureConfig('raw', '50')):
        with pytest.raises(ModelError, match='window|feature_set'):
            model.check_config(other)
    with pytest.raises(ModelError):
        model.score(np.zeros(D + 1))


def test_constructor_validates_shapes():
    with pytest.raises(ModelError, match='scaler.mean'):
        AnomalyModel(CONFIG, np.zeros(3), np.ones(3), 'ocsvm',
                     {'support_vectors': np.zeros((2, 3)), 'dual_coef': np.ones(2), 'intercept': 0.0, 'gamma': 1.0}, 0)
    with pytest.raises(ModelError, match='finite'):
        AnomalyModel(CONFIG, np.zeros(D), np.ones(D), 'ocsvm',
                     {'support_vectors': np.full((2, D), np.nan), 'dual_coef': np.ones(2), 'intercept': 0.0,
                      'gamma': 1.0}, 0)


def test_far_vectors_score_lower_the_further_they_are_and_equal_sklearn_near(fitted):
    """Far from every support vector the RBF sum underflows and scikit-learn gives every vector the same floor
    score; the model goes on ranking them (the log of the sum), finite, and equals scikit-learn above the joint."""
    X, scaler, svm, model = fitted
    centre = X.mean(axis=0)
    direction = X.std(axis=0)
    far = np.array([centre + k * direction for k in (5.0, 10.0, 40.0, 1e3, 1e5)])
    plain = svm.decision_function(scaler.transform(far))
    assert plain[-1] == plain[-2] == plain[-3]                   # scikit-learn: all at its floor
    got = model.scores(far)
    assert np.all(np.isfinite(got)) and np.all(np.diff(got) < 0)  # further is lower, never -inf
    assert np.allclose(got, [model.score(v) for v in far], rtol=1e-9, atol=1e-9)
    joint = FLOOR_FRACTION * -svm.intercept_[0]
    near = np.vstack([data(200, seed=1), far])
    sums = svm.decision_function(scaler.transform(near)) - svm.intercept_[0]
    above = sums >= joint
    assert above.sum() > 100 and (~above).sum() >= 3
    assert np.abs(model.scores(near)[above] - (sums[above] + svm.intercept_[0])).max() < 1e-9
    assert np.all(model.scores(near)[~above] <= joint + svm.intercept_[0] + 1e-12)


def test_the_continued_score_meets_the_plain_one_at_the_joint(fitted):
    """Same value and slope where the kernel sum crosses FLOOR_FRACTION of -intercept."""
    _, _, svm, model = fitted
    joint = FLOOR_FRACTION * -svm.intercept_[0]
    d2 = np.zeros((3, len(svm.dual_coef_.ravel())))
    sums = joint * np.array([1.0 - 1e-6, 1.0, 1.0 + 1e-6])
    # rows whose kernel sums are exactly ``sums``: every centre at the distance giving that sum
    total = svm.dual_coef_.ravel().sum()
    d2[:] = (-np.log(sums / total) / model.kernel['gamma'])[:, None]
    scores = model._continued(sums, d2)
    plain = sums + svm.intercept_[0]
    assert np.abs(scores - plain).max() < 1e-12 * max(1.0, abs(svm.intercept_[0]))
