"""WindowBuffer and Span: logging windows around anomalies, sizes (no roscore)."""
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cc_log.base.spans import Span
from cc_log.base.records import LogWindow, Record
from cc_log.buffer.window_buffer import MemoryCost, WindowBuffer, deep_size
from cc_log.logger.options import TopicLimits


def run(buffer, stamps, anomalies, side=()):
    """Feed driving messages 0..n-1 (msg = index) with the given stamps; trigger at the anomaly indices.

    side: (stamp, name) records of another topic, added in stamp order among the driving messages.
    Returns the completed windows, in order, after the end-of-stream flush.
    """
    side = sorted(side)
    windows = []
    for index, stamp in enumerate(stamps):
        while side and side[0][0] <= stamp:
            side_stamp, name = side.pop(0)
            windows += buffer.add_side(Record(side_stamp, '/side', name))
        windows += buffer.add(Record(stamp, '/odom', index))
        if index in anomalies:
            windows += buffer.trigger('test', -1.0)
    return windows + buffer.flush()


def indices(window):
    return [record.msg for record in window.records if record.topic == '/odom']


def expected_by_count(n, anomalies, pre, post):
    """Reference: the union of [i-pre, i+post] over the anomalies, split into maximal runs, runs at most post
    messages apart joined (with the messages between)."""
    kept = sorted({j for i in anomalies for j in range(max(0, i - pre), min(n - 1, i + post) + 1)})
    runs = []
    for j in kept:
        if runs and j - runs[-1][-1] - 1 <= post:
            runs[-1].extend(range(runs[-1][-1] + 1, j + 1))
        else:
            runs.append([j])
    return runs


def test_single_anomaly_keeps_pre_and_post():
    windows = run(WindowBuffer(pre=3, post=2), [float(i) for i in range(20)], {10})
    assert [indices(w) for w in windows] == [[7, 8, 9, 10, 11, 12]]
    assert windows[0].triggers[0].stamp == 10.0 and windows[0].triggers[0].reason == 'test'


def test_anomaly_inside_open_window_extends_it():
    windows = run(WindowBuffer(pre=2, post=3), [float(i) for i in range(30)], {10, 12})
    assert [indices(w) for w in windows] == [list(range(8, 16))]
    assert len(windows[0].triggers) == 2


def test_touching_windows_become_one():
    # first window 8..12, second starts at 13 = 12 + 1: they touch
    windows = run(WindowBuffer(pre=2, post=2), [float(i) for i in range(30)], {10, 15})
    assert [indices(w) for w in windows] == [list(range(8, 18))]


def test_windows_closer_than_post_become_one_and_farther_ones_stay_apart():
    # first window 8..12; a second from 14 leaves a gap of one message (13), less than post: one window
    windows = run(WindowBuffer(pre=2, post=2), [float(i) for i in range(30)], {10, 16})
    assert [indices(w) for w in windows] == [list(range(8, 19))]
    # a second from 18 leaves 13..17, more than post: two windows
    windows = run(WindowBuffer(pre=2, post=2), [float(i) for i in range(30)], {10, 20})
    assert [indices(w) for w in windows] == [list(range(8, 13)), list(range(18, 23))]


def test_windows_33_ms_apart_become_one_window():
    stamps = [i * 0.01 for i in range(1200)]  # 100 Hz; pre and post 2 s
    # the first ends at 4.0 s (trigger at 2 s); the second begins 33 ms later (trigger at 6.033 s, pre 2 s)
    windows = run(WindowBuffer(pre='2s', post='2s'), stamps, {200, 603})
    assert len(windows) == 1 and [r.stamp for r in windows[0].records] == stamps[0:804]
    windows = run(WindowBuffer(pre='2s', post='2s'), stamps, {200, 700})  # 1 s apart at 100 Hz: still one
    assert len(windows) == 1
    windows = run(WindowBuffer(pre='2s', post='2s'), stamps, {200, 900})  # 3 s apart, more than post: two
    assert [len(w) for w in windows] == [401, 401]


