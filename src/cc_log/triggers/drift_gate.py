"""What the envelope trigger does once its own drift monitor has stated, for a whole span, that the driving left
the training data.

An envelope learned in one place (a corridor) is too tight where the robot drives otherwise (a lecture hall): its
per-feature maxima flag the new driving every few minutes, while the joint check's robust distance, which weighs
the features together, does not. ``on_drift`` (the trigger's key; the nodes' ``~on_drift`` and ``cclog replay
--on-drift``, declared in ``logger.options``) says what changes then:

- ``confirm`` (the default, chosen by the detector benchmark: docs/DETECTION.md, "Against the standard
  detectors"): a window beyond a feature's limit opens only where the robust distance confirms it, its squared
  distance beyond every training window's (the joint ratio at factor CONFIRM_FACTOR above 1), and the joint
  check's factor falls to DRIFT_JOINT_FACTOR (at most; the benchmark's level 2); the local part fires as before;
- ``none``: nothing changes.

The drift monitor is the one ``drift.monitor_envelopes`` reports (``cclog replay``'s summary, the node's
/diagnostics): a ``drift.DriftMonitor`` at ``drift.TRAINED_RATE_FLOOR`` with the envelope's coverage, fed every
window the trigger evaluates with whether it is beyond the envelope as without the gate (the gate never hides
from it the driving it judges), before the window is decided: a decision depends on the window and those before
it, as a live node sees them. The gate holds while drift has been stated (``DriftMonitor.stated``: 20 % of the
last 2 min flagged, 4 episodes in 2 min, or 20 % of it beyond a training maximum) without a break for the
monitor's whole span (``DriftMonitor.sustained``): a new place lasts; a short run that strays, or a true
anomaly's few seconds, do not make it (never before 3 min of driving: the monitor's settle, 1 min, then its span,
2 min). A file without a joint check has nothing to confirm with: ``confirm`` then changes nothing (the trigger
gets no monitor of its own). Pure: no rospy.
"""
import numpy as np

from cc_log.learning import drift

ON_DRIFT = ('confirm', 'none')
DEFAULT_ON_DRIFT = 'confirm'
CONFIRM_FACTOR = 1.0        # under drift a feature beyond its limit counts when d2 passes every training window's
DRIFT_JOINT_FACTOR = 2.0    # the joint check's factor under drift (at most)
ACTION = ('on_drift: confirm: while drift lasts, a window beyond a feature\'s limit opens only where the robust '
          'distance confirms it (farther from typical driving than any training window), and the joint check '
          'flags at %gx' % DRIFT_JOINT_FACTOR)


def check_on_drift(value, name='on_drift'):
    """``value`` when it is one of ON_DRIFT, else ValueError('<name>: ...')."""
    if value not in ON_DRIFT:
        raise ValueError('%s: %s is not one of %s' % (name, repr(value)[:40], ', '.join(ON_DRIFT)))
    return value


def monitor_for(trigger):
    """The drift monitor of an envelope trigger that gates (``drift.monitor_envelopes``' kind), its messages
    saying what the trigger does while drift lasts (``ACTION``)."""
    return drift.DriftMonitor(drift.TRAINED_RATE_FLOOR, name=trigger.name,
                              coverage=drift.EnvelopeCoverage(trigger.envelope), remedies=drift.ENVELOPE_REMEDIES,
                              action=ACTION)


def drifted_ratios(rows, worst, other, joint, joint_factor):
    """Of each row, ``(its largest ratio under drift, its confirming ratio)``: ``worst`` (the largest feature
    ratio) counts only as far as the confirming ratio (the joint ratio at CONFIRM_FACTOR) goes, ``other`` (the
    joint check's and the local part's, ``learning.envelope.part_ratios``) with the joint check at
    ``min(joint_factor, DRIFT_JOINT_FACTOR)``."""
    confirming = joint.ratios(rows, CONFIRM_FACTOR)
    lowered = joint.ratios(rows, min(joint_factor, DRIFT_JOINT_FACTOR))
    return np.maximum(np.minimum(worst, confirming), np.maximum(other, lowered)), confirming


def confirmation_why(row, joint):
    """The ``why`` entry of a window that fired under drift with its robust distance beyond every training
    window's: ``{feature: 'drift_confirmed', value: d2, limit: farthest, ratio: (d2 - typical) / (farthest -
    typical), unit: '1', text}``."""
    value = float(joint.distances(row))
    ratio = (value - joint.typical) / (joint.farthest - joint.typical)
    return {'feature': 'drift_confirmed', 'value': value, 'limit': float(joint.farthest), 'ratio': ratio,
            'unit': '1', 'text': 'under drift (on_drift: confirm): confirmed by the robust distance, %.1fx past '
                                 'every training window' % ratio}
