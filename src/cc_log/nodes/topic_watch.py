"""Subscribe to topics that appear later: poll the master's published topics and hand every new topic the
selection matches to ``subscribe(topic)`` (the node's ``intake.subscribe``), once.

``TopicWatcher(selection, subscribe, published=rospy.get_published_topics, period=1.0, skip=())``: ``poll()``
checks once and returns the topics it subscribed; ``start()`` polls on a daemon thread every ``period``
seconds until ``stop()``. ``skip``: topics already subscribed (the driving topic, the named ones). A failing
poll (master gone) or subscribe is counted in ``errors`` with ``last_error`` and tried again next period.
"""
import threading

__all__ = ['TopicWatcher', 'DEFAULT_PERIOD']

DEFAULT_PERIOD = 1.0


def _published():
    import rospy
    return rospy.get_published_topics()


class TopicWatcher(object):
    """Polls for new topics matching ``selection`` (a ``topic_select.TopicSelection``)."""

    def __init__(self, selection, subscribe, published=None, period=DEFAULT_PERIOD, skip=()):
        self.selection = selection
        self._subscribe = subscribe
        self._published = published or _published
        self.period = float(period)
        self.subscribed = set(skip)
        self.added = []  # topics subscribed by the watcher, in order
        self.errors = 0
        self.last_error = ''
        self._stop = threading.Event()
        self._thread = None

    def poll(self):
        """Subscribe to the new matching topics; return them."""
        try:
            topics = sorted(topic for topic, _ in self._published())
        except Exception as error:  # the master is unreachable: try again next period
            self._failed('published topics: %s' % error)
            return []
        new = []
        for topic in self.selection.select(topics):
            if topic in self.subscribed:
                continue
            try:
                self._subscribe(topic)
            except Exception as error:
                self._failed('subscribe %s: %s' % (topic, error))
                continue
            self.subscribed.add(topic)
            self.added.append(topic)
            new.append(topic)
        return new

    def _failed(self, error):
        self.errors += 1
        self.last_error = error

    def start(self):
        """Poll now and then every ``period`` seconds on a daemon thread."""
        self.poll()
        self._thread = threading.Thread(target=self._loop, name='cc_log topic watch')
        self._thread.daemon = True
        self._thread.start()
        return self

    def _loop(self):
        while not self._stop.wait(self.period):
            self.poll()

    def stop(self):
        """Stop polling."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
