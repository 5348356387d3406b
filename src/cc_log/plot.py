"""``cclog plot``: a run's timeline, so a user sees why a window was or was not kept.

Top: the speed of the driving topic (nav_msgs/Odometry) over time with the saved windows shaded and, with a
ground-truth file, the true events. Bottom: the model's score over the whole run (with a bag and a model),
the scores of the triggers that fired, and the threshold. ``timeline(...)`` takes what was read (windows,
speeds, scores, truth) and writes the image; the readers here turn windows, bags and models into those.
matplotlib (Agg backend: no display) is imported only when drawing.
"""
import collections
import math
import os

ODOMETRY = 'nav_msgs/Odometry'


def speed_of(msg):
    """|linear twist| of a nav_msgs/Odometry."""
    twist = msg.twist.twist.linear
    return math.sqrt(twist.x ** 2 + twist.y ** 2 + twist.z ** 2)


def window_speeds(windows, driving):
    """``[(stamp, speed)]`` of the driving topic's odometry inside the windows (``[(path, metadata,
    records)]``), one list per window."""
    return [[(r.stamp, speed_of(r.msg)) for r in records if r.topic == driving and r.msg._type == ODOMETRY]
            for _, _, records in windows]


def run_scores(bag, driving, model, stride=1):
    """``[(stamp, score)]`` of ``model`` over every feature window of the driving topic of a bag."""
    from . import bagio  # rosbag: imported here so the module stays importable without it
    stamps, vectors = bagio.feature_vectors(bag, driving, model.config, stride)
    return list(zip(stamps.tolist(), model.scores(vectors).tolist())) if len(stamps) else []


def trigger_scores(windows):
    """``([(stamp, score)] of the triggers with a score, threshold or None)`` of the windows' metadata."""
    triggers, threshold = [], None
    for _, metadata, _ in windows:
        for trigger in metadata.get('triggers') or []:
            if isinstance(trigger.get('score'), (int, float)):
                triggers.append((trigger['stamp'], trigger['score']))
        if isinstance(metadata.get('threshold'), (int, float)):
            threshold = metadata['threshold']
    return triggers, threshold


def load_truth(path):
    """The true events of a ground-truth file (``cclog simulate``'s ``<bag>.truth.json`` or a JSON list of
    ``{type, start, end}``); ValueError('<path>: ...') when it cannot be read."""
    from . import sim
    try:
        return sim.load_truth(path)
    except (IOError, OSError) as error:
        raise ValueError('%s: cannot read: %s' % (path, error.strerror or error))
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        raise ValueError('%s: not a truth file (a JSON list of {type, start, end}, or {"anomalies": [...]}): %s'
                         % (path, ' '.join(str(error).split())[:200]))


def timeline(out, windows, speed, curve=(), threshold=None, truth=(), title=None, width=11.0, dpi=100,
             speed_label=None):
    """Draw the timeline into ``out`` (PNG, or the format of its extension); return a summary dict.

    windows: ``[(path, metadata, records)]``; speed: ``[(stamp, speed)]`` of the whole run, or a list of such
    lists (one per window: drawn apart); curve: ``[(stamp, score)]``; threshold: the model's, else the
    windows'; truth: ``[{type, start, end}]``.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from .safe_files import AtomicFile
    parts = speed if speed and isinstance(speed[0], list) else [list(speed)]
    samples = sorted(s for part in parts for s in part)
    triggers, window_threshold = trigger_scores(windows)
    threshold = window_threshold if threshold is None else threshold
    starts = [samples[0][0]] if samples else []
    starts += [min(r.stamp for r in records) for _, _, records in windows if records]
    starts += [t for t, _ in curve[:1]] + [e['start'] for e in truth]
    origin = min(starts) if starts else 0.0
    figure, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(width, 6),
                                         gridspec_kw={'height_ratios': [3, 1]})
    for number, part in enumerate(parts):
        top.plot([s - origin for s, _ in part], [v for _, v in part], lw=0.8, color='tab:blue',
                 label=speed_label if number == 0 else None)
    kept = []
    for number, (_, _, records) in enumerate(windows):
        if not records:
            continue
        start, end = min(r.stamp for r in records), max(r.stamp for r in records)
        kept.append((start, end))
        for axis in (top, bottom):
            axis.axvspan(start - origin, end - origin, color='tab:orange', alpha=0.25, lw=0,
                         label='saved window' if number == 0 and axis is top else None)
    for number, event in enumerate(truth):
        top.axvspan(event['start'] - origin, event['end'] - origin, ymin=0.0, ymax=0.06, color='tab:red',
                    lw=0, label='true event' if number == 0 else None)
        top.annotate(event['type'], (event['start'] - origin, 0.07), xycoords=('data', 'axes fraction'),
                     fontsize=7, color='tab:red', rotation=90, va='bottom')
    if curve:
        bottom.plot([t - origin for t, _ in curve], [v for _, v in curve], lw=0.7, color='tab:gray', label='score')
    if triggers:
        bottom.plot([t - origin for t, _ in triggers], [s for _, s in triggers], 'v', color='tab:red', ms=4,
                    label='trigger score')
    if threshold is not None:
        bottom.axhline(threshold, color='k', ls='--', lw=0.8, label='threshold %.3g' % threshold)
    top.set_ylabel('speed (m/s)')
    top.set_title(title or '', fontsize=9)
    top.legend(loc='upper right', fontsize=8)
    bottom.set_ylabel('score')
    bottom.set_xlabel('time since %.3f (s)' % origin)
    if curve or triggers or threshold is not None:
        bottom.legend(loc='lower right', fontsize=8)
    figure.tight_layout()
    with AtomicFile(out, overwrite=True) as stream:
        figure.savefig(stream, dpi=dpi, format=os.path.splitext(out)[1][1:].lower() or None)
    plt.close(figure)
    caught = sum(1 for e in truth if any(a <= e['end'] and e['start'] <= b for a, b in kept))
    ends = [s for s, _ in samples[-1:]] + [b for _, b in kept]
    return collections.OrderedDict([
        ('out', out), ('windows', len(windows)), ('triggers', len(triggers)), ('speed_samples', len(samples)),
        ('scores', len(curve)), ('truth', len(truth)), ('truth_in_windows', caught), ('start', origin),
        ('end', max(ends) if ends else origin)])