def test_a_trigger_with_a_shorter_pre_joins_the_pending_window_only_when_its_pre_reaches_within_post():
    """A trigger's own pre (a periodic trigger's 2 s in a 5 s / 5 s buffer) decides the gap: the pending window
    waits the buffer's pre + post, but a window whose pre starts more than post after it stays apart."""
    stamps = [i * 0.1 for i in range(300)]  # 10 Hz

    def windows(second, pre):
        buffer, done = WindowBuffer(pre='5s', post='5s'), []
        for index, stamp in enumerate(stamps):
            done += buffer.add(Record(stamp, '/odom', index))
            if index in (100, second):
                joins = buffer.joins(pre)
                done += buffer.trigger('every10s', pre=pre, post='2s' if pre else None)
                if index == second:
                    assert joins == (len(done) == 0)  # a pending window not joined is completed by the trigger
        return [(w.records[0].stamp, w.records[-1].stamp) for w in done + buffer.flush()]
    first = (pytest.approx(8.0), pytest.approx(12.0))
    # the first window 8..12 s; the second's pre (2 s) starts at 18 s: 6 s after it, more than post (5 s)
    assert windows(200, '2s') == [first, (pytest.approx(18.0), pytest.approx(22.0))]
    # the second at 18 s starts at 16 s: 4 s after the first, within post: one window with the messages between
    assert windows(180, '2s') == [(pytest.approx(8.0), pytest.approx(20.0))]
    # the buffer's own pre (5 s) from 20 s reaches 15 s, within post: one window
    assert windows(200, None) == [(pytest.approx(5.0), pytest.approx(25.0))]


def test_anomaly_in_first_and_last_message():
    windows = run(WindowBuffer(pre=3, post=3), [float(i) for i in range(12)], {0, 11})
    assert [indices(w) for w in windows] == [[0, 1, 2, 3], [8, 9, 10, 11]]


def test_back_to_back_anomalies():
    windows = run(WindowBuffer(pre=1, post=1), [float(i) for i in range(10)], {3, 4, 5, 6})
    assert [indices(w) for w in windows] == [list(range(2, 8))]


def test_zero_pre_and_post_keep_the_anomalous_message_only():
    windows = run(WindowBuffer(pre=0, post=0), [float(i) for i in range(10)], {2, 3, 7})
    assert [indices(w) for w in windows] == [[2, 3], [7]]


def test_end_of_stream_flushes_open_window():
    buffer = WindowBuffer(pre=2, post=100)
    windows = run(buffer, [float(i) for i in range(10)], {5})
    assert [indices(w) for w in windows] == [list(range(3, 10))]
    assert not buffer.window_open


def test_window_is_completed_once_pre_and_post_more_messages_show_none_within_post():
    buffer = WindowBuffer(pre=2, post=1)
    completed = []
    for i in range(8):
        completed.append(buffer.add(Record(float(i), '/odom', i)))
        if i == 1:
            buffer.trigger('test')
    # window 0..2; an anomaly at 3 .. 6 would still join it (6 - pre = 4: one message between, within post);
    # 7 pushes 3 out of pre + post, so the window is complete
    assert [len(c) for c in completed] == [0, 0, 0, 0, 0, 0, 0, 1]


def test_durations_with_irregular_stamps():
    stamps = [0.0, 0.1, 0.15, 0.5, 1.0, 1.05, 1.4, 2.2, 2.3, 3.9, 4.0, 6.0]
    windows = run(WindowBuffer(pre='0.5s', post='1s'), stamps, {6})  # anomaly at 1.4 s
    assert [indices(w) for w in windows] == [[4, 5, 6, 7, 8]]  # 0.9 <= t <= 2.4


