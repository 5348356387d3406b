"""SmartLogger and replay on real Husky records (no roscore): windows, events, stats, the writer thread."""
import copy
import os
import threading
import time

import numpy as np
import pytest

from cc_log.learning import learning
from cc_log.base import msg_codec
from cc_log.logger import smart
from cc_log.storage import log_format
from cc_log.logger.collector import VectorStream
from cc_log.features import FeatureConfig, vector_length
from cc_log.base.event_kinds import FAILED, OPENED, WRITTEN
from cc_log.logger.smart import SmartLogger
from cc_log.offline.replay import replay
from cc_log.triggers import ClassifierTrigger
from cc_log.base.records import Record
from cc_log.buffer.window_buffer import WindowBuffer

bagio = pytest.importorskip('cc_log.storage.bag.bagio')  # needs rosbag (a sourced ROS environment)

HUSKY = 'husky_outdoor_2015.bag'
ODOM = '/husky_velocity_controller/odom'
IMU = '/imu/data'
CONFIG = FeatureConfig('motion', '20')
PRE, POST = 10, 10


class ScriptedModel(object):
    """A stand-in model that calls exactly the driving messages whose index is in ``flags`` anomalous
    (the test sets ``index`` before feeding each message); it records every call."""

    def __init__(self, flags=(), config=CONFIG):
        self.config = config
        self.threshold = 0.0
        self.flags = set(flags)
        self.index = None
        self.calls = []

    def is_anomalous(self, vector):
        assert len(vector) == vector_length(self.config)
        self.calls.append(self.index)
        anomalous = self.index in self.flags
        return anomalous, (-1.0 if anomalous else 1.0)


@pytest.fixture(scope='module')
def husky(request):
    """The first 60 s of the Husky bag: odometry (600) and IMU records in bag order."""
    from conftest import REAL_DATA
    path = os.path.join(REAL_DATA, HUSKY)
    if not os.path.exists(path):
        pytest.fail('real data missing: %s' % path)
    records = list(bagio.read_messages(path, [ODOM, IMU]))
    start = records[0].stamp
    return [record for record in records if record.stamp < start + 60.0]


def feed(logger, records, model=None):
    """Feed records; set the scripted model's index to the driving message number."""
    index = -1
    for record in records:
        if record.topic == ODOM:
            index += 1
            if model is not None:
                model.index = index
        logger.on_message(record.topic, record.msg, record.stamp)


def reference_windows(records, flags, pre=PRE, post=POST):
    """What WindowBuffer itself makes of the same stream with the same anomalies."""
    buffer = WindowBuffer(pre=pre, post=post)
    done, index = [], -1
    for record in records:
        if record.topic != ODOM:
            buffer.add_side(record)
            continue
        index += 1
        done += buffer.add(record)
        if index in flags:
            done += buffer.trigger('classifier', -1.0)
    return done + buffer.flush()


def read_all(directory):
    files = sorted(os.path.join(directory, name) for name in os.listdir(directory) if '.tmp-' not in name)
    return [(path,) + tuple(log_format.read_window(path)) for path in files]


def same(a, b):
    return a.topic == b.topic and a.stamp == b.stamp and msg_codec.to_dict(a.msg) == msg_codec.to_dict(b.msg)


