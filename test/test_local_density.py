"""The envelope's local-density part (``learning.local_density``): scikit-learn's LOF in numpy, its file block, its
place in the envelope trigger (pure numpy and synthetic data; the CLI on the Husky's real odometry)."""
import json
import os
import re
import sys

import numpy as np
import pytest
from conftest import approx_floats

import test_envelope as te
from cc_log.features.envelope import ENVELOPE_COLUMNS
from cc_log.learning import envelope, local_density

BENCH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'bench')
COL = {name: i for i, name in enumerate(ENVELOPE_COLUMNS)}
SIZE = len(ENVELOPE_COLUMNS)


def spread_windows(n=600, seed=0):
    """Training windows of every feature spread at its own scale (no two alike)."""
    rng = np.random.default_rng(seed)
    return np.abs(rng.normal(1.0, 0.3, (n, SIZE))) * rng.uniform(0.1, 10.0, SIZE)


def probes(train, seed=1):
    """Windows from typical to far out: typical ones pushed along random directions, near and far."""
    rng = np.random.default_rng(seed)
    typical = np.median(train, axis=0)
    return np.abs(typical + np.geomspace(0.05, 4.0, 300)[:, None] * rng.normal(0.0, 1.0, (300, SIZE)) *
                  train.std(axis=0))


def test_scores_are_scikit_learns_local_outlier_factor_and_decisions_match_at_every_level():
    """``LocalOutlierFactor(n_neighbors=20, novelty=True)`` on StandardScaler's windows: its ``score_samples`` and
    ``negative_outlier_factor_``; flagged at level L where its score < median - L x (median - lowest)."""
    from sklearn.neighbors import LocalOutlierFactor
    from sklearn.preprocessing import StandardScaler
    train = spread_windows()
    train[:, COL['still_fraction']] = 0.0                  # a constant feature: scale 1, as StandardScaler
    local = local_density.learn(train)
    scaler = StandardScaler().fit(train)
    assert local.k == 20 and local.mean == approx_floats(scaler.mean_) and local.scale == approx_floats(scaler.scale_)
    lof = LocalOutlierFactor(n_neighbors=20, novelty=True).fit(scaler.transform(train))
    assert local.training.ravel() == approx_floats(scaler.transform(train).ravel())
    assert local.training_scores() == approx_floats(lof.negative_outlier_factor_)
    nof = lof.negative_outlier_factor_
    assert (local.typical, local.extreme) == approx_floats((np.median(nof), nof.min()))
    rows = probes(train)
    theirs = lof.score_samples(scaler.transform(rows))
    assert local.scores(rows) == approx_floats(theirs)
    assert local.scores(rows[7]) == approx_floats(theirs[7])            # one window alike
    for level in (1.0, 2.0, 6.0):
        flagged = theirs < np.median(nof) - level * (np.median(nof) - nof.min())
        assert 0 < flagged.sum() < len(rows), level
        assert list(local.ratios(rows, level) > 1) == list(flagged), level
    local_density.CHUNK_BYTES, chunk = 4096, local_density.CHUNK_BYTES    # many small chunks: the same scores
    try:
        assert local.scores(rows) == approx_floats(theirs)
    finally:
        local_density.CHUNK_BYTES = chunk


def test_too_few_windows_give_no_part_and_many_are_evenly_subsampled():
    train = spread_windows(n=40)
    assert local_density.learn(train[:20]) is None and local_density.shortfall(20) == \
        '20 training windows, fewer than 21'
    assert local_density.learn(train[:21]) is not None and local_density.shortfall(21) == ''
    assert envelope.learn([train[:20]], te.ODOM, 1.0, 0.25, 5.0).local is None
    assert envelope.learn([train], te.ODOM, 1.0, 0.25, 10.0, local=False).local is None
    many = np.arange(25000, dtype=float)[:, None] * np.ones(SIZE)
    kept = local_density.subsample(many)
    assert len(kept) == local_density.MAX_WINDOWS and kept[0, 0] == 0 and kept[-1, 0] == 24999
    assert np.diff(kept[:, 0]).min() >= 2 and np.diff(kept[:, 0]).max() <= 3