def test_a_later_trigger_with_a_longer_pre_reaches_back_before_the_window_start():
    """A classifier opens a window with its short pre; a goal abort inside it asks for 5 s before itself: the
    window reaches back into what the buffer held when it opened (its own pre: 6 s), side topics too; a count
    pre the same; once a part of the window is written, nothing more."""
    side = [(1.5, 'old'), (3.5, 'early'), (8.5, 'near'), (11.0, 'inside')]
    for pre, post, abort_pre, first in (('6s', '2s', '5s', 7), (6, 2, 5, 7)):
        buffer = WindowBuffer(pre=pre, post=post)
        held = list(side)
        out = []
        for index in range(30):
            stamp = float(index)
            while held and held[0][0] <= stamp:
                out += buffer.add_side(Record(held[0][0], '/side', held.pop(0)[1]))
            out += buffer.add(Record(stamp, '/odom', index))
            if index == 10:
                out += buffer.trigger('classifier', -1.0, 'classifier', pre=Span.parse('1s' if post == '2s' else 1))
            if index == 12:
                out += buffer.trigger('abort', float('nan'), 'abort', pre=Span.parse(abort_pre))
        out += buffer.flush()
        assert [indices(w) for w in out] == [list(range(first, 15))]
        assert [r.msg for r in out[0].records if r.topic == '/side'] == ['near', 'inside']
        assert buffer.buffered_messages == 7   # the pre buffer after the window: nothing of its start held on
    # nothing held before the start: no reach back; a part written: none either
    buffer = WindowBuffer(pre='6s', post='2s', max_window=4)
    out = []
    for index in range(30):
        out += buffer.add(Record(float(index), '/odom', index))
        if index == 10:
            out += buffer.trigger('classifier', -1.0, pre=Span.parse('1s'))
        if index == 13:
            out += buffer.trigger('abort', -1.0, pre=Span.parse('5s'))
    out += buffer.flush()
    assert sorted(i for w in out for i in indices(w)) == list(range(9, 16))


def test_side_topics_are_saved_in_the_window_time_span():
    side = [(0.5, 'a'), (8.5, 'b'), (9.9, 'c'), (12.5, 'd'), (18.0, 'e')]
    windows = run(WindowBuffer(pre=2, post=2), [float(i) for i in range(20)], {10}, side)
    assert len(windows) == 1
    records = windows[0].records
    assert [r.msg for r in records if r.topic == '/side'] == ['b', 'c']
    assert [r.stamp for r in records] == sorted(r.stamp for r in records)
    assert windows[0].topics == ['/odom', '/side']


def test_a_duration_window_keeps_side_records_up_to_its_edges_not_only_between_driving_records():
    # Driving records every 0.1 s, the trigger at 1.0 s, pre 0.45 s, post 0.45 s: the window's span is
    # [0.55, 1.45]; its first and last driving records are 0.6 and 1.4, side records at 0.57 and 1.43 belong to it.
    side = [(0.52, 'before'), (0.57, 'first'), (1.03, 'middle'), (1.43, 'last'), (1.48, 'after')]
    windows = run(WindowBuffer(pre='0.45s', post='0.45s'), [round(0.1 * i, 1) for i in range(30)], {10}, side)
    assert len(windows) == 1
    assert indices(windows[0]) == [6, 7, 8, 9, 10, 11, 12, 13, 14]
    assert [r.msg for r in windows[0].records if r.topic == '/side'] == ['first', 'middle', 'last']


def test_a_part_written_for_the_budget_takes_no_side_record_beyond_the_window():
    # A window in parts (a small budget) ends at 1.45 s; a side record stamped 1.47 s that came before the driving
    # record of 1.5 s is not the window's, whichever part goes out while it is held.
    buffer = WindowBuffer(pre='0.45s', post='0.45s', max_buffer_mb=300 / 1e6)  # a part at every message
    windows = []
    for i in range(30):
        stamp = round(0.1 * i, 1)
        if stamp == 1.5:
            windows += buffer.add_side(Record(1.47, '/side', 'after', 100))
        windows += buffer.add_side(Record(stamp + 0.01, '/side', stamp, 100))
        windows += buffer.add(Record(stamp, '/odom', i, 100))
        if i == 10:
            windows += buffer.trigger('test')
    windows += buffer.flush()
    side = [r.msg for w in windows for r in w.records if r.topic == '/side']
    assert 'after' not in side and side[-1] == 1.4 and len(windows) > 2  # (the budget trimmed the pre-buffer)