def test_windows_follow_window_buffer_and_hold_pre_and_post(husky, tmp_path):
    odom = [r for r in husky if r.topic == ODOM]
    flags = {100, 300, 305}  # 300 and 305 merge into one window
    model = ScriptedModel(flags)
    logger = SmartLogger(model, str(tmp_path), 'json-xz', PRE, POST, driving_topic=ODOM, side_topics=[IMU])
    events = []
    logger.on_event(events.append)
    feed(logger, husky, model)
    assert logger.close(30)
    # the classifier runs on every driving message once 20 rows are in
    assert model.calls == list(range(19, len(odom)))
    files = sorted(read_all(str(tmp_path)), key=lambda f: f[2][0].stamp)
    expected = reference_windows(husky, flags)
    assert len(files) == len(expected) == 2
    written = sorted((e for e in events if e.kind == WRITTEN), key=lambda e: e.start)
    for (path, metadata, records), window, event in zip(files, expected, written):
        assert len(records) == len(window.records)
        assert all(same(a, b) for a, b in zip(records, window.records))
        assert event.path == path and event.messages == len(records) and event.bytes == os.path.getsize(path)
        assert (event.start, event.end) == (records[0].stamp, records[-1].stamp)
        assert metadata['reason'] == 'classifier' and metadata['driving_topic'] == ODOM
    # first window: odometry 90..110, plus exactly the IMU messages between its first and last stamp
    first = files[0][2]
    first_odom = [r for r in first if r.topic == ODOM]
    assert [r.stamp for r in first_odom] == [r.stamp for r in odom[100 - PRE:100 + POST + 1]]
    imu_inside = [r for r in husky if r.topic == IMU and first_odom[0].stamp <= r.stamp <= first_odom[-1].stamp]
    assert imu_inside and [r.stamp for r in first if r.topic == IMU] == [r.stamp for r in imu_inside]
    second_odom = [r for r in files[1][2] if r.topic == ODOM]
    assert [r.stamp for r in second_odom] == [r.stamp for r in odom[300 - PRE:305 + POST + 1]]
    # one OPENED per window (the anomaly at 305 extends the open window), opened at the pre start
    opened = [e for e in events if e.kind == OPENED]
    assert [(e.stamp, e.start) for e in opened] == [(odom[100].stamp, odom[100 - PRE].stamp),
                                                    (odom[300].stamp, odom[300 - PRE].stamp)]
    assert all(e.reason == 'classifier' and e.score == -1.0 for e in opened)


def test_touching_windows_make_one_file_and_one_opened_event(husky, tmp_path):
    """The window of 318 (308..328) overlaps the closed but unwritten window of 300 (290..310)."""
    odom = [r for r in husky if r.topic == ODOM]
    model = ScriptedModel({300, 318})
    logger = SmartLogger(model, str(tmp_path), 'json-xz', PRE, POST, driving_topic=ODOM)
    events = []
    logger.on_event(events.append)
    feed(logger, odom, model)
    logger.close()
    assert [e.kind for e in events] == [OPENED, WRITTEN]
    files = read_all(str(tmp_path))
    assert [[r.stamp for r in f[2]] for f in files] == [[r.stamp for r in odom[290:329]]]
    assert [t['stamp'] for t in files[0][1]['triggers']] == [odom[300].stamp, odom[318].stamp]


def test_stats_count_every_message_and_byte(husky, tmp_path):
    model = ScriptedModel({200})
    logger = SmartLogger(model, str(tmp_path), 'bag-lz4', PRE, POST, driving_topic=ODOM, side_topics=[IMU])
    feed(logger, husky, model)
    logger.close()
    stats = logger.stats()
    files = read_all(str(tmp_path))
    assert stats['messages_seen'] == len(husky)
    assert stats['raw_json_bytes'] == sum(msg_codec.row_json_bytes(r.msg) for r in husky)
    assert stats['windows_saved'] == stats['windows_opened'] == len(files) == 1
    assert stats['messages_kept'] == len(files[0][2])
    assert stats['stored_bytes'] == os.path.getsize(files[0][0])
    assert stats['messages_not_kept'] == len(husky) - len(files[0][2])
    assert stats['messages_queued'] == stats['messages_lost'] == stats['write_errors'] == 0
    assert stats['classifier_calls'] == len(model.calls)
    assert 0 < stats['classifier_mean_us'] <= stats['classifier_max_us']
    assert stats['queue_depth'] == 0


def test_memory_budget_bounds_every_topic_and_writes_an_endless_window_in_parts(husky, tmp_path):
    """A window open the whole run (every message anomalous) with IMU messages too: the buffer stays within
    max_buffer_mb, the window is written in parts, and the parts hold exactly what one unbounded window
    holds."""
    odom = [r for r in husky if r.topic == ODOM]
    flags = set(range(len(odom)))
    budget = 0.3  # MB: about 150 buffered messages

    def run(directory, max_buffer_mb, check=None):
        model = ScriptedModel(flags)
        logger = SmartLogger(model, directory, 'json-xz', PRE, POST, driving_topic=ODOM, side_topics=[IMU],
                             background=False, max_buffer_mb=max_buffer_mb)
        index = -1
        for record in husky:
            if record.topic == ODOM:
                index += 1
                model.index = index
            logger.on_message(record.topic, record.msg, record.stamp)
            if check is not None:
                check(logger.stats())
        logger.close()
        return logger.stats(), read_all(directory)
    peaks = []
    stats, parts = run(str(tmp_path / 'budget'), budget, lambda s: peaks.append(s['buffered_bytes']))
    assert max(peaks) <= budget * 1e6 and stats['buffer_trimmed'] == 0 and stats['messages_lost'] == 0
    unbounded_stats, whole = run(str(tmp_path / 'whole'), 0)
    assert len(whole) == 1 and len(parts) > 10
    assert sorted(metadata['part'] for _, metadata, _ in parts) == list(range(1, len(parts) + 1))
    kept = sorted(((r.stamp, r.topic) for _, _, records in parts for r in records))
    assert kept == [(r.stamp, r.topic) for r in whole[0][2]]
    assert stats['messages_kept'] == unbounded_stats['messages_kept'] == len(kept)


