"""Whether one detector beats another on a robot by more than chance: exact tests on the bench's counts.

A robot with a few minutes of held-out driving gives each detector a dozen events and a handful of nominal
episodes; one event or one false window decides "dominates" there. These tests say whether such a difference
could be chance:

- catches: the two detectors saw the same events, so only the events one caught and the other missed tell them
  apart (McNemar's exact test: those discordant events split 50/50 under "equally good");
- false windows: both watched the same nominal driving for the same time, so under "equal rates" each false
  window is either's with probability 1/2 (the conditional binomial test of two Poisson counts).

``significantly_dominating`` keeps, of the detectors that dominate (as good on both, better on one), those whose
better side is significant at ``ALPHA``. Pure (scipy).
"""
from scipy.stats import binomtest

ALPHA = 0.05  # two-sided


def catches_p(caught_a, caught_b):
    """Two-sided p of "a and b catch equally often" from their per-event catches (same events, same order):
    McNemar's exact test; 1.0 when no event tells them apart."""
    only_a = sum(1 for a, b in zip(caught_a, caught_b) if a and not b)
    only_b = sum(1 for a, b in zip(caught_a, caught_b) if b and not a)
    if only_a + only_b == 0:
        return 1.0
    return binomtest(only_a, only_a + only_b, 0.5).pvalue


def false_windows_p(false_a, false_b):
    """Two-sided p of "a and b open false windows at the same rate" from their counts over the same hours."""
    if false_a + false_b == 0:
        return 1.0
    return binomtest(false_a, false_a + false_b, 0.5).pvalue


def significantly_better(caught, false, caught_ref, false_ref):
    """Whether (``caught`` per-event list, ``false`` count) beats the reference significantly on a side where it
    is better: more catches with ``catches_p`` < ALPHA, or fewer false windows with ``false_windows_p`` < ALPHA."""
    more = sum(caught) > sum(caught_ref) and catches_p(caught, caught_ref) < ALPHA
    fewer = false < false_ref and false_windows_p(false, false_ref) < ALPHA
    return more or fewer


def significantly_dominating(candidates, reference):
    """Of ``candidates`` ``{name: (caught list, false count)}``, the names that dominate ``reference`` (caught
    list, false count) — as many catches and no more false windows, more of one or fewer of the other — with
    their better side significant (``significantly_better``), each with its two p values:
    ``[(name, catches p, false windows p)]``."""
    caught_ref, false_ref = reference
    out = []
    for name, (caught, false) in candidates.items():
        dominates = sum(caught) >= sum(caught_ref) and false <= false_ref and (
            sum(caught) > sum(caught_ref) or false < false_ref)
        if dominates and significantly_better(caught, false, caught_ref, false_ref):
            out.append((name, catches_p(caught, caught_ref), false_windows_p(false, false_ref)))
    return out
