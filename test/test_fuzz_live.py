"""Property-based fuzzing of the live path (issue 42): hostile input (``fuzz_live_strategies``) fed to a
``SmartLogger`` as the intake feeds it (``on_records`` batches, manual requests between them), with the default
envelope trigger, a classifier and rules, writing bag-lz4 or json-xz with a small memory budget into an
example's own directory.

Each example must:
- let no exception escape ``on_records``, ``trigger_now``, ``stats`` or ``close``; a record a trigger cannot
  decode is ``errors.UndecodableRecord``, the drop the intake counts (``intake.Intake._feed_batch``: the batch
  goes on after it), and nothing else;
- keep each call within the bounds of ``test_fuzz_readers.bounded`` (5 s of CPU, 60 s of wall time) and the
  resident set's peak within ``MAX_BUFFER_MB`` + 150 MB of what it was before the logger was made;
- write nothing outside its directory, and there only window files that read back
  (``log_format.read_window``), each record of which was fed (its topic and bytes: nothing corrupted; json-xz:
  or its message's bytes once decoded, a string's invalid UTF-8 replaced: ``text_replaced``).

Settings as ``test_fuzz_readers``: a fixed seed, ``CC_LOG_FUZZ_EXAMPLES`` (default 15), ``CC_LOG_FUZZ_SEED``
for the rounds of the longer run (``tools/fuzz_long.sh``).
"""
import functools
import os
import tempfile

import pytest
from hypothesis import Phase, given
from hypothesis import strategies as st

import fuzz_live_strategies as fl
from test_fuzz_readers import Root, _reset_peak, _rss_kb, bounded, fuzz

pytest.importorskip('rosbag')

from cc_log.base import errors, raw_message  # noqa: E402
from cc_log.base.event_kinds import FAILED  # noqa: E402
from cc_log.base.raw_message import serialized  # noqa: E402
from cc_log.base.records import Record  # noqa: E402
from cc_log.logger.smart import SmartLogger  # noqa: E402
from cc_log.storage import log_format  # noqa: E402

MAX_BUFFER_MB = 8
MAX_GROWTH_MB = MAX_BUFFER_MB + 150


def feed(logger, records):
    """``logger.on_records(records)`` as the intake feeds it: past a record that cannot be decoded (dropped,
    counted) the rest of the batch goes on. The records taken."""
    taken = []
    while records:
        try:
            logger.on_records(records)
            return taken + list(records)
        except errors.UndecodableRecord as error:
            assert error.index < len(records) and '\n' not in str(error)
            taken += records[:error.index]
            records = records[error.index + 1:]
    return taken


def held(record):
    """The serialized bytes a window file holds of a record (bag-lz4: as written; json-xz: its message's)."""
    return record.raw if record.raw is not None else serialized(record.msg)


def text_replaced(record):
    """The bytes of a record's message decoded and serialized again: a json-xz window holds a string field as
    text, invalid UTF-8 replaced (genpy warns once); None when it does not decode."""
    try:
        return serialized(raw_message.decode(record.raw, record.connection))
    except Exception:  # anything: an expectation of the test, not the code under test
        return None


def check_windows(directory, fed):
    """Every file in ``directory`` is a window file that reads back, every record of it one of ``fed``."""
    paths = log_format.window_files(directory)
    assert sorted(os.listdir(directory)) == sorted(os.path.basename(path) for path in paths)
    for path in paths:
        result = bounded(log_format.read_window, path)
        assert not isinstance(result, ValueError), 'a window written does not read back: %s' % result
        _, records = result
        for record in records:
            assert (record.topic, held(record)) in fed, 'not fed: %s %r' % (record.topic, held(record)[:80])


def smart_logger(directory, fmt, triggers):
    """The logger under test: ``MAX_BUFFER_MB``, pre and post 1 s, every topic kept."""
    return SmartLogger(None, directory, fmt, '1s', '1s', driving_topic=fl.DRIVING, side_topics=None,
                       max_buffer_mb=MAX_BUFFER_MB, triggers=triggers)


