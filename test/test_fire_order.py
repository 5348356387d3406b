"""A side record's Fire applies at the last driving record stamped before it, whatever order the topics arrive in
(``logger.fire_order``), and messages read at one time from several connections are put in stamp order
(``raw_message.in_stamp_order``): a window's span follows the stamps, live as in replay."""
import math
import os
import sys

import pytest
from hypothesis import given, settings, strategies as st

from cc_log.base import raw_message
from cc_log.base.records import Record
from cc_log.logger.fire_order import HeldFires
from cc_log.logger.smart import SmartLogger
from cc_log.storage import log_format
from cc_log.triggers import RuleTrigger

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from test_triggers import DIAG, ODOM, diag_msg, odom_msg  # noqa: E402

RATE = 50.0


def stamped_stream(errors):
    """(topic, msg, stamp) of 10 s of odometry at RATE from 100 s and a status 2 ms after every 25th odometry
    message, ERROR at the odometry indices ``errors``, in stamp order."""
    items = []
    for k in range(int(10 * RATE)):
        stamp = 100.0 + k / RATE
        items.append((ODOM, odom_msg(stamp), stamp))
        if k % 25 == 0 or k in errors:
            items.append((DIAG, diag_msg(stamp + 0.002, 2 if k in errors else 0), stamp + 0.002))
    return items


def early(items, shifts):
    """``items`` with the status after odometry message k taken ``shifts[k]`` odometry messages earlier (each
    topic's own order kept): it came on another connection, read before the odometry stamped before it."""
    odom = [item for item in items if item[0] == ODOM]
    at = {}  # odometry index -> statuses taken just before it
    seen = slot = 0
    for item in items:
        if item[0] == ODOM:
            seen += 1
        else:  # never before the status before it: a topic comes in the order it was sent
            slot = max(seen - shifts.get(seen - 1, 0), slot, 0)
            at.setdefault(slot, []).append(item)
    out = []
    for k, item in enumerate(odom):
        out.extend(at.get(k, []))
        out.append(item)
    out.extend(at.get(len(odom), []))
    return out


def windows(items, directory, errors_hold='5s'):
    logger = SmartLogger(None, str(directory), 'json-xz', '15', '15', driving_topic=ODOM,
                         triggers=[RuleTrigger('motor_error', level='ERROR', hold_off=errors_hold)])
    for topic, msg, stamp in items:
        logger.on_message(topic, msg, stamp)
    assert logger.close(30)
    found = []
    for path in log_format.window_files(str(directory)):
        metadata, records = log_format.read_window(path)
        found.append(([t['stamp'] for t in metadata['triggers']], metadata['reason'],
                      [r.stamp for r in records if r.topic == ODOM], [r.stamp for r in records if r.topic == DIAG]))
    return sorted(found)


def test_a_status_taken_before_the_odometry_stamped_before_it_keeps_the_window_of_the_stamp_order(tmp_path):
    items = stamped_stream({150, 400})
    expected = windows(items, tmp_path / 'in_order')
    assert len(expected) == 2
    for (fired, _, odom, _), k in zip(expected, (150, 400)):
        assert fired == [pytest.approx(100.0 + k / RATE)]  # the odometry message before the status
        assert odom[0] == pytest.approx(100.0 + (k - 15) / RATE)
        assert odom[-1] == pytest.approx(100.0 + (k + 15) / RATE)
    for shift in (1, 5, 40):
        assert windows(early(items, {150: shift, 400: shift}), tmp_path / ('early%d' % shift)) == expected, shift


@settings(max_examples=25, deadline=None)
@given(st.sets(st.integers(20, 480), max_size=3), st.dictionaries(st.integers(0, 499), st.integers(1, 60), max_size=8),
       st.lists(st.integers(1, 60), max_size=6))
def test_any_early_arrival_of_statuses_keeps_the_same_windows(tmp_path_factory, errors, shifts, error_shifts):
    items = stamped_stream(errors)
    shifts.update(zip(sorted(errors), error_shifts))  # those of the ERRORs drawn apart: most others are OK statuses
    directory = tmp_path_factory.mktemp('early')
    assert windows(early(items, shifts), directory / 'early') == windows(items, directory / 'in_order')


def test_a_status_taken_late_fires_at_the_newest_odometry():
    """Late (the odometry stamped after it came first): at once, at the newest driving record (nothing waits)."""
    held = HeldFires(ODOM, 10.0)
    assert not held.hold(99.0, ['late'], 100.0) and not held


def rec(stamp, topic=ODOM):
    return Record(stamp, topic, None)


