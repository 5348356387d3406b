"""``cclog plot``: a run's timeline, so a user sees why a window was or was not kept.

Top: the speed of the driving topic (nav_msgs/Odometry) over time with the saved windows shaded (classifier,
manual and rule windows each drawn their own way) and, with a ground-truth file, the true events. Middle: its
yaw rate (a twist, a spin). Bottom: the model's score over the whole run (with a bag and a model), the scores
of the triggers that fired, and the threshold. Time is in seconds from the start of the run; legends sit
right of the panels, off the data. ``draw(...)`` takes what was read (windows, motion samples, scores, truth)
and returns the figure, ``timeline(...)`` writes it; the readers here turn windows, bags and models into
those. matplotlib (Agg backend: no display) is imported only when drawing.
"""
import collections
import datetime
import math
import os

ODOMETRY = 'nav_msgs/Odometry'


def speed_of(msg):
    """|linear twist| of a nav_msgs/Odometry."""
    twist = msg.twist.twist.linear
    return math.sqrt(twist.x ** 2 + twist.y ** 2 + twist.z ** 2)


def motion_of(msg):
    """``(speed, yaw rate)`` of a nav_msgs/Odometry: |linear twist| and its angular z (rad/s)."""
    return speed_of(msg), msg.twist.twist.angular.z


def window_speeds(windows, driving):
    """``[(stamp, speed, yaw rate)]`` of the driving topic's odometry inside the windows (``[(path, metadata,
    records)]``), one list per window."""
    return [[(r.stamp,) + motion_of(r.msg) for r in records if r.topic == driving and r.msg._type == ODOMETRY]
            for _, _, records in windows]


# how each kind of window is shaded: classifier windows filled, manual ones hatched, others (rules, collect
# mode's files) in another colour
WINDOW_STYLES = collections.OrderedDict([
    ('classifier', dict(color='tab:orange', alpha=0.25, lw=0)),
    ('manual', dict(facecolor='none', edgecolor='tab:green', hatch='//', lw=0.8)),
    ('other', dict(color='tab:purple', alpha=0.18, lw=0)),
])


# the trigger markers are drawn above the score curve, the threshold and the windows (lines are at 2)
TRIGGER_ZORDER = 3


def window_kind(metadata):
    """``'classifier'`` when a trigger of the window has a score, else ``'manual'`` when one is the manual
    trigger, else ``'other'`` (rules, collect mode's files)."""
    triggers = [t for t in metadata.get('triggers') or [] if isinstance(t, dict)]
    if any(isinstance(t.get('score'), (int, float)) and not isinstance(t.get('score'), bool) for t in triggers):
        return 'classifier'
    if any(t.get('name', t.get('reason')) == 'manual' for t in triggers):
        return 'manual'
    return 'other'


def run_scores(bag, driving, model, stride=1):
    """``[(stamp, score)]`` of ``model`` over every feature window of the driving topic of a bag."""
    from cc_log.storage.bag import bagio  # rosbag: imported here so the module stays importable without it
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
    from cc_log import sim
    try:
        return sim.load_truth(path)
    except (IOError, OSError) as error:
        raise ValueError('%s: cannot read: %s' % (path, error.strerror or error))
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        raise ValueError('%s: not a truth file (a JSON list of {type, start, end}, or {"anomalies": [...]}): %s'
                         % (path, ' '.join(str(error).split())[:200]))


def _outside_legend(axis):
    """The axis's legend right of it, off the data (nothing when it has no labelled artist)."""
    if axis.get_legend_handles_labels()[0]:
        axis.legend(loc='upper left', bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8)


def _utc(stamp):
    moment = datetime.datetime(1970, 1, 1) + datetime.timedelta(seconds=float(stamp))
    return moment.strftime('%Y-%m-%d %H:%M:%S UTC')