def side_stream(buffer, side, n=1000, trigger_at=500, step=0.1):
    """Driving records 0..n-1 (``/odom``, every ``step`` s, cost 100), each after the side records ``side(i,
    stamp)`` gives; a trigger after record ``trigger_at``. The windows after the flush, and the most records the
    buffer held after a driving record before the trigger."""
    windows, most = [], 0
    for i in range(n):
        stamp = round(step * i, 6)
        for record in side(i, stamp):
            windows += buffer.add_side(record)
        windows += buffer.add(Record(stamp, '/odom', i, 100))
        if i == trigger_at:
            windows += buffer.trigger('test')
        if i < trigger_at:
            most = max(most, buffer.buffered_messages)
    return windows + buffer.flush(), most


def camera(outlier_at, outlier):
    """A camera every 0.1 s beside the driving records, stamped as they are, but the one at ``outlier_at``."""
    return lambda i, stamp: [Record(outlier if i == outlier_at else stamp + 0.05, '/cam', i, 100)]


OUTLIERS = {'2106': 4294000000.0, 'huge': 1e300, 'inf': float('inf'), '11s-ahead': 10.0 + 11.0}


@pytest.mark.parametrize('outlier', list(OUTLIERS.values()), ids=list(OUTLIERS))
@pytest.mark.parametrize('limits', [None, {'/cam': TopicLimits(pre=0.5, post=None, max_mb=0)}], ids=['', 'limits'])
def test_a_side_record_far_ahead_of_the_driving_clock_holds_no_later_record_of_its_topic_back(outlier, limits):
    """One camera message stamped far in the future (its header wrong: 2106), at 10 s: it used to sit at the front of
    its topic's records and hold every later one (neither written nor let go: the window at 50 s had no camera,
    900 records stayed held) or, with the topic's own pre, make it drop what it held. Now it is placed at the
    driving clock when the clock moves on, counted, and let go with the records of its time."""
    reference = WindowBuffer(pre='2s', post='2s', max_buffer_mb=0, topic_limits=limits)
    expected, _ = side_stream(reference, camera(None, None))
    buffer = WindowBuffer(pre='2s', post='2s', max_buffer_mb=0, topic_limits=limits)
    windows, most = side_stream(buffer, camera(100, outlier))
    assert [[tuple(r) for r in w.records] for w in windows] == [[tuple(r) for r in w.records] for w in expected]
    assert [r.msg for r in windows[0].records if r.topic == '/cam'][0] == (495 if limits else 480)
    assert buffer.restamped == {'/cam': 1} and buffer.limited == reference.limited
    assert most <= 2 * 21 + 1  # the pre-buffer's 2 s of both topics (and the outlier) at most


@pytest.mark.parametrize('limits', [None, {'/cam': TopicLimits(pre=0.5, post=None, max_mb=0)}], ids=['', 'limits'])
def test_a_side_record_placed_at_the_driving_clock_goes_into_the_window_at_that_clock(limits):
    """A camera message stamped in 2106 just before the trigger: placed at the driving record after it, it is in the
    window at that stamp, and the camera's own ``pre`` keeps what it kept without it."""
    expected, _ = side_stream(WindowBuffer(pre='2s', post='2s', max_buffer_mb=0, topic_limits=limits),
                              camera(None, None))
    buffer = WindowBuffer(pre='2s', post='2s', max_buffer_mb=0, topic_limits=limits)
    windows, _ = side_stream(buffer, camera(499, 4294000000.0))
    cam = [(r.msg, r.stamp) for r in windows[0].records if r.topic == '/cam']
    assert cam == [(r.msg, 49.9 if r.msg == 499 else r.stamp) for r in expected[0].records if r.topic == '/cam']
    assert len(cam) == (25 if limits else 40) and buffer.restamped == {'/cam': 1}  # from 49.55 or 48.05 to 51.95


