"""A registry of named classes (feature sets, trigger kinds): where a newcomer adds one, and how it is found."""
import collections

from cc_log.base.safe_input import brief


class Registry(object):
    """Classes by the value of their attribute ``key``; ``what`` names them in errors
    (``ValueError("<what>: 'x' is not one of a, b")``)."""

    def __init__(self, what, key):
        self.what = what
        self.key = key
        self._classes = collections.OrderedDict()

    def register(self, cls):
        """Class decorator: add ``cls`` under its ``key`` attribute."""
        self._classes[getattr(cls, self.key)] = cls
        return cls

    def names(self):
        """The registered names, in registration order."""
        return tuple(self._classes)

    def get(self, name):
        """The class registered as ``name``; ValueError naming ``what`` otherwise."""
        try:
            return self._classes[name]
        except (KeyError, TypeError):
            raise ValueError('%s: %s is not one of %s' % (self.what, brief(name), ', '.join(self._classes)))
