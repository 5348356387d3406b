"""Feature windows and window vectors computed a batch at a time (``FeatureStream.add_records``) on real bags:
every vector is ``window_vector`` of the rows the window holds by its rules written out plainly, whatever the
batch boundaries, with gaps and jumps back inside a batch; the classifier decides as record by record (its scores
equal up to the rounding of a BLAS kernel)."""
import os
import random

import numpy as np
import pytest

from cc_log.storage.bag import bagio
from cc_log import features
from cc_log.learning import learning
from cc_log.base import raw_message
from cc_log.features import FeatureConfig, FeatureStream, FeatureWindow, window_vector
from cc_log.features.base import statistics, window_statistics
from cc_log.features.window import EVERY_SLACK, JUMP_BACK_TOLERANCE
from cc_log.base.spans import Span
from cc_log.triggers import ClassifierTrigger
from cc_log.base.records import Record

from conftest import REAL_DATA, approx_floats

HUSKY = ('husky_outdoor_2015.bag', '/husky_velocity_controller/odom', '/imu/data')
F1TENTH = ('f1tenth_DS2.bag', '/odom', None)   # two gaps (one of 26 s) in its odometry
ICELAB = ('icelab_normal_plan.bag', '/odom', None)
RELATIVE = 1e-9


def bag_records(case, seconds=None, jumps=False):
    """The serialized records of a bag's odometry (and IMU), stamps from their headers; ``jumps``: a stretch of
    the stamps moved 3 s back (the window starts over) and one 0.5 s back (within the tolerance)."""
    name, odom, imu = case
    path = os.path.join(REAL_DATA, name)
    if not os.path.exists(path):
        pytest.fail('real data missing: %s' % path)
    records = []
    for record in bagio.read_raw(path, [t for t in (odom, imu) if t]):
        stamp = raw_message.stamp(record.raw, record.connection, record.stamp)
        if seconds is not None and records and stamp > records[0].stamp + seconds:
            break
        records.append(Record(stamp, record.topic, None, 0, record.raw, record.connection))
    if jumps:
        n = len(records)
        for i in range(n // 3, n // 3 + 40):
            records[i] = records[i]._replace(stamp=records[i].stamp - 3.0)
        records[n // 2] = records[n // 2]._replace(stamp=records[n // 2].stamp - 0.5)
    return records


def decoded_some(records, seed):
    """The records with every few ones decoded (a batch mixes bytes and messages: runs split there)."""
    rng = random.Random(seed)
    return [raw_message.decoded(r) if rng.random() < 0.1 else r for r in records]


class PlainStream(object):
    """``FeatureStream``'s rules written out with lists: the rows held as (clock, row) pairs and the vector of
    each due row from ``window_vector``; ``add`` returns ``(vector, rows held, reset, whole)``."""

    def __init__(self, config, every):
        self.config, self.span, self.every = config, config.span, Span.parse(every, 'every')
        self.features = config.feature(config)
        self.held, self.clock, self.filled, self.count, self.at = [], None, None, None, None

    def observe(self, record, role):
        if record.msg is None:
            self.features.observe_raw(role, record.raw, record.stamp)
        else:
            self.features.observe(role, record.msg, record.stamp)

    def add(self, record):
        stamp, span = record.stamp, self.span
        if record.msg is None:
            row = self.features.row_values_raw(record.raw, stamp)
        else:
            row = self.features.row_values(record.msg, stamp)
        covers = self.features.covers(span, stamp)
        reset = self.clock is not None and stamp < self.clock - JUMP_BACK_TOLERANCE
        if reset:
            self.held, self.clock = [], None
        self.clock = stamp if self.clock is None else max(self.clock, stamp)
        if span.is_duration:
            if not self.held or self.clock - self.held[-1][0] > span.seconds:
                self.filled = self.clock
            self.held = [(s, r) for s, r in self.held + [(self.clock, row)] if s >= self.clock - span.seconds]
            full = self.clock - self.filled >= span.seconds
        else:
            self.held = (self.held + [(self.clock, row)])[-span.count:]
            full = len(self.held) >= span.count
        whole = full and covers
        if not whole:
            self.count = self.at = None
            return None, None, reset, whole
        if self.count is not None:
            self.count += 1
            if self.every.is_duration:
                due = stamp - self.at >= self.every.seconds - EVERY_SLACK or stamp < self.at
            else:
                due = self.count >= self.every.count
            if not due:
                return None, None, reset, whole
        self.count, self.at = 0, stamp
        return window_vector([r for _, r in self.held], self.config), self.held, reset, whole


def plain_newest(held, span):
    """The rows of the newest ``span`` of (clock, row) pairs, at least one."""
    if span.is_duration:
        rows = [r for s, r in held if s >= held[-1][0] - span.seconds]
    else:
        rows = [r for _, r in held][-span.count:]
    return np.array(rows[-len(held):] or [held[-1][1]])


def assert_close(got, want, what, width=None):
    """Every entry within RELATIVE of the entry; for mean, std, min, max vectors of ``width`` columns, of the
    largest magnitude of its column where that is more (the std of a constant column, a mean near zero: both
    sides are rounding of the column's values)."""
    got, want = np.asarray(got), np.asarray(want)
    assert got.shape == want.shape, what
    scale = np.abs(want)
    if width:
        column = np.abs(want.reshape(4, width)[[0, 2, 3]]).max(axis=0)
        scale = np.maximum(scale, np.tile(column, 4))
    worst = float(np.max(np.abs(got - want) / np.where(scale > 0, scale, 1.0)))
    assert worst <= RELATIVE, '%s: relative difference %.3g' % (what, worst)


def batches(records, rng, largest):
    """The records cut at random places into batches of 1 to ``largest``."""
    out, i = [], 0
    while i < len(records):
        size = rng.randint(1, largest)
        out.append(records[i:i + size])
        i += size
    return out


def check_against_plain(records, config, roles, every, seed, recent=None):
    """Feed ``records`` in random batches to a FeatureStream and one by one to PlainStream; compare every step."""
    stream, plain = FeatureStream(config, every=every), PlainStream(config, every)
    rng = random.Random(seed)
    vectors = resets = 0
    width = None if config.feature.ordered else len(config.feature.columns)
    for batch in batches(records, rng, rng.choice((8, 64, 400))):
        result = stream.add_records(batch, roles)
        assert len(result.steps) == len(batch)
        for record, step in zip(batch, result.steps):
            if record.topic in roles:
                plain.observe(record, roles[record.topic])
                assert step is None
                continue
            want, held, reset, whole = plain.add(record)
            assert step[:2] == (reset, whole), record.stamp
            assert (step[2] is None) == (want is None), record.stamp
            resets += reset
            if want is None:
                continue
            vectors += 1
            k = step[2]
            assert_close(result.vectors[k], want, '%s at %.3f' % (config, record.stamp), width)
            assert np.array_equal(result.rows(k), np.array([r for _, r in held]))
            if recent is not None:
                assert np.array_equal(result.newest(k, recent), plain_newest(held, recent))
    assert stream.resets == resets
    return vectors, resets


def with_commands(records, odom):
    """``records`` with a decoded geometry_msgs/Twist on /cmd_vel after every 5th odometry record."""
    from geometry_msgs.msg import Twist
    out = []
    for i, record in enumerate(records):
        out.append(record)
        if record.topic == odom and i % 5 == 0:
            msg = Twist()
            msg.linear.x, msg.angular.z = 0.3 + 0.01 * (i % 7), -0.1
            out.append(Record(record.stamp, '/cmd_vel', msg))
    return out


@pytest.mark.parametrize('case, sets', [
    (HUSKY, (('motion', '2s'), ('motion', '50'), ('imu', '1s'), ('dynamics', '1.5s'), ('progress', '3s'),
             ('raw', '20'), ('command', '1s'))),
    (F1TENTH, (('motion', '1s'), ('motion', '30'), ('dynamics', '40'), ('progress', '2s'), ('raw', '10'))),
    (ICELAB, (('motion', '2s'), ('dynamics', '25'), ('progress', '60'))),
], ids=['husky', 'f1tenth-gaps-jumps', 'icelab'])
def test_every_vector_of_a_batch_is_the_window_vector_of_the_rows_held(case, sets):
    records = decoded_some(bag_records(case, seconds=120, jumps=True), seed=1)
    name, odom, imu = case
    for seed, (feature_set, window) in enumerate(sets):
        config = FeatureConfig(feature_set, window)
        first = imu if feature_set == 'imu' else odom
        mine = [r for r in records if r.topic == first]
        roles = {}
        if feature_set == 'command':
            mine, roles = with_commands(mine, odom), {'/cmd_vel': 'cmd_vel'}
        every = ('1', '3', '50ms', '0.2s')[seed % 4]
        recent = Span.parse('0.25s' if config.span.is_duration else '5', 'recent')
        vectors, resets = check_against_plain(mine, config, roles, every, seed, recent)
        assert vectors > 20, (name, config)
        assert resets >= 1, (name, config)  # the stretch moved 3 s back


def test_the_batch_boundaries_do_not_change_any_vector():
    records = bag_records(F1TENTH, seconds=200, jumps=True)
    config = FeatureConfig('motion', '1s')
    one = FeatureStream(config, every='50ms')
    alone = [one.add_record(r) for r in records]
    for largest in (2, 17, 1000):
        stream = FeatureStream(config, every='50ms')
        got = []
        for batch in batches(records, random.Random(largest), largest):
            result = stream.add_records(batch, {})
            got += [None if step[2] is None else result.vectors[step[2]] for step in result.steps]
        assert [v is None for v in got] == [v is None for v in alone]
        for a, b in zip(got, alone):
            if a is not None:
                assert np.array_equal(a, b), 'batches of up to %d' % largest  # the very same floats


def test_window_statistics_of_many_slices_is_statistics_of_each():
    rng = np.random.default_rng(3)
    array = np.concatenate((rng.normal(size=(600, 5)) * [1, 1e3, 1e-3, 0, 1] + [0, 5e3, 0, 2.5, -7],
                            np.full((40, 5), 0.1)))
    starts = rng.integers(0, 560, size=200)
    ends = np.minimum(starts + rng.integers(1, 90, size=200), len(array))
    starts[:3], ends[:3] = (600, 0, 639), (640, 1, 640)   # constant rows, one row, the last row
    got = window_statistics(array, starts, ends)
    for k, (start, end) in enumerate(zip(starts, ends)):
        assert_close(got[k], statistics(array[start:end]), 'slice %d:%d' % (start, end), 5)
        alone = window_statistics(array, [start], [end], origin=7)
        assert np.array_equal(alone[0], window_statistics(array, starts, ends, origin=7)[k])  # the same floats
    assert window_statistics(array, [], []).shape == (0, 20)
    with pytest.raises(ValueError, match='empty'):
        window_statistics(array, [5], [5])


def test_the_window_array_grows_and_moves_without_changing_the_rows_held():
    width = len(features.MOTION_COLUMNS)
    for window in ('7', '0.5s'):
        ring = FeatureWindow(FeatureConfig('motion', window), capacity=2)
        held = []
        for i, size in enumerate([1, 3, 30, 1, 1, 50, 2] * 5):
            stamps = [0.1 * (len(held) + j) for j in range(size)]
            rows = np.arange(len(held), len(held) + size, dtype=float)[:, None] * np.ones(width)
            starts, ends, full = ring.add_block(stamps, rows)
            held += list(zip(stamps, rows[:, 0]))
            assert ring.buffer[ends[-1] - 1, 0] == held[-1][1]
            kept = [r for s, r in held if window != '0.5s' or s >= held[-1][0] - 0.5]
            assert [r[0] for r in ring.rows()] == kept[-len(ring):]
            assert len(full) == size and ends[-1] - starts[-1] == len(ring)
        assert ring.full


def test_a_reset_inside_a_batch_keeps_the_windows_before_it():
    config = FeatureConfig('motion', '5')
    stream = FeatureStream(config)
    rows = np.arange(40, dtype=float)[:, None] * np.ones(len(features.MOTION_COLUMNS))
    stamps = [100.0 + 0.01 * i for i in range(20)] + [50.0 + 0.01 * i for i in range(20)]
    result = stream.add_rows(rows, stamps, [True] * 40)
    assert stream.resets == 1 and result.steps[20][0] and not result.steps[21][0]
    due = [step[2] for step in result.steps]
    assert due[:4] == [None] * 4 and due[20:24] == [None] * 4 and None not in due[24:]
    for k in range(len(result.vectors)):
        rows_k = result.rows(k)
        assert len(rows_k) == 5 and np.array_equal(result.vectors[k], window_vector(rows_k, config))
    assert result.rows(due[19])[:, 0].tolist() == [15, 16, 17, 18, 19]   # before the reset, still there
    assert result.rows(due[39])[:, 0].tolist() == [35, 36, 37, 38, 39]


@pytest.fixture(scope='module')
def f1tenth_model():
    records = bag_records(F1TENTH, seconds=60)  # the rest of the run is often anomalous to it
    config = FeatureConfig('motion', '1s')
    stream = FeatureStream(config, every='2')
    vectors = [v for v in (stream.add_record(r) for r in records) if v is not None]
    return learning.train(np.array(vectors), config=config)[0]


@pytest.mark.parametrize('retrigger', ['event', 'every', 'onset'])
def test_the_classifier_decides_on_a_batch_as_record_by_record(f1tenth_model, retrigger):
    records = decoded_some(bag_records(F1TENTH, jumps=True), seed=2)
    alone = ClassifierTrigger('c', f1tenth_model, '/odom', classify_every='1', retrigger=retrigger)
    together = ClassifierTrigger('c', f1tenth_model, '/odom', classify_every='1', retrigger=retrigger)
    want = [[f.score for f in alone.on_record(r)] for r in records]
    got = []
    for batch in batches(records, random.Random(4), 300):
        got += [[f.score for f in fires] for fires in together.on_records(batch)]
    assert [len(fires) for fires in got] == [len(fires) for fires in want]  # the same records fire
    flat = [[score for fires in run for score in fires] for run in (got, want)]
    assert flat[0] == approx_floats(flat[1])  # equal but for a BLAS kernel's rounding of a batch
    assert together.calls == alone.calls and together.anomalous == alone.anomalous > 1000
    fired = sum(map(len, want))
    assert fired < together.anomalous if retrigger != 'every' else fired == together.anomalous


def test_one_window_with_its_blocks_cached_gives_the_floats_of_any_batch():
    from cc_log.features import base
    rng = np.random.default_rng(1)
    array = rng.normal(size=(3000, 6)) * rng.uniform(0.001, 100, size=6) + rng.uniform(-50, 50, size=6)
    for origin in (0, 7, 31):
        cache, start = base.BlockCache(), 0
        for _ in range(600):  # windows moving on, sometimes jumping anywhere (a reset), lengths varying
            start = int(rng.integers(0, 2500)) if rng.random() < 0.03 else min(2500, start + int(rng.integers(0, 12)))
            end = min(3000, start + int(rng.integers(1, 600)))
            alone = base.window_statistics(array, [start], [end], origin, cache)
            batched = base.window_statistics(array, np.array([start, 0]), np.array([end, 5]), origin)[:1]
            assert alone.tobytes() == batched.tobytes()  # the very same floats