def test_side_records_during_a_silence_of_the_driving_topic_keep_their_stamps():
    """The clock judges a side record when it moves on, not when the record comes: a camera running on through 30 s
    without odometry is not ahead of the clock that comes back, and a window just after keeps its own stamps."""
    buffer, windows = WindowBuffer(pre='2s', post='2s', max_buffer_mb=0), []
    for i in range(600):
        stamp = round(0.1 * i, 6)
        windows += buffer.add_side(Record(stamp + 0.05, '/cam', i, 100))
        if not 200 <= i < 500:  # no odometry from 20 s to 50 s
            windows += buffer.add(Record(stamp, '/odom', i, 100))
        if i == 510:
            windows += buffer.trigger('test')
    windows += buffer.flush()
    assert [r.msg for r in windows[0].records if r.topic == '/cam'] == list(range(490, 530))  # 49.05 .. 52.95
    assert all(r.stamp == round(0.1 * r.msg, 6) + 0.05 for r in windows[0].records if r.topic == '/cam')
    assert buffer.restamped == {}


def test_a_side_record_that_comes_after_a_later_stamped_one_is_kept_in_the_window_its_stamp_falls_in():
    """Side records out of stamp order (two publishers, a sensor's variable delay): a record stamped inside a window
    that came after one stamped beyond its end used to wait behind it and miss the window."""
    def side(i, stamp):
        return [Record(51.5, '/cam', 'beyond', 100), Record(50.9, '/cam', 'inside', 100)] if i == 51 else []
    buffer = WindowBuffer(pre='1s', post='1s', max_buffer_mb=0)
    windows, _ = side_stream(buffer, side, n=100, trigger_at=50, step=1.0)
    assert [[r.msg for r in w.records if r.topic == '/cam'] for w in windows] == [['inside']]
    assert [r.stamp for r in windows[0].records] == sorted(r.stamp for r in windows[0].records)
    assert buffer.restamped == {}


@pytest.mark.parametrize('late', [1.0, 0.0, -1e300], ids=['46s-late', '1970', 'huge'])
def test_a_window_written_in_parts_takes_no_late_side_record_stamped_before_its_start(late):
    """A window from 48 s to 52 s in parts (max_window 3 s: the first ends at 51 s): a side record stamped before
    its start that comes while its last part is collected is not the window's; it used to be written into that part
    (a window file from 1970 to 52 s)."""
    def side(i, stamp):
        return [Record(late, '/cam', 'late', 100)] if i == 515 else [Record(stamp + 0.05, '/cam', i, 100)]
    windows, _ = side_stream(WindowBuffer(pre='2s', post='2s', max_window='3s', max_buffer_mb=0), side)
    cam = [r for w in windows for r in w.records if r.topic == '/cam']
    assert [w.part for w in windows] == [1, 2] and [r.msg for r in cam] == [i for i in range(480, 520) if i != 515]


def test_long_anomaly_is_split_at_max_window_without_loss():
    windows = run(WindowBuffer(pre=2, post=2, max_window=5), [float(i) for i in range(30)], set(range(5, 20)))
    assert [w.part for w in windows] == [1, 2, 3, 4]
    assert sum((indices(w) for w in windows), []) == list(range(3, 22))


def test_time_jumping_backwards_flushes_and_starts_over():
    buffer = WindowBuffer(pre=2, post=5)
    stamps = [100.0 + i for i in range(10)] + [float(i) for i in range(10)]
    windows = run(buffer, stamps, {8, 15})
    assert [indices(w) for w in windows] == [[6, 7, 8, 9], [13, 14, 15, 16, 17, 18, 19]]
    assert buffer.resets == 1


def test_trigger_before_any_message_is_an_error():
    with pytest.raises(ValueError, match='trigger'):
        WindowBuffer().trigger('test')


@pytest.mark.parametrize('kwargs, message', [
    ({'pre': -1}, 'pre'),
    ({'post': '-2s'}, 'post'),
    ({'pre': 200, 'max_window': 100}, 'pre'),
])
def test_bad_configuration_names_the_parameter(kwargs, message):
    with pytest.raises(ValueError) as error:
        WindowBuffer(**kwargs)
    assert str(error.value).startswith(message + ':')
    assert '\n' not in str(error.value)


