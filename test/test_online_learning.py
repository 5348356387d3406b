"""Online learning of nominal (cc_log.online_learning through the classifier trigger; no roscore)."""
import json
import os
import sys

import numpy as np
import pytest

from cc_log.logger import config
from cc_log.learning import drift, learning, online_learning
from cc_log import sim
from cc_log.features import FeatureConfig
from cc_log.learning.model import AnomalyModel
from cc_log.learning.online_learning import OnlineLearner
from cc_log.triggers import ClassifierTrigger
from cc_log.base.records import Record

from conftest import approx_floats

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'bench'))
from learn_online import flag_starts, odometry, slow_model  # noqa: E402  (the bench's runs and counting)


def small_model(dimension=13, seed=0):
    rng = np.random.RandomState(seed)
    model, _ = learning.train(rng.normal(size=(200, dimension)), config=FeatureConfig('progress', '1s'))
    return model


def test_a_refit_only_widens_what_the_original_finds_nominal():
    """WidenedModel: anomalous only where the original and the refit both are; batches score as single vectors."""
    rng = np.random.RandomState(1)
    original = small_model()
    refit, _ = learning.train(rng.normal(loc=6.0, size=(200, 13)), config=original.config)  # a new place only
    here, there, far = np.zeros(13), np.full(13, 6.0), np.full(13, -9.0)
    assert not original.is_anomalous(here)[0] and refit.is_anomalous(here)[0]
    assert original.is_anomalous(there)[0] and not refit.is_anomalous(there)[0]
    assert original.is_anomalous(far)[0] and refit.is_anomalous(far)[0]
    widened = online_learning.WidenedModel(original, refit)
    assert [widened.is_anomalous(v)[0] for v in (here, there, far)] == [False, False, True]
    alone = [widened.is_anomalous(v)[1] for v in (here, there, far)]
    assert widened.score_each([here, there, far]) == approx_floats(alone)  # but for a BLAS kernel's rounding
    trigger = ClassifierTrigger('classifier', original, ['/odom'], learner=OnlineLearner(original, background=False))
    trigger.learner._ready = refit
    trigger._take_learned()
    assert isinstance(trigger.model, online_learning.WidenedModel) and trigger.threshold == 0.0
    assert trigger.model.original is original and trigger.model.refit is refit


def test_in_drift_the_classifiers_own_flags_are_learned_and_other_triggers_still_guard():
    """While the drift monitor reports drift (and ADAPT_HOLD after) the classifier's own flags are the new place's
    driving: its anomalous vectors are offered and its flags ignored; a rule's flag still keeps its span out."""
    model = small_model()
    learner = OnlineLearner(model, every=10 ** 6, keep=1000, guard='2s')
    drifting = [False]
    learner.drifting = lambda: drifting[0]
    assert not learner.adapting_at(0.0)
    learner.flag(1.0, own=True)          # not in drift: the classifier's flag guards
    learner.offer(2.0, np.zeros(13))
    assert learner.refused == 1
    drifting[0] = True
    assert learner.adapting_at(10.0)
    drifting[0] = False
    assert learner.adapting_at(10.0 + online_learning.ADAPT_HOLD) and not learner.adapting_at(
        10.5 + online_learning.ADAPT_HOLD)
    learner.adapting_at(11.0 + online_learning.ADAPT_HOLD)
    drifting[0] = True
    start = 20.0 + online_learning.ADAPT_HOLD
    for step in range(100):            # 10 s, every one flagged by the classifier itself
        stamp = start + 0.1 * step
        assert learner.adapting_at(stamp)
        learner.flag(stamp, own=True)
        if step == 50:
            learner.flag(stamp)        # a rule: nothing within 2 s of it is learned
        learner.offer(stamp, np.full(13, stamp))
    learner.offer(start + 20.0, np.zeros(13))  # flushes what waited the guard
    learned = sorted(vector[0] for _, vector in learner._reservoir)
    assert learned and all(abs(s - (start + 5.0)) > 2.0 for s in learned)
    assert len(learned) == sum(1 for step in range(100) if abs(0.1 * step - 5.0) > 2.0 + 1e-9)


def test_a_classifier_in_drift_offers_its_anomalous_vectors(tmp_path):
    """The trigger offers what it flags while its learner adapts (drift.monitor_classifiers wires the monitor)."""
    from cc_log.learning import drift
    model, _ = slow_model(20.0), None
    learner = OnlineLearner(model, every=10 ** 6, keep=5000, guard='1s', background=False)
    trigger = ClassifierTrigger('classifier', model, '/odom', classify_every='100ms', learner=learner)
    monitor, = drift.monitor_classifiers([trigger])
    fast, _ = odometry(sim.SimConfig(rate=20.0, seed=22, minutes=4, anomalies=0))   # full speed: flagged often
    for stamp, msg in fast:
        trigger.on_record(Record(stamp, '/odom', msg))
    assert monitor.first_drift is not None and learner.adapted > 0
    assert learner.stats()['vectors_adapted'] == learner.adapted