def test_identical_standing_still_windows_count_once():
    """A robot standing still makes many identical windows: learned on the distinct ones, a window next to them
    (standing, turning a little) is as ordinary as they are (with the copies, their density would be
    unbounded and its factor in the millions)."""
    train = spread_windows(n=600)
    still = np.zeros(SIZE)
    still[COL['still_fraction']] = 1.0
    local = local_density.learn(np.vstack([train, np.tile(still, (200, 1))]))
    assert len(local.training) == 601 and local == local_density.learn(np.vstack([train, still]))
    near = still.copy()
    near[COL['still_yaw_rate']] = 0.05 * train[:, COL['still_yaw_rate']].std()
    assert local.ratios(near[None], envelope.DEFAULT_LOCAL_FACTOR)[0] < 1
    assert np.array_equal(local_density.distinct(np.array([[2.0], [1.0], [2.0]])), [[2.0], [1.0]])


def two_kinds_of_driving(n=1000, seed=0):
    """Nominal windows of two kinds: slow (0.3 m/s) and fast (0.9 m/s), each tight, every other feature moving
    with one common driving parameter alike in both; and a window halfway between them (0.6 m/s), typical in
    every other feature."""
    rng = np.random.default_rng(seed)
    slope = rng.uniform(0.5, 2.0, SIZE)
    train = 1.0 + np.outer(rng.uniform(0.0, 1.0, 2 * n), slope) + rng.normal(0.0, 0.001, (2 * n, SIZE))
    train[:, COL['max_speed']] = np.concatenate([rng.normal(0.3, 0.01, n), rng.normal(0.9, 0.01, n)])
    gap = 1.0 + 0.5 * slope
    gap[COL['max_speed']] = 0.6
    return train, gap


def test_a_window_in_a_sparse_gap_between_two_kinds_of_driving_is_flagged_by_the_local_part_alone():
    train, gap = two_kinds_of_driving()
    env = envelope.learn([train], te.ODOM, 1.0, 0.25, 500.0)
    assert env.joint is not None and env.local is not None
    limits = env.limits()
    assert np.all(gap < train.max(axis=0))                               # inside every limit
    assert envelope.scores(gap[None], limits)[0] > 0                     # per feature: nothing
    assert env.joint.ratios(gap[None])[0] < 1                            # the joint check: nothing
    assert envelope.scores(gap[None], limits, env.joint)[0] > 0
    assert env.local.ratios(gap[None], envelope.DEFAULT_LOCAL_FACTOR)[0] > 1
    assert envelope.scores(gap[None], limits, env.joint, local=env.local)[0] < 0      # the local part: flagged
    assert envelope.scores(gap[None], limits, env.joint, local=env.local, local_factor=0)[0] > 0   # 0: off
    assert np.all(envelope.scores(train, limits, env.joint, local=env.local) >= 0)  # no training window is
    why, = envelope.explain(gap, env)
    assert (why['feature'], why['unit']) == ('local', '1')
    score = float(env.local.scores(gap))
    assert why['value'] == approx_floats(-score) and why['limit'] == approx_floats(-env.local.extreme)
    assert why['ratio'] == approx_floats((env.local.typical - score) / (env.local.typical - env.local.extreme))
    match = re.match(r"^unusual for its neighbourhood \((.+)\): local outlier factor ([\d.]+), ([\d.]+)x beyond "
                     r"training's spread$", why['text'])
    assert match, why['text']
    assert match.group(1).startswith('speed') and float(match.group(3)) == pytest.approx(why['ratio'], rel=0.05)
    assert envelope.explain(gap, env, local_factor=0) == ()