@pytest.mark.parametrize('text, span', [
    ('500', Span(500, None)), (500, Span(500, None)), ('5s', Span(None, 5.0)),
    ('2.5s', Span(None, 2.5)), ('250ms', Span(None, 0.25)), (' 7 ', Span(7, None)),
])
def test_span_parse(text, span):
    assert Span.parse(text) == span
    assert Span.parse(str(span)) == span


@pytest.mark.parametrize('text', ['', 's', '1.5', '-1', '-1s', 'nan', 'infs', 'five'])
def test_span_parse_rejects(text):
    with pytest.raises(ValueError, match='^pre: '):
        Span.parse(text, 'pre')


def test_window_buffer_does_not_import_rospy():
    import subprocess
    code = 'import sys, cc_log.buffer.window_buffer, cc_log.base.spans; sys.exit("rospy" in sys.modules)'
    assert subprocess.call([sys.executable, '-c', code], env=None) == 0


def test_log_window_properties():
    window = LogWindow([Record(1.0, '/a', 1), Record(2.0, '/b', 2)], [])
    assert (window.start, window.end, len(window), window.topics) == (1.0, 2.0, 2, ['/a', '/b'])


# -- properties over random streams ----------------------------------------------------------------------

@settings(max_examples=300, deadline=None)
@given(n=st.integers(1, 120), pre=st.integers(0, 12), post=st.integers(0, 12),
       max_window=st.integers(30, 60), data=st.data())
def test_windows_by_count_are_the_union_of_anomaly_neighbourhoods(n, pre, post, max_window, data):
    anomalies = set(data.draw(st.lists(st.integers(0, n - 1), max_size=10)))
    windows = run(WindowBuffer(pre=pre, post=post, max_window=max_window), [float(i) for i in range(n)],
                  anomalies)
    # Split parts of one window are consecutive; joined, they must be exactly the reference runs.
    joined = []
    for window in windows:
        if window.part > 1:
            joined[-1] += indices(window)
        else:
            joined.append(indices(window))
    assert joined == expected_by_count(n, anomalies, pre, post)
    assert all(len(window) <= max_window for window in windows)


@settings(max_examples=300, deadline=None)
@given(gaps=st.lists(st.floats(0.0, 0.5), min_size=1, max_size=100), pre=st.floats(0.0, 1.0),
       post=st.floats(0.0, 1.0), data=st.data())
def test_windows_by_duration_never_duplicate_or_skip(gaps, pre, post, data):
    stamps = []
    for gap in gaps:
        stamps.append((stamps[-1] if stamps else 0.0) + gap)
    anomalies = set(data.draw(st.lists(st.integers(0, len(stamps) - 1), max_size=8)))
    windows = run(WindowBuffer(pre='%rs' % pre, post='%rs' % post), stamps, anomalies)
    kept = sum((indices(w) for w in windows), [])
    assert kept == sorted(set(kept)), 'a message was written twice or out of order'
    for window in windows:
        assert indices(window) == list(range(indices(window)[0], indices(window)[-1] + 1)), 'gap in window'
    for a, b in zip(windows, windows[1:]):
        assert indices(b)[0] > indices(a)[-1] + 1, 'touching windows were not merged'
    for i in anomalies:
        # every message within pre before / post after an anomaly is kept
        near = {j for j, t in enumerate(stamps) if stamps[i] - pre <= t <= stamps[i] + post}
        assert near <= set(kept)


# -- memory budget (max_buffer_mb) -------------------------------------------------------------------------

COST = 100  # bytes per record in these tests
MB = 1000 ** 2


def run_costed(buffer, n, anomalies, side_every=1, check=None):
    """Driving records 0..n-1 (stamp i, cost COST), ``side_every`` side records between two driving ones;
    trigger at the anomalies; ``check(buffer)`` after every call. Returns the windows after the flush."""
    windows = []
    for i in range(n):
        for k in range(side_every):
            windows += buffer.add_side(Record(i - 1 + (k + 1) / (side_every + 1.0), '/side', (i, k), COST))
            check and check(buffer)
        windows += buffer.add(Record(float(i), '/odom', i, COST))
        check and check(buffer)
        if i in anomalies:
            windows += buffer.trigger('test', -1.0)
            check and check(buffer)
    return windows + buffer.flush()


