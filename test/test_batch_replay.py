"""Offline replay in batches: ``bag_reader`` yields rosbag's records in rosbag's order, and a replay fed in
batches (``SmartLogger.on_records``, one scoring call per batch) writes the same windows as one fed record by
record (``on_raw``) from rosbag's own raw read: real and simulated bags, json-xz and bag-lz4, with and without
anomalies, with a rule trigger, and every retrigger rule."""
import collections
import os
import struct

import numpy as np
import pytest

from cc_log.base import errors, raw_message
from cc_log.learning import learning
from cc_log.storage import log_format
from cc_log import sim
from cc_log.features import FeatureConfig
from cc_log.logger.smart import SmartLogger
from cc_log.offline.replay import replay_into
from cc_log.triggers.classifier import scores_of
from cc_log.triggers.rule import RuleTrigger

from conftest import approx_floats

bagio = pytest.importorskip('cc_log.storage.bag.bagio')  # needs rosbag (a sourced ROS environment)
bag_reader = pytest.importorskip('cc_log.storage.bag.bag_reader')

HUSKY = 'husky_outdoor_2015.bag'
HUSKY_ODOM = '/husky_velocity_controller/odom'
HUSKY_IMU = '/imu/data'


@pytest.fixture(scope='module')
def sim_case(tmp_path_factory):
    """A 2-minute simulated bag (100 Hz odometry + IMU) with 2 anomalies, a nominal one, and a model."""
    tmp = tmp_path_factory.mktemp('sim')
    bags = {}
    for name, anomalies, seed in (('anomalies', 2, 1), ('nominal', 0, 3)):
        bags[name] = str(tmp / ('%s.bag' % name))
        sim.simulate_to_bag(bags[name], sim.SimConfig(seed=seed, minutes=2, anomalies=anomalies, imu=True))
    train = str(tmp / 'train.bag')
    sim.simulate_to_bag(train, sim.SimConfig(seed=2, minutes=3, anomalies=0))
    config = FeatureConfig('motion', '300')
    _, X = bagio.feature_vectors(train, sim.ODOM_TOPIC, config, stride=10)
    model, _ = learning.train(X, config=config)
    return bags, model.save(str(tmp / 'sim.model.json'))