def test_the_trigger_flags_the_gap_says_why_and_its_local_factor_is_checked():
    from cc_log.triggers.envelope import EnvelopeTrigger
    env = te.learned(te.nominal_drive(seed=0))
    assert env.local is not None
    trigger = EnvelopeTrigger('envelope', env, te.ODOM)
    assert te.fires_of(trigger, te.odom_records(te.nominal_drive(seed=0))) == []   # the training itself
    described = trigger.describe()
    assert described['local_factor'] == 6.0 and described['local'] == {
        'k': 20, 'windows': len(env.local.training), 'typical': env.local.typical, 'extreme': env.local.extreme}
    off = EnvelopeTrigger('envelope', env, te.ODOM, local_factor=0)
    assert off.local is None and off.describe()['local'] is None
    for bad in (0.5, -1, 'x', True, float('nan')):
        with pytest.raises(ValueError, match='^envelope: local_factor: .* must be 0 \\(off\\) or a number from 1 up'):
            EnvelopeTrigger('envelope', env, te.ODOM, local_factor=bad)


def test_envelope_files_of_version_2_load_without_the_local_part_and_decide_as_before(tmp_path):
    """A file written before the local part (version 2): no local part, the trigger's fires (stamps, scores, why)
    those of the same envelope with the local part off."""
    from cc_log.learning.envelope import Envelope
    from cc_log.triggers.envelope import EnvelopeTrigger
    env = te.learned(te.nominal_drive(seed=0))
    document = env.to_dict()
    assert document['version'] == 4 and set(document['local']) == set(local_density._COMPACT_KEYS)
    old = dict({key: value for key, value in document.items() if key != 'local'}, version=2)
    path = tmp_path / 'v2.json'
    path.write_text(json.dumps(old))
    loaded = Envelope.load(str(path))
    assert loaded.local is None and loaded == env._replace(local=None) and loaded.joint == env.joint
    samples = te.nominal_drive(seconds=40, seed=3)
    v = samples[4].copy()
    v[1000:1100] = 0.05      # crawling while turning as usual: new jointly and locally
    records = te.odom_records(te.drive(v, samples[5]))
    before = te.fires_of(EnvelopeTrigger('envelope', loaded, te.ODOM), records)
    off = te.fires_of(EnvelopeTrigger('envelope', env, te.ODOM, local_factor=0), records)
    now = te.fires_of(EnvelopeTrigger('envelope', env, te.ODOM, local_factor=1), records)
    assert before and [(s, f.score, f.why) for s, f in before] == [(s, f.score, f.why) for s, f in off]
    assert any('local' in [entry['feature'] for entry in fire.why] for _, fire in now)
    assert all('local' not in [entry['feature'] for entry in fire.why] for _, fire in before)
    path.write_text(json.dumps(dict(old, local=document['local'])))
    with pytest.raises(ValueError, match="v2.json: unknown key 'local'$"):
        Envelope.load(str(path))
    path.write_text(json.dumps(dict(document, local=None)))
    assert Envelope.load(str(path)).local is None
    env.save(str(path))
    assert Envelope.load(str(path)) == env


def version_3(document):
    """The version 3 document of a version 4 one (``Envelope.to_dict``): the local block's arrays as lists."""
    local = document['local']
    if local is not None:
        shapes = {'mean': (SIZE,), 'scale': (SIZE,), 'training': (local['windows'], SIZE),
                  'distances': (local['windows'],), 'densities': (local['windows'],)}
        local = dict({key: value for key, value in local.items() if key not in ('encoding', 'windows')},
                     **{key: local_density.decode_array(local[key], shapes[key], key).tolist() for key in shapes})
    return dict(document, version=3, local=local)