def within(budget):
    def check(buffer):
        assert buffer.buffered_bytes <= budget
        assert buffer.buffered_bytes == COST * buffer.buffered_messages
    return check


def test_a_window_open_all_the_time_is_written_in_parts_within_the_budget():
    budget = 5000  # 50 records
    buffer = WindowBuffer(pre=10, post=10, max_buffer_mb=budget / MB)
    windows = run_costed(buffer, 1000, set(range(0, 1000)), side_every=1, check=within(budget))
    records = [r for w in windows for r in w.records]
    assert [r.msg for r in records if r.topic == '/odom'] == list(range(1000))  # every one, once, in order
    assert sorted(r.msg for r in records if r.topic == '/side') == [(i, 0) for i in range(1, 1000)]  # from 0.0 on
    assert [r.stamp for r in records] == sorted(r.stamp for r in records)
    assert [w.part for w in windows] == list(range(1, len(windows) + 1)) and len(windows) >= 35
    assert all(len(w) <= budget // COST + 1 for w in windows)
    assert buffer.trimmed == 0  # nothing inside a window is ever dropped


def test_side_records_between_two_parts_of_a_split_window_are_kept():
    """A side message after one part's last driving message and before the next part's first one."""
    windows = run_costed(WindowBuffer(pre=2, post=2, max_window=10, max_buffer_mb=0), 100,
                         set(range(100)), side_every=1)
    assert [w.final for w in windows] == [False] * 10 + [True] and not windows[-1].records  # it ended after part 10
    assert len(set(w.key for w in windows)) == 1
    windows = windows[:-1]
    assert len(windows) == 10 and [w.part for w in windows] == list(range(1, 11))
    assert sorted(r.msg for w in windows for r in w.records if r.topic == '/side') == [(i, 0) for i in range(1, 100)]


def test_outside_windows_the_budget_trims_the_oldest_and_counts_them():
    budget = 2000
    buffer = WindowBuffer(pre=100, post=5, max_buffer_mb=budget / MB)
    windows = run_costed(buffer, 500, {400}, side_every=2, check=within(budget))
    assert buffer.trimmed > 0
    assert [w.part for w in windows] == list(range(1, len(windows) + 1))  # one window, in parts at the budget
    odom = [r.msg for w in windows for r in w.records if r.topic == '/odom']
    assert odom[-6:] == list(range(400, 406)) and odom == list(range(odom[0], 406))
    assert sum(len(w) for w in windows) <= budget // COST + 1 + 5 * 3
    without = run_costed(WindowBuffer(pre=100, post=5, max_buffer_mb=0), 500, {400}, side_every=2)
    assert len(without[0]) == 101 * 3 + 5 * 3 - 2  # no budget: the whole pre part


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 150), pre=st.integers(0, 30), post=st.integers(0, 30), budget=st.integers(3, 40),
       side_every=st.integers(0, 3), data=st.data())
def test_the_budget_never_drops_a_window_message_nor_writes_one_twice(n, pre, post, budget, side_every, data):
    anomalies = set(data.draw(st.lists(st.integers(0, n - 1), max_size=10)))
    buffer = WindowBuffer(pre=pre, post=post, max_window=1000, max_buffer_mb=budget * COST / MB)
    windows = run_costed(buffer, n, anomalies, side_every, check=within(budget * COST))
    odom = [r.msg for w in windows for r in w.records if r.topic == '/odom']
    side = [r.msg for w in windows for r in w.records if r.topic == '/side']
    assert odom == sorted(set(odom)) and len(side) == len(set(side))
    for i in anomalies:  # the anomaly and its post part are never dropped
        assert set(range(i, min(n, i + post + 1))) <= set(odom)
    reference = [r.msg for w in run_costed(WindowBuffer(pre=pre, post=post, max_window=1000,
                                                        max_buffer_mb=0), n, anomalies, side_every)
                 for r in w.records if r.topic == '/odom']
    assert set(odom) <= set(reference)  # nothing outside the windows is added either