@pytest.mark.parametrize('fmt', log_format.Format.ALL)
def test_an_endless_window_is_handed_on_at_half_the_budget_over_the_formats_part_factor(fmt, husky, tmp_path):
    """The buffer of an open window reaches half max_buffer_mb divided by its format's PART_FACTOR (the memory its
    part takes while written), then hands a part on."""
    from cc_log.storage import formats
    odom = [r for r in husky if r.topic == ODOM]
    model = ScriptedModel(set(range(len(odom))))
    budget = 2.0  # MB
    logger = SmartLogger(model, str(tmp_path), fmt, PRE, POST, driving_topic=ODOM, side_topics=[IMU],
                         background=False, max_buffer_mb=budget)
    limit = budget * 1e6 / 2 / formats.get(fmt).PART_FACTOR
    peak, index = 0, -1
    for record in husky:
        if record.topic == ODOM:
            index += 1
            model.index = index
        logger.on_message(record.topic, record.msg, record.stamp)
        peak = max(peak, logger.stats()['buffered_bytes'])
    logger.close()
    assert 0.9 * limit < peak <= limit + 10000  # at most one message (a decoded Odometry: ~4 kB) beyond it
    files = read_all(str(tmp_path))
    assert logger.stats()['messages_lost'] == 0
    if log_format.streams(fmt):  # the parts went into one file, the whole window
        assert len(files) == 1 and files[0][1]['part'] == 0
        assert files[0][1]['count'] == logger.stats()['messages_kept'] == len(files[0][2]) > 2000
    else:
        assert len(files) > 2


def test_writer_thread_never_blocks_the_message_path(husky, tmp_path, monkeypatch):
    release = threading.Event()
    writing = threading.Event()
    real_write = log_format.write_window
    calls = []

    def slow_write(window, directory, fmt, metadata=None, **options):
        calls.append(len(window))
        writing.set()
        release.wait(30)
        return real_write(window, directory, fmt, metadata, **options)

    monkeypatch.setattr(log_format, 'write_window', slow_write)
    model = ScriptedModel({50, 150, 250, 350})
    logger = SmartLogger(model, str(tmp_path), 'json-xz', PRE, POST, driving_topic=ODOM, side_topics=[IMU])
    started = time.time()
    feed(logger, husky, model)
    elapsed = time.time() - started
    assert writing.wait(30)  # the writer thread took the first window (it may start after feeding ended) ...
    assert not release.is_set() and len(calls) == 1  # ... and that write is still blocked ...
    assert elapsed < 25                      # ... and feeding went on regardless
    stats = logger.stats()
    assert stats['windows_saved'] == 0 and stats['queue_depth'] >= 2
    assert stats['messages_queued'] > 0
    release.set()
    assert logger.close(30)
    stats = logger.stats()
    assert stats['windows_saved'] == 4 and stats['messages_queued'] == 0 and stats['queue_depth'] == 0
    kept = [r for _, _, records in read_all(str(tmp_path)) for r in records]
    assert len(kept) == stats['messages_kept']
    expected = [r for w in reference_windows(husky, {50, 150, 250, 350}) for r in w.records]
    assert sorted((r.stamp, r.topic) for r in kept) == sorted((r.stamp, r.topic) for r in expected)


