"""Property-based fuzzing of the window buffer's side topics (no roscore): records of two side topics with any
stamps (by the driving clock, jittered, out of order, some seconds to a million seconds ahead, in 2106, huge or
infinite, far in the past; never NaN) beside a driving clock that walks (steps, gaps, standing still, jitter and
jumps back) or falling silent while the side topics go on (a silence: up to 600 side records over up to 60 s, no
driving record), triggers at random, fed record by record or in batches (``add_batch``), with or without a memory
budget or a topic's own limits. Each example must:

- bound what the buffer holds of a side topic in time: after each driving record that finds no window open, every
  record it holds lies at most ``max_ahead`` after the driving clock (a record further ahead was placed at the clock
  and counted in ``restamped``), so memory per side topic is bounded by the span of the buffer plus ``max_ahead``;
- stay within the memory budget (when there is one) after every call, whatever the driving clock does (the newest
  driving record excepted: a trigger needs it), a silence inside a window too (``budget_trim``);
- write each side record at most once, into a window whose time span covers the stamp it was placed at: its own,
  or the driving clock it was placed at (more than ``max_ahead`` before its own);
- hold nothing forever: once the clock has moved on past every stamp, the buffer holds one driving record and
  nothing of a side topic; and every record stamped beyond that clock was placed (counted) or trimmed by the
  budget (counted: ``trimmed``, ``trimmed_silent``), when time never jumped back (a jump starts the buffer over,
  dropping what it held).

Settings as ``test_fuzz_readers``: a fixed seed, ``CC_LOG_FUZZ_EXAMPLES`` (here times 20: an example takes
milliseconds), ``CC_LOG_FUZZ_SEED`` for the rounds of the longer run.
"""
import collections
import functools

from hypothesis import given
from hypothesis import strategies as st

from cc_log.base.records import Record
from cc_log.buffer.window_buffer import WindowBuffer
from cc_log.logger.options import TopicLimits
from test_fuzz_readers import EXAMPLES, fuzz

DRIVING = '/odom'
SIDE = ('/camera', '/scan')
COST = 100
FAR = (4294000000.0, 1e300, float('inf'), -1e300, float('-inf'), 0.0)  # 2106, huge, none, 1970
CONFIGS = [dict(pre='2s', post='1s'), dict(pre='0.5s', post='0.3s', max_window='3s'),
           dict(pre='1s', post='1s', max_ahead=2.0), dict(pre='1s', post='0.5s', max_buffer_mb=0.005),
           dict(pre='0.3s', post='2s', max_buffer_mb=0.02, max_ahead=0.5),
           dict(pre='1s', post='0.5s', topic_limits={'/scan': TopicLimits(pre=0.3, post=0.2, max_mb=0.001)})]
FINAL_STEP = 1e8  # past every stamp the strategy gives but those of FAR


@st.composite
def streams(draw):
    """``(start, events)``: the driving clock's start and a list of ('drive', step), ('side', topic, kind, value),
    ('silence', records, step) and ('trigger',) in the order they come."""
    start = draw(st.sampled_from([0.0, 1000.0, 1.7e9]))
    events = []
    for _ in range(draw(st.integers(1, 250))):
        what = draw(st.sampled_from(['drive', 'drive', 'side', 'side', 'side', 'trigger', 'silence']))
        if what == 'silence':
            events.append(('silence', draw(st.integers(1, 600)), draw(st.sampled_from([0.01, 0.1]))))
        elif what == 'drive':
            events.append(('drive', draw(st.sampled_from([0.01, 0.1, 0.1, 0.0, -0.005, 0.7, 4.0, 15.0, -3.0]))))
        elif what == 'side':
            kind = draw(st.sampled_from(['near', 'near', 'near', 'ahead', 'far']))
            value = (draw(st.floats(-1.5, 1.5)) if kind == 'near' else
                     draw(st.floats(0.5, 1e6)) if kind == 'ahead' else draw(st.sampled_from(FAR)))
            events.append(('side', draw(st.sampled_from(SIDE)), kind, value))
        else:
            events.append(('trigger',))
    return start, events


