"""WindowBuffer.add_batch: the same windows and counters as add / add_side of each record, without a call per
record in the common case (no roscore)."""
from hypothesis import given, settings
from hypothesis import strategies as st

from cc_log.base.records import Record
from cc_log.buffer.window_buffer import WindowBuffer
from cc_log.logger.options import TopicLimits

DRIVING = '/odom'


def stream(draw):
    """Records of the driving topic and two others, in arrival order, with the indices a trigger follows and the
    pre/post of each trigger (None: the buffer's)."""
    records, triggers, stamp = [], {}, 100.0
    for index in range(draw(st.integers(1, 150))):
        step = draw(st.sampled_from([0.01, 0.01, 0.02, 0.0, -0.005, 0.3, -3.0]))  # jitter, gaps, a jump back
        stamp += step
        topic = draw(st.sampled_from([DRIVING, DRIVING, '/imu', '/scan']))
        offset = 0.0 if topic == DRIVING else draw(st.sampled_from([0.0, -0.004, -0.05, 0.003, 15.0]))  # 15: far ahead
        records.append(Record(stamp + offset, topic, index, draw(st.sampled_from([100, 150, 2000]))))
        if topic == DRIVING and draw(st.integers(0, 14)) == 0:
            triggers[len(records) - 1] = draw(st.sampled_from([(None, None), ('0.1s', '0.05s'), ('3', '2')]))
    return records, triggers


def shape(windows):
    """Windows without their keys (a counter shared by every buffer), keys by order of first appearance."""
    keys = {}
    return [(keys.setdefault(w.key, len(keys)), [tuple(r) for r in w.records], w.triggers, w.part, w.final)
            for w in windows]


def counters(buffer):
    return (buffer.buffered_bytes, buffer.buffered_messages, buffer.trimmed, buffer.limited, buffer.resets,
            buffer.window_open, buffer.oldest(), dict(buffer.restamped))


def feed(buffer, records, triggers, cuts, batch):
    """Feed records one by one or (``batch``) by ``add_batch`` in slices ending at the triggered records and at
    ``cuts``; trigger after each triggered record. Returns the windows and the counters at each slice's end."""
    windows, seen = [], []
    ends = sorted(set(triggers) | set(cuts) | {len(records) - 1})
    start = 0
    for end in ends:
        if not batch:
            for record in records[start:end + 1]:
                windows += buffer.add(record) if record.topic == DRIVING else buffer.add_side(record)
        else:
            part = records[start:end + 1]
            windows += buffer.add_batch(part, [record.topic for record in part], DRIVING)
        if end in triggers:
            pre, post = triggers[end]
            windows += buffer.trigger('test', -1.0, pre=pre, post=post)
        seen.append(counters(buffer))
        start = end + 1
    return windows + buffer.flush(), seen


CONFIGS = [dict(), dict(pre='5', post='4'), dict(pre='2', post='1'), dict(pre='1', post='3', max_window='12'),
           dict(pre='0.2s', post='0.1s', max_window='0.5s'),
           dict(pre='0.1s', post='0.1s', max_window='40'), dict(pre='0.3s', post='0.2s', max_buffer_mb=0.02),
           dict(pre='0.2s', post='0.1s', max_buffer_mb=0),
           dict(pre='0.3s', post='0.2s', max_buffer_mb=0.05),
           dict(pre='0.3s', post='0.2s', max_buffer_mb=0.08, part_factor=2.0, held_elsewhere=lambda: 15000),
           dict(pre='0.2s', post='0.1s', topic_limits={'/scan': TopicLimits(pre=0.05, post=None, max_mb=0.001)})]


@settings(max_examples=400, deadline=None)
@given(config=st.sampled_from(CONFIGS), data=st.data())
def test_a_batch_leaves_what_its_records_one_by_one_leave(config, data):
    records, triggers = stream(data.draw)
    cuts = data.draw(st.lists(st.integers(0, len(records) - 1), max_size=40))
    one_by_one = feed(WindowBuffer(**config), records, triggers, cuts, False)
    batched = feed(WindowBuffer(**config), records, triggers, cuts, True)
    assert shape(batched[0]) == shape(one_by_one[0])
    assert batched[1] == one_by_one[1]


def counting(buffer):
    """Count the calls of the per-record methods of ``buffer``."""
    calls = {'add': 0, 'add_side': 0}
    for name in calls:
        method = getattr(buffer, name)

        def counted(record, name=name, method=method):
            calls[name] += 1
            return method(record)
        setattr(buffer, name, counted)
    return calls


def odometry_and_imu(start, count):
    """``count`` driving records at 100 Hz from ``start`` with an IMU record between two."""
    records = []
    for i in range(count):
        records.append(Record(start + i * 0.01 - 0.005, '/imu', ('imu', i), 300))
        records.append(Record(start + i * 0.01, DRIVING, i, 900))
    return records


def test_a_batch_outside_and_inside_a_window_makes_no_call_per_record():
    batched, single = WindowBuffer(pre='1s', post='2s'), WindowBuffer(pre='1s', post='2s')
    calls = counting(batched)
    first, second = odometry_and_imu(0.0, 500), odometry_and_imu(5.0, 150)
    topics = [record.topic for record in first]
    windows = batched.add_batch(first, topics, DRIVING)  # no window: the pre buffer, trimmed and pruned once
    assert calls == {'add': 0, 'add_side': 0}
    windows += batched.trigger('test', -1.0)
    windows += batched.add_batch(second, [record.topic for record in second], DRIVING)  # taken by the open window
    assert calls == {'add': 0, 'add_side': 0}
    windows += batched.flush()
    for record in first:
        assert single.add(record) == [] if record.topic == DRIVING else single.add_side(record) == []
    expected = single.trigger('test', -1.0)
    for record in second:
        expected += single.add(record) if record.topic == DRIVING else single.add_side(record)
    expected += single.flush()
    assert shape(windows) == shape(expected)
    assert len(windows) == 1 and len(windows[0].records) == 101 + 100 + 2 * 150  # 1 s of pre, the second batch


def test_a_pre_buffer_of_cameras_over_half_the_budget_takes_batches_without_a_call_per_record():
    # 2 s of a 0.9 MB camera at 30 Hz and 100 Hz odometry hold ~56 MB: more than the 32 MB part limit of the node's
    # 256 MB budget (bag-lz4: part factor 4), within the budget; outside a window the batch goes by slices
    config = dict(pre='2s', post='2s', max_buffer_mb=256, part_factor=4.0, held_elsewhere=lambda: 30 * 10 ** 6)
    batched, single = WindowBuffer(**config), WindowBuffer(**config)
    records = []
    for i in range(500):  # 5 s
        records.append(Record(i * 0.01, DRIVING, i, 900))
        if i % 3 == 0:
            records.append(Record(i * 0.01 - 0.004, '/camera', ('camera', i), 921600))
    calls = counting(batched)
    windows, expected = [], []
    for start in range(0, len(records), 50):
        batch = records[start:start + 50]
        windows += batched.add_batch(batch, [record.topic for record in batch], DRIVING)
        for record in batch:
            expected += single.add(record) if record.topic == DRIVING else single.add_side(record)
        assert counters(batched) == counters(single)
    assert calls == {'add': 0, 'add_side': 0}
    assert batched.buffered_bytes > batched.part_limit and windows == expected == []
    windows += batched.trigger('test', -1.0) + batched.flush()
    expected += single.trigger('test', -1.0) + single.flush()
    assert shape(windows) == shape(expected) and len(windows[0].records) == 201 + 67