def test_disabled_logger_counts_but_keeps_nothing(husky, tmp_path):
    model = ScriptedModel({100, 400})
    logger = SmartLogger(model, str(tmp_path), 'json-xz', PRE, POST, driving_topic=ODOM, side_topics=[IMU],
                         enabled=False)
    assert logger.trigger_now() == (False, 'the logger is disabled')
    odom_seen = 0
    for record in husky:
        if record.topic == ODOM:
            model.index = odom_seen
            odom_seen += 1
            if odom_seen == 300:
                logger.set_enabled(True)
        logger.on_message(record.topic, record.msg, record.stamp)
    logger.close()
    stats = logger.stats()
    assert stats['messages_seen'] == len(husky)
    files = read_all(str(tmp_path))
    assert len(files) == 1  # 100 came while disabled
    odom_kept = [r for r in files[0][2] if r.topic == ODOM]
    odom = [r for r in husky if r.topic == ODOM]
    assert [r.stamp for r in odom_kept] == [r.stamp for r in odom[400 - PRE:400 + POST + 1]]
    # the feature window restarts when enabled: the first call is 20 messages after enabling
    assert model.calls[0] == 299 + 19


def test_disable_completes_the_open_window(husky, tmp_path):
    model = ScriptedModel({100})
    logger = SmartLogger(model, str(tmp_path), 'json-xz', PRE, POST, driving_topic=ODOM)
    odom = [r for r in husky if r.topic == ODOM]
    for index, record in enumerate(odom[:105]):
        model.index = index
        logger.on_message(ODOM, record.msg, record.stamp)
    logger.set_enabled(False)
    for record in odom[105:200]:
        logger.on_message(ODOM, record.msg, record.stamp)
    logger.close()
    files = read_all(str(tmp_path))
    assert [[r.stamp for r in f[2]] for f in files] == [[r.stamp for r in odom[90:105]]]


def test_manual_trigger_saves_pre_and_post(husky, tmp_path):
    model = ScriptedModel()
    logger = SmartLogger(model, str(tmp_path), 'json-xz', PRE, POST, driving_topic=ODOM)
    assert logger.trigger_now()[0] is False  # nothing received yet
    events = []
    logger.on_event(events.append)
    odom = [r for r in husky if r.topic == ODOM]
    for index, record in enumerate(odom[:200]):
        logger.on_message(ODOM, record.msg, record.stamp)
        if index == 50:
            ok, message = logger.trigger_now()
            assert ok, message
    logger.close()
    files = read_all(str(tmp_path))
    assert [[r.stamp for r in f[2]] for f in files] == [[r.stamp for r in odom[40:61]]]
    assert files[0][1]['reason'] == 'manual'
    assert [e.kind for e in events] == [OPENED, WRITTEN]
    assert events[0].reason == 'manual' and np.isnan(events[0].score)


def test_onset_retrigger_keeps_only_the_onsets(husky, tmp_path):
    """retrigger='onset': a run of anomalous scores triggers once, at its first message; a new run after a
    nominal score triggers again (hysteresis at the threshold); 'every' extends the window with every
    anomalous score."""
    odom = [r for r in husky if r.topic == ODOM]
    flags = set(range(100, 140)) | {150} | set(range(300, 330))  # 150: a new onset after 140..149 nominal
    windows = {}
    for rule in ('every', 'onset'):
        model = ScriptedModel(flags)
        directory = tmp_path / rule
        logger = SmartLogger(model, str(directory), 'json-xz', PRE, POST, driving_topic=ODOM, retrigger=rule)
        assert logger.retrigger == rule
        feed(logger, odom, model)
        assert logger.close(30)
        assert logger.stats()['anomalous_messages'] == len(flags)  # every anomalous score is still counted
        windows[rule] = [([r.stamp for r in f[2]], [t['stamp'] for t in f[1]['triggers']])
                         for f in sorted(read_all(str(directory)), key=lambda f: f[2][0].stamp)]
    stamps = [r.stamp for r in odom]
    assert windows['every'] == [(stamps[90:161], [stamps[i] for i in sorted(flags) if i < 200]),
                                (stamps[290:340], stamps[300:330])]
    # onset: 100 opens 90..110; 150 (after nominal 140..149) opens 140..160; they do not touch: two files
    assert windows['onset'] == [(stamps[90:111], [stamps[100]]), (stamps[140:161], [stamps[150]]),
                                (stamps[290:311], [stamps[300]])]
    with pytest.raises(ValueError, match='retrigger'):
        SmartLogger(ScriptedModel(), str(tmp_path / 'bad'), 'json-xz', PRE, POST, driving_topic=ODOM,
                    retrigger='sometimes')