def test_damaged_local_blocks_of_version_3_are_refused_in_one_line(tmp_path):
    from cc_log.learning.envelope import Envelope
    env = envelope.learn([spread_windows(n=60)], te.ODOM, 1.0, 0.25, 15.0)
    document = version_3(env.to_dict())
    local = document['local']
    path = str(tmp_path / 'envelope.json')
    training = [list(row) for row in local['training']]
    training[5] = training[5][:18]
    nan = [list(row) for row in local['training']]
    nan[3][2] = 'x'
    cases = [([1], 'local: must map k, mean, scale, training, distances, densities, typical, extreme to numbers'),
             (dict(local, extra=1), "(unknown key 'extra')"),
             (dict(local, k=60), 'local: training: must be a list of more than k=60 and at most 10000 windows'),
             (dict(local, k=10 ** 12), 'local: k: 1000000000000 must be a count of neighbours from 1 to 1000'),
             (dict(local, k=True), 'local: k: True must be a count'),
             (dict(local, training=[[0.0] * SIZE] * 10001), 'local: training: must be a list of more than k=20 and '
                                                            'at most 10000 windows'),
             (dict(local, training=training), 'local: training: must be 60 x 19 numbers'),
             (dict(local, training=nan), "local: training: 'x' is not a finite number"),
             (dict(local, mean=local['mean'][:18]), 'local: mean: must be 19 numbers'),
             (dict(local, distances=local['distances'][:59]), 'local: distances: must be 60 numbers'),
             (dict(local, scale=[0.0] * SIZE), 'local: scale: every entry must be positive'),
             (dict(local, densities=[-1.0] * 60), 'local: densities: every entry must be positive'),
             (dict(local, distances=[-1.0] * 60), 'local: distances: every entry must be non-negative'),
             (dict(local, typical=local['extreme']), 'local: extreme %r must be below typical' % local['extreme']),
             (dict(local, extreme='low'), "local: extreme: 'low' must be a finite number")]
    te.assert_blocks_refused(path, document, 'local', cases)
    with open(path, 'w') as stream:
        stream.write(json.dumps(document).replace(json.dumps(local['typical']), 'NaN', 1))
    with pytest.raises(ValueError, match='NaN is not a number JSON allows'):
        Envelope.load(path)


def test_version_4_files_hold_the_local_part_compactly_and_decide_exactly_as_version_3_files(tmp_path):
    """Version 4 (``cclog learn-envelope`` writes it): the local block's arrays as float64 in base64, bit for bit
    the numbers learned, in well under half the bytes of version 3's lists, which still load: the same envelope,
    the same fires (stamps, scores, why) on the same windows."""
    import base64
    from cc_log.learning.envelope import Envelope
    from cc_log.triggers.envelope import EnvelopeTrigger
    env = te.learned(te.nominal_drive(seed=0))
    new, old = str(tmp_path / 'v4.json'), str(tmp_path / 'v3.json')
    env.save(new)
    document = json.loads(open(new).read())
    local = document['local']
    assert document['version'] == 4 and local['encoding'] == 'float64 little-endian, base64'
    assert local['windows'] == len(env.local.training) > 100 and local['k'] == 20
    assert np.array_equal(np.frombuffer(base64.b64decode(local['training']), '<f8'), env.local.training.ravel())
    with open(old, 'w') as stream:
        json.dump(version_3(document), stream, indent=1)
    assert os.path.getsize(new) < 0.6 * os.path.getsize(old)
    assert Envelope.load(new) == env and Envelope.load(old) == env
    samples = te.nominal_drive(seconds=40, seed=3)
    v = samples[4].copy()
    v[1000:1100] = 0.05      # crawling while turning as usual: new jointly and locally
    records = te.odom_records(te.drive(v, samples[5]))
    fired = [[(s, f.score, f.why) for s, f in te.fires_of(EnvelopeTrigger('envelope', Envelope.load(path), te.ODOM,
                                                                          local_factor=1), records)]
             for path in (new, old)]
    assert fired[0] and fired[0] == fired[1]
    assert any('local' in [entry['feature'] for entry in why] for _, _, why in fired[0])