@pytest.fixture(scope='module')
def husky_model(tmp_path_factory):
    from conftest import REAL_DATA
    config = FeatureConfig('motion', '2s')
    _, X = bagio.feature_vectors(os.path.join(REAL_DATA, HUSKY), HUSKY_ODOM, config)
    model, _ = learning.train(X[:len(X) // 2], config=config)
    return model.save(str(tmp_path_factory.mktemp('husky') / 'husky.model.json'))


def rosbag_records(path, topics):
    return list(bagio.read_raw(path, topics))


@pytest.mark.parametrize('name', [HUSKY, 'alfa_carbonZ_engine_failure.bag', 'socspioneer_trace0.bag',
                                  'f1tenth_DS2.bag'])
def test_the_chunk_reader_yields_rosbags_records_in_rosbags_order(real_bag, name):
    path = real_bag(name)
    bag = bagio.open_bag(path)
    topics = sorted(bagio.topics_of(bag))
    bag.close()
    expected = rosbag_records(path, topics)
    got = list(bag_reader.read_raw(path, topics))
    assert len(got) == len(expected) > 1000
    assert got == expected  # stamp, topic, bytes and connection header of every message, in the same order


def test_the_chunk_reader_reads_lz4_chunks_and_says_what_is_missing(sim_case, monkeypatch):
    bags, _ = sim_case
    topics = [sim.ODOM_TOPIC, sim.IMU_TOPIC]
    expected = rosbag_records(bags['anomalies'], topics)
    assert list(bag_reader.read_raw(bags['anomalies'], topics)) == expected
    monkeypatch.setattr(bag_reader, 'RECORDS_BLOCK', 997)  # many blocks of the index
    assert list(bag_reader.read_raw(bags['anomalies'], topics)) == expected
    with pytest.raises(ValueError, match=r'anomalies\.bag: topic /nothing is not in the bag; its topics: '):
        list(bag_reader.read_raw(bags['anomalies'], ['/nothing']))


def _damaged_copy(source, target, change):
    """A copy of the bag at ``source`` with ``change(bag, data)`` applied to its bytes (a bytearray)."""
    bag = bagio.open_bag(source)
    data = bytearray(open(source, 'rb').read())
    change(bag, data)
    bag.close()
    with open(target, 'wb') as stream:
        stream.write(bytes(data))
    return target


def _chunk_size_field(bag, data):
    """Where the first chunk record's ``size`` (uncompressed bytes) field value is."""
    pos = bag._chunks[0].pos
    header_len = struct.unpack_from('<I', data, pos)[0]
    at = bytes(data[pos + 4:pos + 4 + header_len]).index(b'size=')
    return pos + 4 + at + 5


@pytest.mark.parametrize('damage, message', [
    ('huge', r'declares 4294967295 bytes, more than'),
    ('wrong size', r'does not decompress to its'),
    ('index', r'index of the chunk at byte \d+ points past its end|message record at'),
])
def test_a_damaged_bag_is_one_clear_line(sim_case, tmp_path, damage, message):
    bags, _ = sim_case

    def change(bag, data):
        if damage == 'huge':
            struct.pack_into('<I', data, _chunk_size_field(bag, data), 0xffffffff)
        elif damage == 'wrong size':
            at = _chunk_size_field(bag, data)
            struct.pack_into('<I', data, at, struct.unpack_from('<I', data, at)[0] - 1)
        else:  # the first index entry of the first chunk points far past the chunk's end
            header = bag._chunk_headers[bag._chunks[0].pos]
            pos = header.data_pos + header.compressed_size
            header_len = struct.unpack_from('<I', data, pos)[0]
            struct.pack_into('<I', data, pos + 4 + header_len + 4 + 8, 0x7fffffff)
    path = _damaged_copy(bags['anomalies'], str(tmp_path / 'damaged.bag'), change)
    with pytest.raises(ValueError, match=r'damaged\.bag: bag is truncated or damaged \(.*(%s)' % message):
        list(bag_reader.read_raw(path, [sim.ODOM_TOPIC, sim.IMU_TOPIC]))


def windows_of(directory):
    """Every window file's messages (stamp, topic, message) and metadata, in file-name order."""
    found = []
    for path in log_format.window_files(directory):
        metadata, records = log_format.read_window(path)
        found.append((os.path.basename(path), metadata,
                      [(r.stamp, r.topic, raw_message.decoded(r).msg) for r in records]))
    return sorted(found, key=lambda window: window[0])


def same_windows(batched, single):
    """The windows of two runs are the same: names, messages and metadata exactly, but for the triggers' scores
    (within ``approx_floats``: a BLAS kernel may round the scores of a batch differently in the last bits)."""
    assert [name for name, _, _ in batched] == [name for name, _, _ in single]
    for (name, meta_b, records_b), (_, meta_s, records_s) in zip(batched, single):
        scores_b, scores_s = ([t.pop('score') for t in meta['triggers']] for meta in (meta_b, meta_s))
        assert meta_b == meta_s, name
        assert scores_b == approx_floats(scores_s), name
        assert records_b == records_s, name


def replay_both(tmp_path, path, topic, side, model_path, fmt, rule=None, **options):
    """The windows of a batched replay (``replay_into``: chunk reader, ``on_records``) and of one fed record by
    record (``on_raw``) from rosbag's raw read."""
    from cc_log.learning.model import AnomalyModel
    results = []
    for how in ('batched', 'one by one'):
        out = str(tmp_path / ('%s %s' % (fmt, how)))
        triggers = [RuleTrigger('fast', topic=topic, when='twist.twist.linear.x > %s' % rule)] if rule else []
        logger = SmartLogger(AnomalyModel.load(model_path), out, fmt, driving_topic=topic, side_topics=(side,),
                             background=False, triggers=triggers, **options)
        if how == 'batched':
            replay_into(logger, path)
        else:
            for record in bagio.read_raw(path, [topic, side]):
                logger.on_raw(record.topic, record.raw, record.connection, record.stamp)
            logger.close()
        results.append(windows_of(out))
    return results


@pytest.mark.parametrize('bag, fmt, rule, retrigger', [
    ('anomalies', 'json-xz', None, 'every'),
    ('anomalies', 'bag-lz4', None, 'every'),
    ('anomalies', 'json-xz', '0.5', 'every'),
    ('anomalies', 'bag-lz4', None, 'onset'),
    ('anomalies', 'json-xz', None, 'event'),
    ('nominal', 'json-xz', None, 'every'),
    ('nominal', 'bag-lz4', '0.5', 'every'),
])
def test_batched_replay_writes_the_same_windows_as_record_by_record_on_simulated_bags(sim_case, tmp_path, bag, fmt,
                                                                                      rule, retrigger):
    bags, model_path = sim_case
    batched, single = replay_both(tmp_path, bags[bag], sim.ODOM_TOPIC, sim.IMU_TOPIC, model_path, fmt, rule,
                                  retrigger=retrigger)
    if bag == 'anomalies' or rule:
        assert batched, 'no window: the comparison would prove nothing'
    same_windows(batched, single)


@pytest.mark.parametrize('fmt, rule', [('json-xz', None), ('bag-lz4', '1.0')])
def test_batched_replay_writes_the_same_windows_as_record_by_record_on_the_husky_bag(real_bag, husky_model,
                                                                                     tmp_path, fmt, rule):
    batched, single = replay_both(tmp_path, real_bag(HUSKY), HUSKY_ODOM, HUSKY_IMU, husky_model, fmt, rule)
    assert batched
    same_windows(batched, single)


def test_scoring_a_batch_gives_each_vectors_own_score_and_decision(sim_case):
    from cc_log.learning.model import AnomalyModel
    model = AnomalyModel.load(sim_case[1])
    rng = np.random.default_rng(5)
    vectors = [model.mean + model.scale * rng.normal(size=model.mean.shape) * spread
               for spread in np.linspace(0.1, 4.0, 100)]
    got, want = scores_of(model, vectors), [model.score(vector) for vector in vectors]
    assert got == approx_floats(want)  # a BLAS kernel may round a batch differently in the last bits
    decisions = [score < model.threshold for score in got]
    assert decisions == [model.is_anomalous(vector)[0] for vector in vectors] and 0 < sum(decisions) < 100


def test_a_record_that_cannot_be_decoded_stops_a_batch_after_the_records_before_it(sim_case, tmp_path):
    bags, model_path = sim_case
    records = [r for r in bagio.read_raw(bags['anomalies'], [sim.ODOM_TOPIC])][:50]
    rule = RuleTrigger('fast', topic=sim.ODOM_TOPIC, when='twist.twist.linear.x > 100')  # reads the fields
    logger = SmartLogger(None, str(tmp_path), driving_topic=sim.ODOM_TOPIC, background=False, triggers=[rule])
    broken = records[:20] + [records[20]._replace(raw=records[20].raw[:30])] + records[21:]
    with pytest.raises(errors.UndecodableRecord) as caught:
        logger.on_records(broken)
    assert caught.value.index == 20 and caught.value.topic == sim.ODOM_TOPIC
    assert logger.stats()['messages_buffered'] == 20
    logger.close()


def test_the_intake_feeds_a_drained_batch_at_once_and_drops_only_a_message_that_cannot_be_decoded(sim_case,
                                                                                                  tmp_path):
    import threading
    rospy = pytest.importorskip('rospy')
    from cc_log.nodes.intake import Intake, MessageDecoder
    bags, _ = sim_case
    records = [r for r in bagio.read_raw(bags['anomalies'], [sim.ODOM_TOPIC])][:30]
    rule = RuleTrigger('fast', topic=sim.ODOM_TOPIC, when='twist.twist.linear.x > 100')  # reads the fields
    logger = SmartLogger(None, str(tmp_path), driving_topic=sim.ODOM_TOPIC, background=False, triggers=[rule])
    calls = []
    feed = logger.on_records
    logger.on_records = lambda batch: (calls.append(len(batch)), feed(batch))
    intake = Intake.__new__(Intake)  # the feeder's part only: no subscribers, no thread
    intake.sink, intake.decoder, intake.dropped = logger, MessageDecoder(), 0
    intake._typed, intake.subscribers, intake._lock = set(), {}, threading.Lock()
    batch = [(record.topic, record.raw[:30] if k == 10 else record.raw, record.connection,
              rospy.Time.from_sec(record.stamp)) for k, record in enumerate(records)]
    initialized = rospy.rostime.is_rostime_initialized()
    rospy.rostime.set_rostime_initialized(True)  # wall-clock time for rospy's throttled warning, as a node has
    try:
        assert intake._feed_records(batch + [None]) is False  # the end mark
    finally:
        rospy.rostime.set_rostime_initialized(initialized)
    assert calls == [30, 19] and intake.dropped == 1
    assert logger.stats()['messages_buffered'] == 29
    logger.close()


def _taken_in_thread(queue, delay):
    """``queue.take_batch(delay)`` run in a thread: ``(thread, result list)``."""
    import threading
    result = []
    thread = threading.Thread(target=lambda: result.append(queue.take_batch(delay)), daemon=True)
    thread.start()
    return thread, result


def test_the_intake_queue_hands_a_batch_when_it_is_full_by_count_or_bytes_or_marked_long_before_the_delay():
    pytest.importorskip('rospy')
    from cc_log.nodes.intake import IntakeQueue
    for fill in ('count', 'bytes', 'force'):
        queue = IntakeQueue(100, 10000, batch_messages=5, batch_bytes=1000)
        thread, result = _taken_in_thread(queue, 3600.0)
        items = {'count': [(k, 1) for k in range(5)], 'bytes': [(0, 400), (1, 400), (2, 400)],
                 'force': [(0, 1), (1, 1)]}[fill]
        for k, (item, size) in enumerate(items):
            assert queue.put(item, size, force=(fill == 'force' and k == len(items) - 1))
        thread.join(60.0)  # an hour's delay: the batch is due because it is full (or marked)
        assert not thread.is_alive(), fill
        assert result == [[item for item, _ in items]] and queue.qsize() == 0 and queue.bytes == 0


def test_the_intake_queue_hands_what_arrived_once_the_delay_is_over():
    pytest.importorskip('rospy')
    from cc_log.nodes.intake import IntakeQueue
    queue = IntakeQueue(100, 10000, batch_messages=50)
    thread, result = _taken_in_thread(queue, 0.2)
    assert queue.put('a', 10) and queue.put('b', 10)
    thread.join(60.0)
    assert not thread.is_alive() and result == [['a', 'b']]
    assert queue.put('c', 10) and queue.take_batch(0.0) == ['c']  # no delay: at once


def test_intake_sync_returns_once_what_was_received_before_it_is_fed(sim_case, tmp_path):
    # the feeder thread with an hour's batch delay: only the sync mark can make it feed now
    rospy = pytest.importorskip('rospy')
    import threading
    from cc_log.nodes.intake import Intake, IntakeQueue, MessageDecoder
    bags, _ = sim_case
    records = [r for r in bagio.read_raw(bags['nominal'], [sim.ODOM_TOPIC])][:25]
    logger = SmartLogger(None, str(tmp_path), driving_topic=sim.ODOM_TOPIC, background=False)
    intake = Intake.__new__(Intake)  # the feeder's part only: no subscribers
    intake.sink, intake.decoder, intake.dropped, intake.cpu_seconds = logger, MessageDecoder(), 0, 0.0
    intake.queue, intake.batch_delay = IntakeQueue(1000, 10 ** 7), 3600.0
    intake._typed, intake.subscribers, intake._lock, intake._receiver = set(), {}, threading.Lock(), None
    intake._thread = threading.Thread(target=intake._feed, daemon=True)
    intake._thread.start()
    for record in records:
        intake.queue.put((record.topic, record.raw, record.connection, rospy.Time.from_sec(record.stamp)),
                         len(record.raw))
    assert intake.sync(timeout=60.0)
    assert logger.stats()['messages_buffered'] == 25
    intake.queue.put(None, force=True)  # the end mark: fed at once too
    intake._thread.join(60.0)
    assert not intake._thread.is_alive()
    assert intake.sync(timeout=60.0) is False  # stopped: nothing to wait for
    logger.close()


def per_record_calls(logger, bag_path):
    """The replay summary of ``bag_path`` through ``logger`` and how many records went into its window buffer one
    by one (``add``/``add_side``)."""
    calls, buffer = collections.Counter(), logger._buffer
    for name in ('add', 'add_side'):
        def counted(record, name=name, method=getattr(buffer, name)):
            calls[name] += 1
            return method(record)
        setattr(buffer, name, counted)
    return replay_into(logger, bag_path), calls


def test_a_batched_replay_buffers_its_records_by_slices_not_one_by_one(sim_case, tmp_path):
    """Between two records that fire, a batch goes into the window buffer at once (``add_batch``): the per-record
    ``add``/``add_side`` serve only for a slice of one record and the record that completes a pending window
    (counted, not timed: 2% of the records here, all of them before)."""
    from cc_log.learning.model import AnomalyModel
    bags, model_path = sim_case
    logger = SmartLogger(AnomalyModel.load(model_path), str(tmp_path), 'bag-lz4', driving_topic=sim.ODOM_TOPIC,
                         side_topics=(sim.IMU_TOPIC,), wait_for_writer=True)
    summary, calls = per_record_calls(logger, bags['anomalies'])
    assert summary['windows'], 'no window: the replay would not have opened, merged or closed one'
    assert sum(calls.values()) < summary['input_messages'] / 20, calls


def test_a_batch_longer_than_max_ahead_goes_by_slices_too(real_bag, husky_model, tmp_path):
    """A batch of Husky's spans more than ``max_ahead`` (10 s): its last IMU records lie that far after its first
    odometry record, not after the odometry record after each (which places one at its clock when it is): the
    batches still go in by slices (counted: 85% of the records one by one before, 11% now, those of the batches
    where a window ends; the windows are those of a replay record by record: the Husky test above)."""
    from cc_log.learning.model import AnomalyModel
    logger = SmartLogger(AnomalyModel.load(husky_model), str(tmp_path), 'bag-lz4', driving_topic=HUSKY_ODOM,
                         side_topics=(HUSKY_IMU,), wait_for_writer=True)
    summary, calls = per_record_calls(logger, real_bag(HUSKY))
    assert summary['messages_restamped'] == 0  # none is ahead of the clock it meets
    assert sum(calls.values()) < summary['input_messages'] / 5, calls


def test_a_replay_hands_the_logger_batches_of_2048_records_and_at_most_16_mb(tmp_path):
    """Each batch costs the triggers a fixed part (an envelope trigger's rows and neighbour search): the Husky
    bag's 15,817 messages go to the logger in 8 batches (31 of 512, 62 of 256 before); big messages are cut at
    REPLAY_BATCH_BYTES of serialized bytes (a record larger goes alone), decoded records kept apart."""
    from conftest import REAL_DATA
    from cc_log.base.records import Record
    from cc_log.offline import replay
    logger = SmartLogger(None, str(tmp_path), 'bag-lz4', driving_topic=HUSKY_ODOM, side_topics=(HUSKY_IMU,),
                         wait_for_writer=True)
    sizes, on_records = [], logger.on_records
    logger.on_records = lambda records: sizes.append(len(records)) or on_records(records)
    summary = replay_into(logger, os.path.join(REAL_DATA, HUSKY))
    assert summary['input_messages'] == sum(sizes) == 15817 and sizes == [2048] * 7 + [1481]
    image = b'\0' * (6 << 20)                   # one 6 MB payload, shared by the records
    big = [Record(float(n), '/camera', None, 0, image if n != 3 else image * 3, {}) for n in range(8)]
    small = [Record(8.0 + n, '/odom', None, 0, b'x', {}) for n in range(2)]
    decoded = [Record(10.0, '/odom', 'a message')]
    batches = list(replay._batches(big + small + decoded))
    assert [[record.stamp for record in batch] for batch in batches] == \
        [[0.0, 1.0], [2.0], [3.0], [4.0, 5.0], [6.0, 7.0, 8.0, 9.0], [10.0]]
    assert all(sum(len(record.raw or b'') for record in batch) <= replay.REPLAY_BATCH_BYTES or len(batch) == 1
               for batch in batches)