def test_time_jumping_back_restarts_the_buffer(husky, tmp_path):
    """A bag played twice (rosbag play -l): the second pass starts over instead of failing."""
    model = ScriptedModel()
    logger = SmartLogger(model, str(tmp_path), 'json-xz', PRE, POST, driving_topic=ODOM)
    odom = [r for r in husky if r.topic == ODOM][:150]
    stream = odom + odom
    model.flags = {100, 250}  # the same message (100) in both passes
    for index, record in enumerate(stream):
        model.index = index
        logger.on_message(ODOM, record.msg, record.stamp)
    logger.close()
    stats = logger.stats()
    assert stats['time_resets'] == 1
    files = read_all(str(tmp_path))
    assert len(files) == 2
    for _, _, records in files:
        assert [r.stamp for r in records] == [r.stamp for r in odom[90:111]]
    # after the jump the feature window refilled: 19 messages without a classifier call
    assert 150 + 19 in model.calls and 150 + 18 not in model.calls


def stamped(record, stamp):
    """``record`` with a copy of its message whose header says ``stamp`` (its arrival, ``record.stamp``, unchanged)."""
    msg = copy.deepcopy(record.msg)
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9)) % 1000000000
    return record._replace(msg=msg)


def manual_window(tmp_path, odom, at=300):
    """``(logger, records of the one window)``: ``odom`` through a logger holding 2 s before and 1 s after, a
    manual trigger at message ``at``."""
    logger = SmartLogger(ScriptedModel(), str(tmp_path), 'json-xz', '2s', '1s', driving_topic=ODOM)
    for index, record in enumerate(odom):
        logger.on_message(ODOM, record.msg, record.stamp)
        if index == at:
            assert logger.trigger_now()[0]
    assert logger.close(30)
    (_, _, records), = read_all(str(tmp_path))
    return logger, records


@pytest.mark.parametrize('outlier', [4294000000.0, 1.0, 100.0], ids=['2106', '1970', '100s-ahead'])
def test_one_outlier_stamp_of_the_driving_topic_keeps_what_is_held_before_an_event(husky, tmp_path, outlier):
    odom = [r for r in husky if r.topic == ODOM][:400]
    _, expected = manual_window(tmp_path / 'plain', odom)
    bad = 296  # 0.4 s before the event at 300 (10 Hz)
    stamp = odom[bad].stamp + outlier if outlier == 100.0 else outlier
    logger, records = manual_window(tmp_path / 'outlier', odom[:bad] + [stamped(odom[bad], stamp)] + odom[bad + 1:])
    assert [r.stamp for r in records] == [r.stamp for r in expected]  # the same first message, none lost
    first = [r.stamp for r in odom].index(records[0].stamp)
    assert odom[300].stamp - records[0].stamp <= 2.0 < odom[300].stamp - odom[first - 1].stamp  # the whole 2 s
    stats = logger.stats()
    assert stats['restamped_by_topic'] == {ODOM: 1} and stats['time_resets'] == 0


def test_a_jump_of_the_driving_clock_that_persists_is_followed(husky, tmp_path):
    from cc_log.base.stamp_clock import FOLLOW_AFTER
    odom = [r for r in husky if r.topic == ODOM][:400]
    jumped = odom[:200] + [stamped(r, r.stamp + 100.0) for r in odom[200:]]  # the clock set 100 s ahead at 200
    _, expected = manual_window(tmp_path / 'plain', odom)
    logger, records = manual_window(tmp_path / 'jumped', jumped)
    # the pre-buffer refilled on the new clock long before the event: the same window, 100 s later
    assert [r.stamp for r in records] == pytest.approx([r.stamp + 100.0 for r in expected], abs=1e-6)
    assert logger.stats()['restamped_by_topic'] == {ODOM: FOLLOW_AFTER - 1}  # placed at the clock until followed