def test_damaged_compact_local_blocks_are_refused_in_one_line(tmp_path):
    from cc_log.learning.envelope import Envelope
    env = envelope.learn([spread_windows(n=60)], te.ODOM, 1.0, 0.25, 15.0)
    document = env.to_dict()
    local = document['local']
    encode = local_density.encode_array
    nan = env.local.training.copy()
    nan[3, 2] = np.nan
    cases = [([1], 'local: must map k, encoding, windows, mean, scale, training, distances, densities, typical, '
                   'extreme'),
             (dict(local, extra=1), "(unknown key 'extra')"),
             (dict(local, encoding='float32'), "local: encoding: 'float32', this cc_log reads 'float64 little-endian, "
                                               "base64'"),
             (dict(local, windows=20), 'local: windows: must be a count of more than k=20 and at most 10000 windows'),
             (dict(local, windows='60'), 'local: windows: must be a count of more than k=20'),
             (dict(local, windows=61), 'local: training: must be 61 x 19 numbers, float64 little-endian, base64 in '
                                       '12364 characters'),
             (dict(local, training=local['training'][:-4]), 'local: training: must be 60 x 19 numbers'),
             (dict(local, training=env.local.training.tolist()), 'local: training: must be 60 x 19 numbers'),
             (dict(local, mean=encode(env.local.mean[:18])), 'local: mean: must be 19 numbers'),
             (dict(local, distances='!' * len(local['distances'])), 'local: distances: not float64 little-endian, '
                                                                    'base64'),
             (dict(local, densities='\u00e9' * len(local['densities'])), 'local: densities: not float64'),
             (dict(local, training=encode(nan)), 'local: training: entry 59 is not a finite number'),
             (dict(local, scale=encode(np.zeros(SIZE))), 'local: scale: every entry must be positive'),
             (dict(local, distances=encode(-np.ones(60))), 'local: distances: every entry must be non-negative'),
             (dict(local, k=10 ** 12), 'local: k: 1000000000000 must be a count of neighbours from 1 to 1000'),
             (dict(local, typical=local['extreme']), 'local: extreme %r must be below typical' % local['extreme'])]
    path = str(tmp_path / 'envelope.json')
    te.assert_blocks_refused(path, document, 'local', cases)
    with open(path, 'w') as stream:     # a version 3 file with a compact block, a version 4 one with lists
        json.dump(dict(document, version=3), stream)
    with pytest.raises(ValueError, match='local: must map k, mean, scale, .* to numbers .unknown key .encoding.'):
        Envelope.load(path)
    with open(path, 'w') as stream:
        json.dump(dict(version_3(document), version=4), stream)
    with pytest.raises(ValueError, match='local: must map k, encoding, windows, mean, '):
        Envelope.load(path)


def test_the_neighbours_are_those_of_every_distance_bit_for_bit():
    """``_nearest`` picks its candidates by a matrix product, then computes their distances as ``_nearest_brute``
    does from every difference: the same indices and distances, exactly, with ties (the lower index first), windows
    that repeat a training window, the window itself left out, and values too large to square."""
    rng = np.random.default_rng(7)
    for trial in range(60):
        n = int(rng.integers(31, 400))
        train = rng.normal(0.0, 1.0, (n, SIZE)) * rng.uniform(0.01, 100.0, SIZE)
        if trial % 3 == 0:
            train = np.round(train, 0)     # many equal distances
        rows = train[rng.integers(0, n, 30)] + (trial % 4) * 1e-3 * rng.normal(0.0, 1.0, (30, SIZE))
        k = int(rng.integers(1, 21))
        for found, brute in ((local_density._nearest(rows, train, k), local_density._nearest_brute(rows, train, k)),
                             (local_density._nearest(train[:30], train, k, exclude=np.arange(30)),
                              local_density._nearest_brute(train[:30], train, k, exclude=np.arange(30)))):
            assert np.array_equal(found[0], brute[0]) and np.array_equal(found[1], brute[1]), trial
    huge = rows.copy()
    huge[0, 3] = 1e200
    found, brute = local_density._nearest(huge, train, 5), local_density._nearest_brute(huge, train, 5)
    assert np.array_equal(found[0], brute[0]) and np.array_equal(found[1], brute[1])


def test_scoring_a_batch_computes_the_differences_of_its_candidates_only():
    """A batch of 25 windows against 10,000 training windows: every difference (25 x 10,000 x 19 floats) would
    take 38 MB; the candidates' differences and the matrix product's estimates (25 x 10,000) take a few."""
    import tracemalloc
    train = spread_windows(n=10000, seed=3)
    local = local_density.learn(train[:2000])
    local = local._replace(training=local.standardised(train), distances=np.ones(10000), densities=np.ones(10000))
    rows = probes(train)[:25]
    tracemalloc.start()
    try:
        local.scores(rows)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8e6, peak