@functools.lru_cache(maxsize=None)
def warmed_up():
    """Run a logger of every trigger once in each format (the modules, classes and buffers a first run makes are
    not the growth of an example)."""
    driving = fl.smooth_driving(200, 1432235498.0)
    for fmt in ('bag-lz4', 'json-xz'):
        with tempfile.TemporaryDirectory() as directory:
            logger = smart_logger(directory, fmt, fl.make_triggers(['envelope', 'classifier', 'when']))
            feed(logger, driving)
            logger.trigger_now('warm up')
            feed(logger, [record._replace(stamp=record.stamp + 4.0) for record in driving])
            assert logger.close(60)
    return True


def records_of_headers(headers, count=20):
    """``count`` serialized std_msgs/String records on /chatter for each connection header of ``headers``."""
    from std_msgs.msg import String
    return [Record(1432235499.1 + 0.04 * i, '/chatter', None, 0, serialized(String('m%d' % i)), header)
            for header in headers for i in range(count)]


def string_header(**changes):
    """A std_msgs/String publisher's connection header; ``changes``: keys replaced (None: removed)."""
    from std_msgs.msg import String
    header = {'type': String._type, 'md5sum': String._md5sum, 'message_definition': String._full_text,
              'callerid': '/talker', 'latching': '0'}
    header.update(changes)
    return {key: value for key, value in header.items() if value is not None}


# what rospy hands over from a publisher's header: keys missing (the intake's decoder lets a header without
# md5sum or definition through); values of other types and no header at all: what on_records may be given
BAD_HEADERS = {'no type': string_header(type=None), 'no md5sum': string_header(md5sum=None),
               'no definition': string_header(message_definition=None), 'md5sum 5': string_header(md5sum=5),
               'definition bytes': string_header(message_definition=b'string data'), 'no header': None}


@pytest.mark.parametrize('fmt', ['bag-lz4', 'json-xz'])
@pytest.mark.parametrize('bad', sorted(BAD_HEADERS))
def test_a_connection_header_without_type_md5sum_or_definition_is_refused_and_counted(tmp_path, bad, fmt):
    events = []
    logger = smart_logger(str(tmp_path), fmt, [])
    logger.on_event(events.append)
    driving = fl.smooth_driving(100, 1432235498.0)
    logger.on_records(driving[:50])
    logger.on_records(records_of_headers([BAD_HEADERS[bad]]) + records_of_headers([string_header()]))
    logger.on_records(driving[50:])
    assert logger.trigger_now('test')[0]
    assert logger.close(60)
    stats = logger.stats()
    assert stats['messages_refused'] == 20
    assert stats['last_refused'].startswith('/chatter: message refused (')
    assert [event.kind for event in events if event.kind == FAILED] == []
    (path,) = log_format.window_files(str(tmp_path))
    _, records = log_format.read_window(path)  # on a header without md5sum, a bag-lz4 window was unreadable
    assert sorted(held(record) for record in records if record.topic == '/chatter') == \
        sorted(record.raw for record in records_of_headers([string_header()]))


@functools.partial(fuzz, phases=[Phase.generate])  # no shrinking: it takes minutes over streams of MBs
@given(steps=fl.live_streams(), names=fl.trigger_sets(), fmt=st.sampled_from(['bag-lz4', 'json-xz']))
def test_hostile_live_input_through_a_smart_logger(steps, names, fmt):
    with Root(allow_in=True) as root:
        out = os.path.join(root.input, 'out')
        os.mkdir(out)
        assert warmed_up()
        triggers = fl.make_triggers(names)
        _reset_peak()  # not the peak of making the example's data
        before = _rss_kb('VmRSS')
        limits = dict(max_growth_mb=MAX_GROWTH_MB, since_kb=before)
        logger = smart_logger(out, fmt, triggers)
        fed = set()
        try:
            for step in steps:
                if step[0] == 'records':
                    taken = bounded(feed, logger, step[1], **limits)
                    assert not isinstance(taken, ValueError), 'on_records raised: %s' % taken
                    fed.update((record.topic, record.raw) for record in taken)
                    if fmt == 'json-xz':
                        fed.update((record.topic, text_replaced(record)) for record in taken)
                else:
                    answer = bounded(logger.trigger_now, 'fuzz', step[1], step[2], **limits)
                    assert isinstance(answer, tuple) and '\n' not in answer[1], answer
            assert not isinstance(bounded(logger.stats, **limits), ValueError)
        finally:
            closed = bounded(logger.close, 50, **limits)
        assert closed is True
        assert os.listdir(root.input) == ['out']
        check_windows(out, fed)