def test_nothing_from_around_a_flag_is_learned():
    """Vectors within guard (2 s) of a flag, before or after it, never reach the reservoir; the others all do."""
    model = small_model()
    learner = OnlineLearner(model, every=10 ** 6, keep=1000, guard='2s')
    flags = (10.0, 30.0, 30.5)
    for step in range(600):
        stamp = 0.1 * step
        if any(abs(stamp - flag) < 1e-9 for flag in flags):
            learner.flag(stamp)
        else:
            learner.offer(stamp, np.full(13, stamp))
    learned = sorted(vector[0] for _, vector in learner._reservoir)
    assert learned and all(min(abs(s - f) for f in flags) > 2.0 for s in learned)
    near = [0.1 * i for i in range(600) if 0 < min(abs(0.1 * i - f) for f in flags) <= 2.0]
    stats = learner.stats()
    assert stats['vectors_refused'] == len(near)
    assert stats['vectors_learned'] + stats['vectors_refused'] + len(learner._pending) == 600 - len(flags)
    assert stats['refits'] == 0 and stats['last_refit'] is None


def test_the_reservoir_is_bounded_and_a_refit_is_saved_beside_the_model(tmp_path):
    """keep bounds the reservoir; every ``every`` vectors a refit is saved to model.online.json (atomically:
    no temporary file left), the original model file is untouched, and the classifier takes the new model."""
    path = tmp_path / 'model.json'
    model = small_model()
    model.save(str(path))
    before = path.read_bytes()
    learner = OnlineLearner(AnomalyModel.load(str(path)), online_learning.online_path(str(path)), every=150,
                            keep=100, guard='1s', background=False)
    rng = np.random.RandomState(1)
    for step in range(400):
        learner.offer(0.1 * step, rng.normal(size=13))
    stats = learner.stats()
    assert stats['reservoir'] == 100 and stats['refits'] == 2 and stats['last_error'] is None
    assert path.read_bytes() == before
    saved = AnomalyModel.load(str(tmp_path / 'model.online.json'))
    assert saved.info['online']['refit'] == 2 and saved.info['online']['reservoir'] == 100
    assert sorted(os.listdir(str(tmp_path))) == ['model.json', 'model.online.json']
    assert learner.take() is not None and learner.take() is None


def test_a_restarted_classifier_resumes_the_refit_of_its_own_model_only(tmp_path):
    """A node restarted with learn_online goes on from the refit it saved: the classifier scores with the original
    widened by it at its first message, and the refit's training vectors seed the reservoir. A refit of another
    model (retrained since), a damaged file or ``learn_resume: false`` start afresh, saying why."""
    path = str(tmp_path / 'model.json')
    small_model().save(path)
    first = OnlineLearner(AnomalyModel.load(path), online_learning.online_path(path), every=150, keep=100,
                          guard='1s', background=False)
    rng = np.random.RandomState(2)
    for step in range(200):
        first.offer(0.1 * step, rng.normal(loc=3.0, size=13))   # a new place: refitted once
    assert first.stats()['refits'] == 1

    def build(options):
        entry = dict({'name': 'c', 'kind': 'classifier', 'model': path, 'topics': ['/odom'], 'learn_online': True},
                     **options)
        trigger, = config.Config.from_dict({'triggers': [entry]}).build_triggers(AnomalyModel.load, lambda t: None)
        return trigger

    trigger = build({})
    assert trigger.learner.resumed.startswith('resumed from %s (its refit 1' % online_learning.online_path(path))
    assert trigger.describe()['online'] == trigger.learner.resumed
    assert trigger.learner.stats()['reservoir'] == len(online_learning.training_support(first.take()))
    trigger._take_learned()
    assert isinstance(trigger.model, online_learning.WidenedModel) and trigger.model.original is not None
    there = np.full(13, 3.0)
    assert trigger.original.is_anomalous(there)[0] and not trigger.model.is_anomalous(there)[0]

    document = json.loads(open(online_learning.online_path(path)).read())
    document['info']['online']['refit'] = 'x' * 500          # only numbers are shown of what the file says
    with open(online_learning.online_path(path), 'w') as stream:
        json.dump(document, stream)
    assert '(its refit ?, ' in build({}).learner.resumed

    fresh = build({'learn_resume': False})
    assert fresh.learner.resumed is None and fresh.learner.stats()['reservoir'] == 0
    assert fresh.describe()['online'] == 'learning online from scratch'

    small_model(seed=5).save(path)                            # retrained: the saved refit widens another model
    assert build({}).learner.resumed == ('not resumed: %s widens another model (replaced at the next refit)'
                                         % online_learning.online_path(path))
    small_model(seed=6).save(online_learning.online_path(path))   # a model file, not a refit
    assert build({}).learner.resumed == ('not resumed: %s names no original model (saved by an older cc_log or not '
                                         'a refit)' % online_learning.online_path(path))
    with open(online_learning.online_path(path), 'w') as stream:
        stream.write('{"format": "cc_log')
    assert build({}).learner.resumed.startswith('not resumed: %s: not a cc_log model' %
                                                online_learning.online_path(path))
    with pytest.raises(ValueError, match="learn_resume: 'no' must be true or false$"):
        build({'learn_resume': 'no'})