def test_the_triggers_see_a_jump_of_the_driving_clock_at_its_header_stamps_and_open_no_window(husky, tmp_path):
    """A bag played again while its clock runs on (the same run, its header stamps 100 s later, the robot back at
    its start): the clock places the first messages of the jump at their arrival until it follows, but the
    envelope sees them at their own stamps, a gap, so the robot's return to its start is no pose jump."""
    from cc_log.features.envelope import envelope_windows, odometry_samples
    from cc_log.learning import envelope
    from cc_log.triggers.envelope import EnvelopeTrigger
    odom = [r for r in husky if r.topic == ODOM][:400]
    samples = odometry_samples(odom)
    learned = envelope.learn([envelope_windows(*samples)[1]], ODOM, 1.0, 0.25, samples[0][-1] - samples[0][0])
    step = odom[-1].stamp - odom[-2].stamp
    again = [stamped(r, r.stamp + 100.0)._replace(stamp=odom[-1].stamp + step * (k + 1)) for k, r in enumerate(odom)]
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '2s', '1s', driving_topic=ODOM,
                         triggers=[EnvelopeTrigger('envelope', learned, ODOM)])
    feed(logger, odom + again)
    assert logger.close(30)
    stats = logger.stats()
    assert stats['restamped_by_topic'] == {ODOM: 2} and stats['windows_saved'] == 0, stats


def imu_window(tmp_path, records, at=200):
    """The records of the one window of ``records`` (odometry and IMU) through a logger holding 2 s before and 1 s
    after, a manual trigger at odometry message ``at``, and the logger's stats."""
    logger = SmartLogger(ScriptedModel(), str(tmp_path), 'json-xz', '2s', '1s', driving_topic=ODOM, side_topics=[IMU])
    index = -1
    for record in records:
        logger.on_message(record.topic, record.msg, record.stamp)
        if record.topic == ODOM:
            index += 1
            if index == at:
                assert logger.trigger_now()[0]
    assert logger.close(30)
    (_, _, kept), = read_all(str(tmp_path))
    return kept, logger.stats()


def test_a_side_topic_that_starts_before_the_driving_one_on_a_bag_played_without_its_clock_is_kept(husky, tmp_path):
    """A bag played beside a node on wall time (no --clock): header stamps of the bag's day, arrivals of today. The
    IMU's first 3 s come before the first odometry message, so before the clock knows the bag's offset: they are
    placed at their own header stamps (no clock to judge them by, and not in the future of their arrival), not at
    today's arrival, where one of them held every later IMU message of the topic back from every window."""
    start = [r.stamp for r in husky if r.topic == ODOM][0]
    records = [r for r in husky if r.topic == IMU or r.stamp >= start + 3.0]
    assert records[0].topic == IMU
    expected, _ = imu_window(tmp_path / 'bag_time', records)
    today = 1.7e9 - start  # the arrivals a year of seconds later: wall time
    kept, stats = imu_window(tmp_path / 'wall_time', [r._replace(stamp=r.stamp + today) for r in records])
    imu = [r.stamp for r in kept if r.topic == IMU]
    assert len(imu) > 50 and imu == [r.stamp for r in expected if r.topic == IMU]  # 3 s of it
    assert [r.stamp for r in kept] == [r.stamp for r in expected]
    assert stats['restamped_by_topic'] == {}


def test_a_side_stamp_the_clock_cannot_judge_is_placed_by_the_buffer_and_counted_with_the_restamped(husky, tmp_path):
    """An IMU message stamped in 2106 that comes with no arrival time (0: before the clock started) keeps its header
    stamp past the stamp clock, and used to hold every later IMU message back from every window (the window at 20 s
    had no IMU). The buffer places it at its driving clock; the count joins the clock's (``stats()``, on
    /diagnostics, and the summary of ``cclog replay``)."""
    from cc_log.offline.replay import replay_records
    expected, _ = imu_window(tmp_path / 'plain', husky)
    bad = [k for k, record in enumerate(husky) if record.topic == IMU][100]  # at about 3 s
    records = husky[:bad] + [stamped(husky[bad], 4294000000.0)._replace(stamp=0.0)] + husky[bad + 1:]
    kept, stats = imu_window(tmp_path / 'placed', records)
    assert len([r for r in kept if r.topic == IMU]) == 90 and [r.stamp for r in kept] == [r.stamp for r in expected]
    assert stats['restamped_by_topic'] == {IMU: 1} and stats['messages_restamped'] == 1
    logger = SmartLogger(ScriptedModel(), str(tmp_path / 'replay'), 'json-xz', '2s', '1s', driving_topic=ODOM,
                         side_topics=[IMU])
    summary = replay_records(logger, records)
    assert summary['restamped_by_topic'] == {IMU: 1} and summary['messages_restamped'] == 1


