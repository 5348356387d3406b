"""Triggers: every reason to keep a window, one home.

- ``classifier``: a learned model over a feature set (``classifier.ClassifierTrigger``);
- ``rule``: declarative conditions on any topic: a field compared with a value, a diagnostics level, a
  message arriving, a topic falling silent or slow (``rule.RuleTrigger``);
- ``manual``: on request, with a reason and an optional span (``manual.ManualTrigger``);
- ``periodic``: a window every ``every`` of message time, a nominal sample to retrain from
  (``periodic.PeriodicTrigger``);
- ``envelope``: odometry beyond the learned physics envelope of nominal driving (``envelope.EnvelopeTrigger``;
  under lasting drift ``drift_gate``).

``base.Trigger`` is what they share and ``base.Fire`` what they say; ``SmartLogger`` runs a list of them.
How to add a trigger: docs/DESIGN.md.
"""
from cc_log.triggers import classifier  # noqa: F401
from cc_log.triggers import rule  # noqa: F401
from cc_log.triggers import manual  # noqa: F401
from cc_log.triggers import periodic  # noqa: F401
from cc_log.triggers import envelope  # noqa: F401
from cc_log.triggers.base import Fire, Trigger, get, kinds, register
from cc_log.triggers.classifier import (
    DEFAULT_CLASSIFY_EVERY, DEFAULT_RETRIGGER, RETRIGGER_MODES, ClassifierTrigger)
from cc_log.triggers.manual import ManualTrigger
from cc_log.triggers.rule import RuleTrigger

__all__ = ['Fire', 'Trigger', 'ClassifierTrigger', 'RuleTrigger', 'ManualTrigger', 'get', 'kinds', 'register',
           'DEFAULT_CLASSIFY_EVERY', 'DEFAULT_RETRIGGER', 'RETRIGGER_MODES']
