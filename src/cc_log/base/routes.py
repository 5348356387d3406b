"""Routes: a window cut once and written as one file per route, each route a topic set in its own format.

A configuration's ``routes`` (``options``)::

    format: bag-lz4                                   # the window's own file: every topic no route takes
    routes:
      - {name: numeric, topics: [odom, imu/data, /diagnostics], format: json-xz}

write each window as ``cc_log_<UTC>_<reason>.bag`` (the cameras, the lidar) beside
``cc_log_<UTC>_<reason>+numeric.json.xz`` (the odometry, the IMU, the diagnostics: ``xz -dc | jq``-readable).
A topic goes to the first route whose ``topics`` match it (names, ``*``, ``re:``, ``!`` as the configuration's
``topics``), else to the window's own file. A route with ``copy: true`` takes a copy: its topics stay in the
window's own file too (a bag that replays the whole moment alone), and readers of the window's files read them
from the window's own file only. A topic name a route lists is subscribed (read from a bag) like the names of
``topics`` (``Config.named_topics``); one a bag lacks routes nothing, and ``cclog replay`` says so. The files
of one window share its name, reserved once (``storage.log_format``: ``<name>[+<route>][.<NNN>]<ext>``,
``SEPARATOR`` before the route): ``cclog info``, ``cat``, ``export`` and ``stats`` show them as one window. Pure.
"""
import collections
import re

from cc_log.base.records import LogWindow
from cc_log.base.safe_input import brief, loads_yaml, unknown_key
from cc_log.base.topic_select import TopicSelection

SEPARATOR = '+'  # between a window's name and a route's name in the route's file name
ROUTE_KEYS = ('name', 'topics', 'format', 'copy')
MAX_TEXT = 1 << 20  # characters of routes given as YAML text
_NAME = re.compile(r'[A-Za-z0-9-]{1,40}')


class Route(collections.namedtuple('Route', 'name selection format copy')):
    """One route: its ``name`` (in its file names), the ``TopicSelection`` of its topics, its ``format``, and
    ``copy``: True when its topics stay in the window's own file too."""

    __slots__ = ()

    def __new__(cls, name, selection, format, copy=False):
        return super(Route, cls).__new__(cls, name, selection, format, copy)

    def resolved(self, resolve):
        """The route with its topic names resolved by ``resolve`` (patterns are kept as they are)."""
        return self._replace(selection=self.selection.resolved(resolve))


def parse_routes(value, formats, name='routes'):
    """``[Route]`` of a list of ``{name, topics, format}`` mappings; ``formats``: the format names there are.
    ValueError('<name>[i]: ...') naming what is wrong."""
    if value in (None, '', ()):
        return []
    if isinstance(value, str):  # a launch argument: YAML text
        if len(value) > MAX_TEXT:
            raise ValueError('%s: longer than %d characters' % (name, MAX_TEXT))
        value = loads_yaml(value, name)
    if not isinstance(value, (list, tuple)):
        raise ValueError('%s: a list of {name, topics, format}, not %s' % (name, brief(value)))
    routes, names = [], set()
    for index, entry in enumerate(value):
        where = '%s[%d]' % (name, index)
        if isinstance(entry, Route):
            routes.append(entry)
            continue
        if not isinstance(entry, dict):
            raise ValueError('%s: a mapping {name, topics, format}, not %s' % (where, brief(entry)))
        unknown = unknown_key(entry, ROUTE_KEYS, where)
        if unknown:
            raise ValueError(unknown)
        route_name = entry.get('name')
        if not isinstance(route_name, str) or not _NAME.fullmatch(route_name):
            raise ValueError('%s: name: %s must be 1 to 40 letters, digits or "-"' % (where, brief(route_name)))
        if route_name in names:
            raise ValueError('%s: name %s is used twice' % (where, route_name))
        names.add(route_name)
        fmt = entry.get('format')
        if fmt not in formats:
            raise ValueError('%s (%s): format: %s is not one of: %s' % (
                where, route_name, brief(fmt), ', '.join(formats)))
        topics = entry.get('topics')
        if not isinstance(topics, (list, tuple)) or not topics:
            raise ValueError('%s (%s): topics: a list of topic names or patterns, not %s' % (
                where, route_name, brief(topics)))
        copy = entry.get('copy', False)
        if not isinstance(copy, bool):
            raise ValueError('%s (%s): copy: true or false, not %s' % (where, route_name, brief(copy)))
        routes.append(Route(route_name, TopicSelection.parse(list(topics), '%s (%s): topics' % (where, route_name)),
                            fmt, copy))
    return routes


def metadata(window_metadata, route):
    """The metadata of ``route``'s file of a window: the window's, with the route named (and ``copy: true`` for a
    copy) and what was dropped said once, in the window's own file."""
    result = dict(window_metadata, route=route.name)
    if route.copy:
        result['copy'] = True
    result.pop('dropped', None)
    return result


def route_of(topic, routes):
    """The first of ``routes`` whose topics match ``topic``, else None (the window's own file)."""
    return next((route for route in routes if route.selection.matches(topic)), None)


def format_of(topic, routes, own_format):
    """The format ``topic`` is written in: its route's, else the window's own ``own_format``."""
    route = route_of(topic, routes)
    return own_format if route is None else route.format


def split(window, routes):
    """``[(route or None, LogWindow)]``: ``window``'s records by route (None: the window's own file), each
    part with the window's triggers, part number, finality and key; a record a ``copy`` route takes is in the
    window's own part too; a route that takes no record of this window is left out, the window's own part never
    is (it carries the window's triggers even when empty)."""
    if not routes:
        return [(None, window)]
    by_route = collections.OrderedDict((route, []) for route in routes)
    own, cache = [], {}
    for record in window.records:
        route = cache.get(record.topic, False)
        if route is False:
            route = cache[record.topic] = route_of(record.topic, routes)
        if route is None or route.copy:
            own.append(record)
        if route is not None:
            by_route[route].append(record)
    parts = [(None, LogWindow(own, window.triggers, window.part, window.final, window.key))]
    parts += [(route, LogWindow(records, window.triggers, window.part, window.final, window.key))
              for route, records in by_route.items() if records or window.part]
    return parts