def test_failed_writes_are_reported_not_raised(husky, tmp_path):
    blocker = tmp_path / 'not_a_directory'
    blocker.write_text('x')
    model = ScriptedModel({100})
    logger = SmartLogger(model, str(blocker), 'json-xz', PRE, POST, driving_topic=ODOM)
    events = []
    logger.on_event(events.append)
    feed(logger, [r for r in husky if r.topic == ODOM][:200], model)
    assert logger.close(30)
    stats = logger.stats()
    assert stats['write_errors'] == 1 and stats['messages_lost'] == 21 and stats['windows_saved'] == 0
    assert [e.kind for e in events] == [OPENED, FAILED, FAILED] and events[1].error  # held, then lost at close
    assert 'still failing at close' in events[2].error and events[2].messages == 21


def test_bad_configuration_names_the_parameter(tmp_path):
    model = ScriptedModel()
    for kwargs, name in (({'fmt': 'zip'}, 'format'), ({'pre': '-1'}, 'pre'), ({'post': 'soon'}, 'post'),
                         ({'max_window': '0'}, 'max_window'), ({'driving_topic': ''}, 'driving_topic')):
        with pytest.raises(ValueError) as error:
            SmartLogger(model, str(tmp_path), **kwargs)
        assert str(error.value).startswith(name), str(error.value)


# -- replay with a trained model ---------------------------------------------------------------------------

def inject(records, at, count=6, amplitude=3.0):
    """Copies of odometry records with a jerky burst: twist flips by +-amplitude for ``count`` messages."""
    out = [Record(r.stamp, r.topic, copy.deepcopy(r.msg)) for r in records]
    for k in range(at, at + count):
        out[k].msg.twist.twist.linear.x += amplitude * (-1) ** k
        out[k].msg.twist.twist.angular.z += amplitude * (-1) ** k
    return out


def vectors(records):
    stream = VectorStream(CONFIG, 1)
    return [(i, v) for i, v in ((i, stream.add(r.msg, r.stamp)) for i, r in enumerate(records)) if v is not None]


@pytest.fixture(scope='module')
def trained(husky, tmp_path_factory):
    """A model trained on the first 40 s of odometry, with injected bursts as anomalous examples."""
    odom = [r for r in husky if r.topic == ODOM][:400]
    nominal = np.array([v for _, v in vectors(odom)])
    anomalous = np.array([v for at in (60, 160, 260) for i, v in vectors(inject(odom[at - 40:at + 40], 40))
                          if 40 <= i < 40 + 6 + 20])
    model, _ = learning.train(nominal, anomalous, CONFIG)
    path = str(tmp_path_factory.mktemp('model') / 'model.json')
    model.save(path)
    return path, model


def test_replay_finds_the_injected_anomaly(husky, trained, tmp_path):
    import rosbag
    path, model = trained
    odom = [r for r in husky if r.topic == ODOM][400:600]
    run = inject(odom, 100)
    flagged = [i for i, v in vectors(run) if model.is_anomalous(v)[0]]
    # only the burst: rows 100..107 (accelerations and jerk see it two messages longer), in 20-row windows
    assert flagged and 100 <= min(flagged) and max(flagged) <= 107 + 19
    bag = str(tmp_path / 'run.bag')
    with rosbag.Bag(bag, 'w') as out:
        for record in run:
            out.write(ODOM, record.msg, t=record.msg.header.stamp)
    summary = replay(bag, ODOM, path, str(tmp_path / 'out'), PRE, POST, 'json-xz')
    assert set(summary) == {'input_messages', 'raw_json_bytes', 'stored_bytes', 'windows', 'keep_budget',
                            'messages_restamped', 'restamped_by_topic', 'messages_trimmed_silent'}
    assert summary['input_messages'] == len(run)
    # estimated from a sample of the messages (replay does not decode them all)
    assert summary['raw_json_bytes'] == pytest.approx(sum(msg_codec.row_json_bytes(r.msg) for r in run), rel=0.01)
    window, = summary['windows']
    # the default rule ('event') fires at the onset, then while the newest quarter of the 20-row feature
    # window (5 rows) sees the burst: the window ends 5 rows after the burst's last row (107) + post, not a
    # whole feature window later as with 'every'
    trigger = ClassifierTrigger('classifier', model, ODOM, classify_every='1')
    fired = [i for i, r in enumerate(run) if trigger.on_record(r)]
    assert trigger.retrigger == 'event' and fired[0] == min(flagged) and 105 <= fired[-1] <= 107 + 5
    lo, hi = fired[0] - PRE, fired[-1] + POST
    assert hi < max(flagged) + POST
    assert (window['start'], window['end'], window['messages']) == (run[lo].stamp, run[hi].stamp, hi - lo + 1)
    assert summary['stored_bytes'] == os.path.getsize(window['path'])
    _, records = log_format.read_window(window['path'])
    assert all(same(a, b) for a, b in zip(records, run[lo:hi + 1]))
    every = replay(bag, ODOM, path, str(tmp_path / 'every'), PRE, POST, 'json-xz', retrigger='every')['windows']
    assert [(w['start'], w['end']) for w in every] == [(run[lo].stamp, run[max(flagged) + POST].stamp)]
    assert smart.DEFAULT_FORMAT == 'bag-lz4'


