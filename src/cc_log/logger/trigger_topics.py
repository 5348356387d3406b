"""The triggers of one smart logger by topic: each a trigger with a name of its own (``check_triggers``), the
message type each topic must carry for them (``topic_types``), and the records as they see them (``TriggerViews``:
decoded where a trigger of the topic reads fields). Pure."""
import collections
import itertools

from cc_log.base import raw_message

__all__ = ['check_triggers', 'topic_types', 'TriggerViews']


def check_triggers(triggers):
    """The triggers, each a ``triggers.Trigger`` with a name of its own; ValueError('triggers: ...')."""
    seen = set()
    for trigger in triggers:
        name = getattr(trigger, 'name', None)
        if not hasattr(trigger, 'on_record') or not hasattr(trigger, 'topics'):
            raise ValueError('triggers: %r is not a trigger' % (trigger,))
        if name in seen:
            raise ValueError('triggers: two triggers are named %r' % name)
        seen.add(name)
    return list(triggers)


def topic_types(triggers):
    """``{topic: type}`` the triggers read; ValueError('topics: ...') when two read one topic as two types."""
    types, owners = {}, {}
    for trigger in triggers:
        for topic, kind in trigger.topic_types().items():
            if types.setdefault(topic, kind) != kind:
                raise ValueError('topics: %s is %s for trigger %s and %s for trigger %s'
                                 % (topic, types[topic], owners[topic], kind, trigger.name))
            owners.setdefault(topic, trigger.name)
    return types


class TriggerViews(object):
    """The records of a batch as the triggers of their topics see them (``by_topic``: topic -> its triggers)."""

    def __init__(self, triggers):
        self.by_topic = collections.defaultdict(list)
        for trigger in triggers:
            for topic in trigger.topics:
                self.by_topic[topic].append(trigger)
        self._decode = {}  # (topic, id(connection)) -> (connection, whether a trigger of the topic reads fields)

    def needs_message(self, record, triggers):
        """Whether a trigger reads fields of ``record``'s messages (memoised per topic and connection)."""
        key = (record.topic, id(record.connection))
        known = self._decode.get(key)
        if known is None or known[0] is not record.connection:
            known = self._decode[key] = (record.connection, any(t.needs_message(record) for t in triggers))
        return known[1]

    def views(self, records, topics, connections, stamps=None):
        """``(the records as the triggers see them: decoded where a trigger of the topic reads fields, the
        error decoding one)``; the views stop before a record that cannot be decoded. ``stamps``: the stamps the
        triggers see, when not the records' (a message the clock placed off its header stamp is seen at it)."""
        by_topic = self.by_topic
        if stamps is not None:
            records = [r if r.stamp == stamp else r._replace(stamp=stamp) for r, stamp in zip(records, stamps)]
        firsts = dict(zip(zip(map(id, connections), topics), records))  # one record of each connection and topic
        if not any(record.msg is None and topic in by_topic and self.needs_message(record, by_topic[topic])
                   for (_, topic), record in firsts.items()):
            return records, None
        views = list(records)
        for k, record in enumerate(records):
            triggers = by_topic.get(record.topic)
            if record.msg is None and triggers and self.needs_message(record, triggers):
                try:
                    views[k] = raw_message.decoded(record)  # before buffering: one that cannot be decoded is not kept
                except raw_message.DECODE_ERRORS as error:
                    return views[:k], error
        return views, None

    @staticmethod
    def ahead(batched, views, topics):
        """``{trigger: a deque of its Fires of each of its records of the batch, in order}`` of the ``batched``
        triggers (those that read a batch at once) with records in it (``views``, ``topics``: the batch's)."""
        present, ahead = set(topics), {}
        for trigger in batched:
            mine = views if present <= trigger.topics else \
                list(itertools.compress(views, map(trigger.topics.__contains__, topics)))
            if mine:
                ahead[trigger] = collections.deque(trigger.on_records(mine))
        return ahead

    def plan(self, ahead, topics):
        """``[(index, [Fires of each trigger in order])]``: the records of the batch that fire, in order, when every
        trigger of its topics read it ahead (``ahead``); else None (one reads record by record)."""
        by_topic = self.by_topic
        if any(trigger not in ahead for topic in set(topics) for trigger in by_topic.get(topic, ())):
            return None
        marks = collections.defaultdict(list)
        for trigger, fires in ahead.items():  # in the order of the triggers, as by_topic lists them
            places = range(len(topics)) if len(fires) == len(topics) else \
                itertools.compress(range(len(topics)), map(trigger.topics.__contains__, topics))
            for index, fired in itertools.compress(zip(places, fires), fires):
                marks[index].append(fired)
        return sorted(marks.items())