def records_of(start, events):
    """The records of the events (a side record's stamp by the driving clock so far: ``near`` and ``ahead`` are
    offsets from it, ``far`` a stamp) and the indices after which a trigger comes; then records that move the
    clock past everything."""
    records, triggers, clock = [], set(), start
    for event in events:
        if event[0] == 'drive':
            clock += event[1]
            records.append(Record(clock, DRIVING, len(records), COST))
        elif event[0] == 'side':
            _, topic, kind, value = event
            records.append(Record(value if kind == 'far' else clock + value, topic, len(records), COST))
        elif event[0] == 'silence':  # the side topics go on, ``step`` apart, the driving clock standing still
            _, count, step = event
            first = len(records)
            records.extend([Record(clock + step * (k + 1), SIDE[k % 2], first + k, COST) for k in range(count)])
        elif records and records[-1].topic == DRIVING:
            triggers.add(len(records) - 1)
    last = max([record.stamp for record in records if record.topic == DRIVING] + [start])
    for k in range(3):
        records.append(Record(last + FINAL_STEP * (k + 1), DRIVING, len(records), COST))
    return records, triggers


def held_side(buffer):
    """The side records the buffer holds (white box: its deques of other topics)."""
    return [record for side in buffer._side.values() for record in side]


def feed(buffer, records, triggers, cuts):
    """Feed ``records`` one by one (``cuts`` None) or by ``add_batch`` in slices ending at the triggered records and
    ``cuts``, triggering after each triggered record; check the bound in time after each driving record (or slice
    ending with one) that finds no window open. The windows, after the flush."""
    windows = []
    ends = sorted(set(triggers) | set(cuts or range(len(records))) | {len(records) - 1})
    start = 0
    for end in ends:
        part = records[start:end + 1]
        windows += buffer.add_batch(part, [record.topic for record in part], DRIVING)
        assert not buffer.max_buffer_bytes or buffer.buffered_bytes <= buffer.max_buffer_bytes + COST, 'over budget'
        if part[-1].topic == DRIVING and not buffer.window_open:
            clock = buffer._clock
            assert all(record.stamp <= clock + buffer.max_ahead for record in held_side(buffer)), clock
        if end in triggers:
            windows += buffer.trigger('fuzz')
        start = end + 1
    return windows + buffer.flush()


def spans(windows, buffer):
    """Window key -> (first, last) stamp of its time span: from its first driving record or its first trigger's
    ``pre`` before, whichever is first, to its last driving record or its last trigger's ``post`` after."""
    pre, post = buffer.pre.seconds, buffer.post.seconds
    driving, triggers = collections.defaultdict(list), collections.defaultdict(list)
    for window in windows:
        driving[window.key] += [record.stamp for record in window.records if record.topic == DRIVING]
        triggers[window.key] += [trigger.stamp for trigger in window.triggers]
    return dict((key, (min(driving[key] + [min(triggers[key]) - pre]), max(driving[key] + [max(triggers[key]) + post])))
                for key in triggers)


@functools.partial(fuzz, examples=EXAMPLES * 20)
@given(config=st.sampled_from(CONFIGS), stream=streams(), batched=st.booleans(), data=st.data())
def test_no_side_record_is_held_forever_and_each_is_written_at_most_once_where_it_was_placed(
        config, stream, batched, data):
    records, triggers = records_of(*stream)
    cuts = data.draw(st.lists(st.integers(0, len(records) - 1), max_size=30)) if batched else None
    buffer = WindowBuffer(**config)
    windows = feed(buffer, records, triggers, cuts)
    fed = dict((record.msg, record) for record in records if record.topic != DRIVING)
    written = [(window.key, record) for window in windows for record in window.records if record.topic != DRIVING]
    assert len(set(record.msg for _, record in written)) == len(written), 'a side record was written twice'
    span = spans(windows, buffer)
    for key, record in written:
        own = fed[record.msg].stamp
        assert record.stamp == own or record.stamp < own - buffer.max_ahead, (record, own)
        assert span[key][0] <= record.stamp <= span[key][1], (record, span[key])
    placed_written = sum(1 for _, record in written if record.stamp != fed[record.msg].stamp)
    assert placed_written <= sum(buffer.restamped.values())
    # the clock has moved on past everything: nothing of a side topic is held, only the newest driving record
    assert not buffer.window_open and not held_side(buffer) and buffer.buffered_messages == 1
    if not buffer.resets:
        beyond = sum(1 for record in fed.values() if record.stamp > records[-1].stamp + buffer.max_ahead)
        assert beyond <= sum(buffer.restamped.values()) + buffer.trimmed + buffer.trimmed_silent