def test_a_window_whose_odometry_falls_silent_keeps_the_budget_and_its_imu_and_says_what_it_trimmed(husky, tmp_path):
    """A window opens at odometry message 195 (pre and post 1 s) and the odometry stops at message 200 while the IMU
    goes on for 40 s, far more than the budget: the IMU after the window's end used to pile up in memory without bound
    (the window never ended). Now the buffer stays within the budget, the window holds the IMU a logger without a
    budget writes, and the IMU let go after the window's end is counted (stats, the node's /diagnostics)."""
    odom = [r for r in husky if r.topic == ODOM]
    silent = [r for r in husky if r.topic != ODOM or r.stamp < odom[200].stamp]
    budget = 0.2  # MB: about 90 IMU messages

    def run(directory, max_buffer_mb, check=None):
        model = ScriptedModel({195})
        logger = SmartLogger(model, directory, 'json-xz', '1s', '1s', driving_topic=ODOM, side_topics=[IMU],
                             background=False, max_buffer_mb=max_buffer_mb)
        for record in silent:
            if record.topic == ODOM:
                model.index = odom.index(record)
            logger.on_message(record.topic, record.msg, record.stamp)
            if check is not None:
                check(logger.stats())
        logger.close()
        return logger.stats(), read_all(directory)
    peaks, unbounded_peaks = [], []
    stats, parts = run(str(tmp_path / 'budget'), budget, lambda s: peaks.append(s['buffered_bytes']))
    unbounded_stats, whole = run(str(tmp_path / 'whole'), 0, lambda s: unbounded_peaks.append(s['buffered_bytes']))
    assert max(unbounded_peaks) > 10 * budget * 1e6  # what the buffer held before, and without a budget
    assert max(peaks) <= budget * 1e6 and stats['messages_lost'] == 0 and stats['buffer_trimmed'] == 0
    kept = sorted((r.stamp, r.topic) for _, _, records in parts for r in records)
    assert len(whole) == 1 and kept == [(r.stamp, r.topic) for r in whole[0][2]]
    imu_after = sum(1 for r in silent if r.topic == IMU and r.stamp > odom[195].stamp + 1.0)
    assert unbounded_stats['buffer_trimmed_silent'] == 0 and 0 < stats['buffer_trimmed_silent'] < imu_after
    assert stats['buffer_trimmed_silent'] > 0.9 * imu_after  # all but the last the budget holds (let go at the close)
    from cc_log.offline.replay import replay_records  # the same in the summary of ``cclog replay``

    class Counting(ScriptedModel):  # (fed in batches: the model counts the driving messages itself)
        def is_anomalous(self, vector):
            self.index = len(self.calls) + 19  # it scores every driving message from the 20th on
            return ScriptedModel.is_anomalous(self, vector)
    logger = SmartLogger(Counting({195}), str(tmp_path / 'replay'), 'json-xz', '1s', '1s', driving_topic=ODOM,
                         side_topics=[IMU], max_buffer_mb=budget, wait_for_writer=True)
    summary = replay_records(logger, silent)
    assert len(summary['windows']) == 1 and summary['windows'][0]['messages'] == len(kept)
    assert summary['messages_trimmed_silent'] > 0.9 * imu_after
