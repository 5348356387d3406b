"""Triggers: every reason to keep a window, one home.

- ``classifier``: a learned model over a feature set (``classifier.ClassifierTrigger``);
- ``rule``: declarative conditions on any topic: a field compared with a value, a diagnostics level, a
  message arriving, a topic falling silent or slow (``rule.RuleTrigger``);
- ``manual``: on request, with a reason and an optional span (``manual.ManualTrigger``);
- ``periodic``: a window every ``every`` of message time, a nominal sample to retrain from
  (``periodic.PeriodicTrigger``).

``base.Trigger`` is what they share and ``base.Fire`` what they say; ``SmartLogger`` runs a list of them.
How to add a trigger: docs/DESIGN.md.
"""
from . import classifier  # noqa: F401  (each module registers its kind)
from . import rule  # noqa: F401
from . import manual  # noqa: F401
from . import periodic  # noqa: F401
from .base import Fire, Trigger, get, kinds, register
from .classifier import DEFAULT_CLASSIFY_EVERY, DEFAULT_RETRIGGER, RETRIGGER_MODES, ClassifierTrigger
from .manual import ManualTrigger
from .rule import RuleTrigger

__all__ = ['Fire', 'Trigger', 'ClassifierTrigger', 'RuleTrigger', 'ManualTrigger', 'get', 'kinds', 'register',
           'DEFAULT_CLASSIFY_EVERY', 'DEFAULT_RETRIGGER', 'RETRIGGER_MODES']