def test_a_window_in_parts_whose_every_record_is_refused_leaves_no_file(tmp_path):
    """Every record refused by the bag-lz4 writer (bytes not of their connection's type): the window fails, and
    the file begun for its parts is removed (it was left as ``.tmp-<pid>``, its descriptor open)."""
    import random
    events = []
    logger = smart_logger(str(tmp_path), 'bag-lz4', [])
    logger.on_event(events.append)
    wrong = fl._real_connection('sensor_msgs/Image')  # odometry said to be images
    driving = [record._replace(connection=wrong) for record in fl.smooth_driving(200, 1432235498.0)]
    noise = random.Random(0).randbytes(1 << 20)
    images = [Record(1432235498.5 + 0.1 * i, '/camera', None, 0, noise, wrong) for i in range(30)]
    logger.on_records(driving[:20])
    assert logger.trigger_now('test', 0.1, 10.0)[0]
    logger.on_records(images + driving[20:])
    assert logger.close(60)
    assert os.listdir(str(tmp_path)) == []
    assert FAILED in [event.kind for event in events]


@pytest.mark.parametrize('arrival', [float('nan'), float('inf'), -float('inf'), -1.0, 1e308, 1e18])
def test_an_arrival_stamp_that_is_no_time_is_the_one_before_and_counted(tmp_path, arrival):
    """A message arriving at NaN, an infinity, before 1970 or past any ROS time: placed at the arrival before it
    (without a header stamp) or by its header stamp, counted as restamped (a driving message's set the clock:
    windows at an infinity, an OverflowError out of ``on_records`` naming a file, or at no time)."""
    logger = smart_logger(str(tmp_path), 'bag-lz4', [])
    driving = fl.smooth_driving(100, 1432235498.0)
    odd = records_of_headers([string_header()], 1)[0]._replace(stamp=arrival)
    logger.on_records([odd, driving[0]._replace(stamp=arrival)] + driving[1:50])
    logger.on_records(driving[50:60] + [odd] + driving[60:])
    assert logger.trigger_now('test', 3.0, 1.0)[0]
    assert logger.close(60)
    assert logger.stats()['restamped_by_topic'] == {'/chatter': 2, fl.DRIVING: 1}
    (path,) = log_format.window_files(str(tmp_path))
    metadata, records = log_format.read_window(path)
    assert [(record.topic, record.stamp) for record in records if record.topic == '/chatter'] == \
        [('/chatter', driving[59].stamp)]  # the first came before the clock started (arrival 0): not in the window


@pytest.mark.parametrize('ahead', [86400.0 * 365, 2.0 ** 32 - 1432235498.0, 1e6])
def test_the_envelope_makes_no_grid_over_a_jump_of_the_stamps(ahead):
    """Odometry stamps jumping a year, to 2106 or 11 days ahead: the envelope evaluates the windows around the
    samples only (a grid over the gap of 2106 was 76 GiB: a MemoryError out of ``on_records``) and fires alike."""
    import test_envelope as te
    from cc_log.triggers.envelope import EnvelopeTrigger
    samples = te.nominal_drive(seconds=20.0, seed=1)
    later = (samples[0] + ahead,) + samples[1:]
    records = te.odom_records(samples) + te.odom_records(later)
    trigger = EnvelopeTrigger('envelope', fl._envelope(), fl.DRIVING)
    fires = bounded(te.fires_of, trigger, records, 256, max_growth_mb=50)
    assert not isinstance(fires, ValueError)
    apart = EnvelopeTrigger('envelope', fl._envelope(), fl.DRIVING)
    alone = te.fires_of(apart, te.odom_records(samples), 256)
    apart.reset()
    alone += te.fires_of(apart, te.odom_records(later), 256)
    assert [stamp for stamp, _ in fires] == [stamp for stamp, _ in alone]
    assert trigger.stats()['envelope_windows'] < 2 * len(te.envelope_windows(*samples)[0]) + 50  # not 4e6 ends