def test_bad_learning_options_are_named():
    model = small_model()
    for key, value, text in (('learn_online', 'yes', 'learn_online: '), ('learn_every', 0, 'learn_every: '),
                             ('learn_keep', 3, 'learn_keep: '), ('learn_guard', '100', 'learn_guard: ')):
        options = {'learn_online': True, key: value}
        with pytest.raises(ValueError, match='^' + text):
            online_learning.from_options(model, 'm.json', options)
    assert online_learning.from_options(model, 'm.json', {'learn_every': 5}) is None


def test_a_configuration_turns_online_learning_on(tmp_path):
    path = tmp_path / 'm.json'
    small_model().save(str(path))
    entry = {'name': 'progress', 'kind': 'classifier', 'model': str(path), 'topics': ['/odom'],
             'learn_online': True, 'learn_every': 500, 'learn_guard': '5s'}
    trigger, = config.Config.from_dict({'triggers': [entry]}).build_triggers(AnomalyModel.load, lambda t: None)
    assert trigger.learner.every == 500 and trigger.learner.guard == 5.0
    assert trigger.learner.save_path == str(tmp_path / 'm.online.json')
    assert trigger.stats()['online']['vectors_seen'] == 0
    entry['learn_online'] = False
    trigger, = config.Config.from_dict({'triggers': [entry]}).build_triggers(AnomalyModel.load, lambda t: None)
    assert trigger.learner is None and 'online' not in trigger.stats()


def test_a_refit_learns_new_manoeuvres_and_still_catches_anomalies(tmp_path):
    """A model trained on a slow robot (0.5 m/s, 0.5 rad/s) flags the full-speed robot's nominal driving over
    and over; learning online on 10 minutes of it (through the classifier trigger) refits the model, which then
    flags a quarter or less of the windows it flagged in another nominal full-speed run (it flags 60 % of the
    full-speed driving: drift, in which its own flags are learned too; 28 windows before, 1 after), and still
    catches a collision and a sudden acceleration injected after the refit."""
    rate = 20.0
    model = slow_model(rate)
    path = str(tmp_path / 'slow.json')
    model.save(path)

    learner = OnlineLearner(model, online_learning.online_path(path), every=1000, keep=3000, guard='3s',
                            background=False)
    trigger = ClassifierTrigger('classifier', model, '/odom', classify_every='100ms', learner=learner)
    drift.monitor_classifiers([trigger])   # as smart mode and cclog replay run it: in drift, flags are learned
    learning_run, _ = odometry(sim.SimConfig(rate=rate, seed=22, minutes=10, anomalies=0))
    for stamp, msg in learning_run:
        trigger.on_record(Record(stamp, '/odom', msg))
    stats = learner.stats()
    assert stats['refits'] >= 1 and stats['vectors_refused'] > 0 and stats['last_error'] is None, str(stats)
    assert trigger.model is not model and trigger.threshold == trigger.model.threshold

    held_back, _ = odometry(sim.SimConfig(rate=rate, seed=23, minutes=4, anomalies=0))
    before, after = flag_starts(model, held_back), flag_starts(trigger.model, held_back)
    assert len(before) >= 10 and len(after) <= len(before) / 4.0, (len(before), len(after))

    anomalies, truth = odometry(sim.SimConfig(rate=rate, seed=24, minutes=2, anomalies=2, gap=15.0,
                                              anomaly_types=('collision', 'sudden_acceleration')))
    starts = flag_starts(trigger.model, anomalies)
    for entry in truth:
        assert any(entry['start'] <= s <= entry['end'] + 1.0 for s in starts), (entry, starts)
    saved = json.loads(open(online_learning.online_path(path)).read())
    assert saved['info']['online']['refit'] == stats['refits']