def run(held, records, clock):
    """What ``HeldFires.add`` does with records: the parts added and the Fires applied, in order."""
    steps = []
    held.add(records, [r.topic for r in records], clock, lambda part, topics: steps.append([r.stamp for r in part]),
             lambda fires: steps.append(fires))
    return steps


def test_held_fires_apply_before_the_first_driving_record_stamped_after_them():
    held = HeldFires(ODOM, 10.0)
    assert held.hold(100.5, ['a'], 100.0) and held.hold(100.25, ['b'], 100.0)
    assert run(held, [rec(100.2), rec(100.3, DIAG), rec(100.4), rec(100.6), rec(100.7)], 100.0) == [
        [100.2, 100.3], ['b'], [100.4], ['a'], [100.6, 100.7]]
    assert not held


def test_held_fires_never_wait_past_max_ahead_a_jump_back_or_a_flush():
    held = HeldFires(ODOM, 2.0)
    assert not held.hold(102.5, ['far'], 100.0)  # more than max_ahead after the clock: at once
    assert held.hold(101.0, ['silent'], 100.0)
    # the driving topic falls silent: once a side record is stamped max_ahead after the Fire, at the clock
    assert run(held, [rec(101.5, DIAG), rec(103.0, DIAG), rec(103.5, DIAG)], 100.0) == [
        [101.5, 103.0], ['silent'], [103.5]]
    assert held.hold(100.5, ['jump'], 100.0)
    assert run(held, [rec(50.0), rec(50.1)], 100.0) == [['jump'], [50.0, 50.1]]  # the clock jumped back
    assert held.hold(100.5, ['x'], 100.0) and held.hold(100.7, ['y'], 100.0)
    assert held.release() == ['x', 'y'] and not held and held.release() == []
    assert not held.hold(math.nan, ['nan'], 100.0)
    assert held.hold(100.5, ['first'], None)  # before any driving record: it waits for the first
    assert run(held, [rec(100.2), rec(100.6)], None) == [[100.2], ['first'], [100.6]]


def test_a_status_taken_before_the_first_odometry_applies_where_its_stamp_lies(tmp_path):
    items = stamped_stream({20})
    error = next(i for i, (topic, _, stamp) in enumerate(items) if topic == DIAG and stamp > 100.4)  # at 100.402
    moved = [items[error]] + items[:error] + items[error + 1:]  # taken before any odometry
    assert windows(moved, tmp_path / 'moved') == windows(items, tmp_path / 'in_order') != []


def test_a_fire_held_at_close_is_kept_at_the_newest_odometry(tmp_path):
    items = stamped_stream(set()) + [(DIAG, diag_msg(109.99, 2), 109.99)]  # after the last odometry
    assert windows(items, tmp_path)[0][0] == [pytest.approx(109.98)]


def header():
    from nav_msgs.msg import Odometry
    return raw_message.class_header('/odom', Odometry)


def test_messages_read_at_one_time_from_several_connections_are_merged_by_stamp_each_topic_in_its_order():
    from diagnostic_msgs.msg import DiagnosticArray
    odom_header, diag_header = header(), raw_message.class_header(DIAG, DiagnosticArray)
    odom = [(ODOM, raw_message.serialized(odom_msg(100.0 + k / 10)), odom_header) for k in range(5)]
    diag = [(DIAG, raw_message.serialized(diag_msg(s, 0)), diag_header) for s in (100.05, 100.25, 100.2)]
    merged = raw_message.in_stamp_order(odom + diag)
    assert [(topic, round(raw_message.stamp(data, h, math.nan), 6)) for topic, data, h in merged] == [
        (ODOM, 100.0), (DIAG, 100.05), (ODOM, 100.1), (ODOM, 100.2), (DIAG, 100.25), (DIAG, 100.2), (ODOM, 100.3),
        (ODOM, 100.4)]  # a topic's own order kept (100.25 before 100.2: the order it was sent)
    assert raw_message.in_stamp_order(odom) is odom


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([ODOM, DIAG, '/raw']), st.binary(max_size=16)), max_size=30))
def test_any_pass_of_any_bytes_is_merged_into_a_permutation_keeping_each_topics_order(messages):
    """Hostile or short payloads (a stamp of any value, fewer bytes than a header) only reorder one pass."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import String
    headers = {ODOM: header(), DIAG: raw_message.class_header(DIAG, DiagnosticArray),
               '/raw': raw_message.class_header('/raw', String)}
    items = [(topic, data, headers[topic]) for topic, data in messages]
    merged = raw_message.in_stamp_order(items)
    assert sorted(map(id, merged)) == sorted(map(id, items))
    for topic in headers:
        assert [item for item in merged if item[0] == topic] == [item for item in items if item[0] == topic]