def draw(windows, speed, curve=(), threshold=None, truth=(), title=None, width=11.0, speed_label=None):
    """``(figure, summary)``: the timeline drawn (see ``timeline`` for the arguments), not yet saved."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    parts = speed if speed and isinstance(speed[0], list) else [list(speed)]
    samples = sorted(s for part in parts for s in part)
    triggers, window_threshold = trigger_scores(windows)
    threshold = window_threshold if threshold is None else threshold
    starts = [samples[0][0]] if samples else []
    starts += [min(r.stamp for r in records) for _, _, records in windows if records]
    starts += [t for t, _ in curve[:1]] + [e['start'] for e in truth]
    origin = min(starts) if starts else 0.0
    yaw = any(len(s) > 2 for s in samples)
    rows = 3 if yaw else 2
    figure, axes = plt.subplots(rows, 1, sharex=True, figsize=(width, 7.5 if yaw else 6),
                                gridspec_kw={'height_ratios': [3, 2, 1.5] if yaw else [3, 1]})
    top, bottom = axes[0], axes[-1]
    for number, part in enumerate(parts):
        top.plot([s[0] - origin for s in part], [s[1] for s in part], lw=0.8, color='tab:blue',
                 label=speed_label if number == 0 else None)
        if yaw:
            axes[1].plot([s[0] - origin for s in part if len(s) > 2], [s[2] for s in part if len(s) > 2], lw=0.8,
                         color='tab:cyan', label='yaw rate' if number == 0 else None)
    kept, labelled = [], set()
    for _, metadata, records in windows:
        if not records:
            continue
        start, end = min(r.stamp for r in records), max(r.stamp for r in records)
        kept.append((start, end))
        kind = window_kind(metadata)
        for axis in axes:
            label = '%s window' % kind if axis is top and kind not in labelled else None
            axis.axvspan(start - origin, end - origin, label=label, **WINDOW_STYLES[kind])
        labelled.add(kind)
    for number, event in enumerate(truth):
        top.axvspan(event['start'] - origin, event['end'] - origin, ymin=0.0, ymax=0.06, color='tab:red',
                    lw=0, label='true event' if number == 0 else None)
        top.annotate(event['type'], (event['start'] - origin, 0.07), xycoords=('data', 'axes fraction'),
                     fontsize=7, color='tab:red', rotation=90, va='bottom')
    if curve:
        bottom.plot([t - origin for t, _ in curve], [v for _, v in curve], lw=0.7, color='tab:gray', label='score')
    if triggers:
        bottom.plot([t - origin for t, _ in triggers], [s for _, s in triggers], 'v', color='tab:red', ms=4,
                    label='trigger score', zorder=TRIGGER_ZORDER)
    if threshold is not None:
        bottom.axhline(threshold, color='k', ls='--', lw=0.8, label='threshold %.3g' % threshold)
    top.set_ylabel('speed (m/s)')
    top.set_title(title or '', fontsize=9)
    if yaw:
        axes[1].set_ylabel('yaw rate (rad/s)')
        axes[1].axhline(0.0, color='k', lw=0.4)
    bottom.set_ylabel('score')
    bottom.set_xlabel('seconds from the start (%s)' % _utc(origin))
    for axis in axes:
        _outside_legend(axis)
    figure.tight_layout()
    caught = sum(1 for e in truth if any(a <= e['end'] and e['start'] <= b for a, b in kept))
    ends = [s[0] for s in samples[-1:]] + [b for _, b in kept]
    return figure, collections.OrderedDict([
        ('windows', len(windows)), ('triggers', len(triggers)), ('speed_samples', len(samples)),
        ('scores', len(curve)), ('truth', len(truth)), ('truth_in_windows', caught), ('start', origin),
        ('end', max(ends) if ends else origin)])


def timeline(out, windows, speed, curve=(), threshold=None, truth=(), title=None, width=11.0, dpi=100,
             speed_label=None):
    """Draw the timeline into ``out`` (PNG, or the format of its extension); return a summary dict.

    windows: ``[(path, metadata, records)]``; speed: ``[(stamp, speed)]`` or ``[(stamp, speed, yaw rate)]`` of
    the whole run, or a list of such lists (one per window: drawn apart); curve: ``[(stamp, score)]``;
    threshold: the model's, else the windows'; truth: ``[{type, start, end}]``.
    """
    import matplotlib.pyplot as plt
    from cc_log.base.safe_files import AtomicFile
    figure, summary = draw(windows, speed, curve, threshold, truth, title, width, speed_label)
    with AtomicFile(out, overwrite=True) as stream:
        figure.savefig(stream, dpi=dpi, format=os.path.splitext(out)[1][1:].lower() or None,
                       bbox_inches='tight')
    plt.close(figure)
    summary['out'] = out
    summary.move_to_end('out', last=False)
    return summary