def test_memory_cost_is_measured_once_per_type_and_scales_with_the_serialized_length():
    import io
    nav_msgs = pytest.importorskip('nav_msgs.msg')
    buff = io.BytesIO()
    nav_msgs.Odometry().serialize(buff)
    msg = nav_msgs.Odometry().deserialize(buff.getvalue())  # as received: every float its own object
    cost = MemoryCost()
    first = cost(msg, 700)
    assert 3000 < deep_size(msg) < first < 6000  # a decoded Odometry: ~3.5 kB of Python objects
    assert cost(nav_msgs.Odometry(), 700) == first and cost(nav_msgs.Odometry(), 1400) == 2 * first
    assert cost(nav_msgs.Odometry()) == first  # no length known: the type's estimate
    buffer = WindowBuffer(pre=2, post=2)
    buffer.add(Record(1.0, '/odom', msg))  # no cost given: the buffer estimates it
    assert buffer.buffered_bytes == MemoryCost()(msg) > 0


@pytest.mark.parametrize('value', ['-1', 'lots', float('nan'), float('inf'), [1]])
def test_bad_budget_names_the_parameter(value):
    with pytest.raises(ValueError) as error:
        WindowBuffer(max_buffer_mb=value)
    assert str(error.value).startswith('max_buffer_mb:')


# -- the driving topic falls silent while a window is open -------------------------------------------------

def silent_stream(buffer, cost, seconds=40.0, back=None):
    """Odometry every 0.1 s (cost 100) and a camera every 0.1 s (``cost``, stamped 0.05 s after), a trigger at 5 s;
    the odometry silent from 5.5 s on (back at ``back`` s, if given). Checks the budget after every call; returns the
    windows after the flush and the most bytes held."""
    windows, most = [], 0
    for i in range(int(seconds * 10)):
        stamp = round(0.1 * i, 6)
        windows += buffer.add_side(Record(round(stamp + 0.05, 6), '/cam', i, cost))
        most = max(most, buffer.buffered_bytes)
        if stamp <= 5.5 or (back is not None and stamp >= back):
            windows += buffer.add(Record(stamp, '/odom', i, 100))
            most = max(most, buffer.buffered_bytes)
        if i == 50:
            windows += buffer.trigger('test')
    return windows + buffer.flush(), most


@pytest.mark.parametrize('back, fed', [(None, 400), (39.0, 391)], ids=['never-back', 'back-at-39s'])
def test_a_window_whose_driving_topic_falls_silent_stays_within_the_budget_and_keeps_its_side_records(back, fed):
    """A window opens at 5 s (pre 2 s, post 2 s: it ends at 7 s) and the odometry dies at 5.5 s while the camera runs
    on, 10 times the budget of it: the driving clock never reached the window's end, the budget did not trim while it
    was open and its parts took side records up to its end only, so the camera after it piled up without bound (330 kB
    held of a 40 kB budget). Now the parts hold what a buffer without a budget writes (the camera from 3.05 s to
    6.95 s, each record once), and the camera after the window's end goes the oldest first at the budget, counted."""
    budget = 40000  # 40 camera records of 1000 bytes; 400 are fed
    buffer = WindowBuffer(pre='2s', post='2s', max_buffer_mb=budget / MB)
    windows, most = silent_stream(buffer, 1000, back=back)
    assert most <= budget
    cam = [r.msg for w in windows for r in w.records if r.topic == '/cam']
    unbounded, _ = silent_stream(WindowBuffer(pre='2s', post='2s', max_buffer_mb=0), 1000, back=back)
    assert cam == [r.msg for r in unbounded[0].records if r.topic == '/cam'] == list(range(30, 70))
    assert [r.msg for w in windows for r in w.records if r.topic == '/odom'] == list(range(30, 56))
    assert len(set(w.key for w in windows)) == len(unbounded) == 1 and windows[-1].final
    assert [w.part for w in windows] == list(range(1, len(windows) + 1)) and len(windows) >= 2
    # fed while silent (before the odometry came back) = 30 before the window + 40 in it + the 40 the budget holds
    # + those trimmed
    assert buffer.trimmed_silent == fed - 30 - 40 - budget // 1000 and buffer.trimmed == 0
