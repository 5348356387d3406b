"""One vocabulary of window events (issue 44): the writer, the smart logger and the node's ``~anomalies`` say a
window's kind with ``base.event_kinds``, whose values are AnomalyEvent's constants on the wire, so nothing
translates one into another."""
import os
import re

import pytest

from cc_log.base import event_kinds
from cc_log.logger import smart, smart_events
from cc_log.storage import window_writer

KINDS = ('OPENED', 'WRITTEN', 'FAILED', 'SPLIT', 'DELETED')
MSG = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'msg', 'AnomalyEvent.msg')


def message_constants():
    """The constants of msg/AnomalyEvent.msg (name -> value), as genmsg reads ``uint8 NAME=value``."""
    with open(MSG) as stream:
        text = stream.read()
    return {name: int(value) for name, value in re.findall(r'^\s*uint8\s+([A-Z_]+)\s*=\s*(\d+)', text, re.M)}


def test_the_message_constants_are_the_vocabulary_on_the_wire():
    constants = message_constants()
    assert constants == {'OPENED': 0, 'WRITTEN': 1, 'FAILED': 2}  # the wire keeps its values
    assert constants == {name: getattr(event_kinds, name) for name in constants}


def test_the_kinds_are_distinct_and_defined_only_in_the_vocabulary():
    values = [getattr(event_kinds, name) for name in KINDS]
    assert len(set(values)) == len(KINDS)
    for module in (window_writer, smart_events, smart):
        for name in KINDS:  # a module may import a kind, never define one of its own
            assert getattr(module, name, getattr(event_kinds, name)) is getattr(event_kinds, name), (module, name)


def test_the_logger_says_the_writer_kind_as_it_is_and_the_node_publishes_it_unchanged(tmp_path):
    pytest.importorskip('rosbag')
    from cc_log.logger.smart import SmartLogger
    from test_heavy_windows import ODOM, feed, stream
    logger = SmartLogger(None, str(tmp_path), 'bag-lz4', '1s', '1s', driving_topic=ODOM, background=False)
    heard, said = [], []
    logger.writer.on_event(heard.append)
    logger.on_event(said.append)
    feed(logger, stream(1, camera_hz=1))
    ok, message = logger.trigger_now('door')
    assert ok, message
    assert logger.close(30)
    constants = message_constants()
    assert [event.kind for event in said] == [constants['OPENED'], constants['WRITTEN']]
    assert [event.kind for event in heard] == [constants['WRITTEN']]