def test_the_default_flags_exactly_what_the_benchmarks_env2_maha4_lof6_flags():
    """The trigger's rule (the envelope at 2x, the joint check at 4, the local part at 6) and the bench's candidate
    ``env2|maha4|lof6`` (``detector_candidates.Either`` of its envelope, mahalanobis and lof) on the same windows."""
    sys.path.insert(0, BENCH)
    import detectors
    train, gap = two_kinds_of_driving()
    rng = np.random.default_rng(4)    # training windows pushed off their kind of driving, near and far
    near = train[::20] + np.geomspace(1e-4, 0.2, 100)[:, None] * rng.normal(0.0, 1.0, (100, SIZE)) * train.std(0)
    rows = np.vstack([near, gap, 2.5 * train[:20]])
    found = detectors.make_detectors(candidates=True)
    for name in ('envelope', 'mahalanobis', 'lof'):
        found[name].fit(train)
    either = found['env2|maha4|lof6'].fit(train)
    theirs = either.score(rows) < either.threshold(2.0)
    env = envelope.learn([train], te.ODOM, 1.0, 0.25, 500.0)
    ours = envelope.scores(rows, env.limits(), env.joint, 4.0, env.local, 6.0) < 0
    assert 0 < ours.sum() < len(rows)
    assert list(ours) == list(theirs)
    lof = found['lof']
    local_only = (lof.score(rows) < lof.threshold(6.0)) & ~(envelope.scores(rows, env.limits(), env.joint) < 0)
    assert local_only.any()     # the local part decides some of them


def test_cclog_learn_envelope_says_the_local_part_and_its_windows_say_why_in_info(tmp_path, husky_surge):
    """``cclog learn-envelope`` learns the local part (unless --no-local) and says its figures on its last line;
    ``cclog replay --model`` with a local factor low enough that the local part opens windows: their metadata
    and ``cclog info`` carry its why."""
    from conftest import cclog
    from cc_log.learning.envelope import Envelope
    from cc_log.storage import log_format
    out = tmp_path / 'envelope.json'
    result = cclog('learn-envelope', husky_surge['train'], '--out', out)
    assert result.returncode == 0, result.stderr
    learned = Envelope.load(str(out))
    local = learned.local
    assert local is not None and len(local.training) == learned.windows
    last = result.stdout.strip().splitlines()[-1]
    assert last == 'local part over %d windows, 20 neighbours: local outlier factor %.4g typical (median), %.4g ' \
        'the largest; flagged beyond %.4g (local_factor 6)' % (
            learned.windows, -local.typical, -local.extreme, -local.typical + 6 * (local.typical - local.extreme)), last
    config = tmp_path / 'config.yaml'
    config.write_text('driving_topic: %s\nformat: json-xz\nwindows: {pre: 1s, post: 1s}\ntriggers:\n'
                      '  - {name: envelope, kind: envelope, limits: %s, local_factor: 1}\n' % (te.HUSKY_ODOM, out))
    result = cclog('replay', husky_surge['injected'], '--config', config, '--out', tmp_path / 'logs', '--json')
    assert result.returncode == 0, result.stderr
    said = []
    for window in json.loads(result.stdout)['windows']:
        metadata = log_format.read_window(window['path'])[0]
        for fired in metadata['triggers']:
            said += [(window['path'], entry) for entry in fired.get('why', ()) if entry['feature'] == 'local']
    assert said, 'no window opened by the local part at local_factor 1'
    _, entry = said[0]
    assert entry['text'].startswith('unusual for its neighbourhood') and entry['ratio'] > 1
    info = cclog('info', tmp_path / 'logs')
    assert info.returncode == 0, info.stderr
    assert 'unusual for its neighbourhood' in info.stdout, info.stdout
    result = cclog('learn-envelope', husky_surge['train'], '--out', out, '--no-local', '--json')
    assert result.returncode == 0 and json.loads(result.stdout)['local'] is None
    assert Envelope.load(str(out)).local is None


husky_surge = te.husky_surge
