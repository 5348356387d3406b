"""The exceptions cc_log raises on purpose, in one place. Each is a ``ValueError`` whose message is the one line a
user sees: what is wrong and where (a node prints it and exits 1, ``cclog`` exits 1 or 2)."""

__all__ = ['ConfigError', 'CommandError', 'ModelError', 'UnsafeDefinition', 'UndecodableRecord']


class ConfigError(ValueError):
    """Bad configuration of a node: the message is one line naming the parameter."""


class CommandError(ValueError):
    """Bad input found by a ``cclog`` command itself (the message is the one line printed)."""


class ModelError(ValueError):
    """A model file or model use that is not valid: the message names the file and what is wrong."""


class UnsafeDefinition(ValueError):
    """A message definition refused by ``safe_input.check_definition`` (the message says where and why)."""


class UndecodableRecord(ValueError):
    """A record of a batch that a trigger must read but cannot be decoded: ``index`` (its place in the batch;
    the records before it were taken), ``topic``, ``error`` (the decoding error)."""

    def __init__(self, index, topic, error):
        super(UndecodableRecord, self).__init__('%s: a message cannot be decoded (%s)' % (topic, error))
        self.index, self.topic, self.error = index, topic, error
