"""The physics envelope's features: 19 non-negative measures of one window of planar odometry.

``envelope_windows(stamps, x, y, yaw, v, w, window=1.0, stride=0.25)`` takes odometry samples in time order (stamps
s, pose x y m, heading rad, forward speed m/s, yaw rate rad/s) and returns the window end stamps and one row of
``ENVELOPE_COLUMNS`` per window. The windows end on the grid of multiples of ``stride`` (absolute stamps, so a live
trigger fed the same samples computes the same rows, ``envelope_rows``) from the first end that has ``window`` s of
samples before it to the last sample; a window holds the samples with ``end - window < t <= end`` and is left out
when it holds fewer than two. Samples that are not finite or do not move time forward are dropped first.

Per sample ``i`` (each measure is 0 where its reference is missing):

- a *step* is from the sample before (``dt = t[i] - t[i-1]``); a step over more than ``MAX_GAP`` (0.5 s) is none;
- a *derivative* is the difference to the newest sample at least ``DIFF_SPAN`` (0.05 s) earlier, over their time
  difference (at most ``MAX_GAP``), so close or jittered stamps do not make false extremes and a dropped sample
  only lengthens the span;
- a *span* is the same with the newest sample at least ``SPAN`` (0.2 s) and at most ``SPAN_MAX`` (0.3 s) earlier.

The columns (window = the samples in it; units in ``ENVELOPE_UNITS``):

==================== ==========================================================================================
``max_speed``        max ``|v|`` (m/s)
``max_yaw_rate``     max ``|w|`` (rad/s)
``max_accel``        max ``|dv/dt|``, derivatives (m/s^2)
``max_yaw_accel``    max ``|dw/dt|``, derivatives (rad/s^2)
``max_jerk``         max ``|d(dv/dt)/dt|``: the derivative of the derivative (m/s^3)
``speed_variation``  total variation of ``v``: sum of ``|v[i] - v[i-1]|`` over the window's steps (m/s)
``yaw_rate_variation`` total variation of ``w`` over the window's steps (rad/s)
``yaw_rate_flips``   sign changes of ``w`` among samples with ``|w| > FLIP_DEADBAND`` (0.05 rad/s) (count)
``max_pose_gap``     max over steps of the pose step minus the twist-predicted step: ``|(dx, dy) - v_mean dt
                     (cos yaw_mid, sin yaw_mid)|`` (m)
``sum_pose_gap``     the same summed over the window's steps (m)
``max_heading_gap``  max over steps of ``|wrap(yaw[i] - yaw[i-1]) - w_mean dt|``: heading change minus the
                     yaw-rate-integrated change (rad)
``sum_heading_gap``  the same summed (rad)
``still_fraction``   the fraction of the window's samples standing still (``|v| < STILL_SPEED``, 0.05 m/s) (1)
``still_yaw_rate``   max ``|w|`` among samples standing still (rad/s)
``max_span_accel``   max ``|dv/dt|`` over spans of 0.2-0.3 s (m/s^2)
``max_decel``        max deceleration: ``-d|v|/dt``, derivatives (m/s^2)
``max_speedup``      max acceleration: ``+d|v|/dt``, derivatives (m/s^2)
``max_speed_drop``   max over samples of the largest ``|v|`` of the 0.2 s before minus ``|v|`` now (m/s)
``max_speed_rise``   max over samples of ``|v|`` now minus the smallest ``|v|`` of the 0.2 s before (m/s)
==================== ==========================================================================================

``ENVELOPE_FLOORS``: the smallest limit each feature gets whatever the training saw (a robot that never turned
in training must not flag every turn; ``still_fraction``'s is 1, a whole window: parking alone never flags).
``odometry_samples(records)`` reads the six inputs from nav_msgs/Odometry records (serialized or decoded) with the
readers of ``motion``. Pure numpy, vectorised: no rospy.
"""
import numpy as np

from cc_log.features.base import CLIP
from cc_log.features.motion import OdometrySet, read_odometry, read_odometry_block_raw

ENVELOPE_COLUMNS = (
    'max_speed', 'max_yaw_rate', 'max_accel', 'max_yaw_accel', 'max_jerk',
    'speed_variation', 'yaw_rate_variation', 'yaw_rate_flips',
    'max_pose_gap', 'sum_pose_gap', 'max_heading_gap', 'sum_heading_gap',
    'still_fraction', 'still_yaw_rate', 'max_span_accel',
    'max_decel', 'max_speedup', 'max_speed_drop', 'max_speed_rise',
)
ENVELOPE_UNITS = {
    'max_speed': 'm/s', 'max_yaw_rate': 'rad/s', 'max_accel': 'm/s^2', 'max_yaw_accel': 'rad/s^2',
    'max_jerk': 'm/s^3', 'speed_variation': 'm/s', 'yaw_rate_variation': 'rad/s', 'yaw_rate_flips': '1',
    'max_pose_gap': 'm', 'sum_pose_gap': 'm', 'max_heading_gap': 'rad', 'sum_heading_gap': 'rad',
    'still_fraction': '1', 'still_yaw_rate': 'rad/s', 'max_span_accel': 'm/s^2',
    'max_decel': 'm/s^2', 'max_speedup': 'm/s^2', 'max_speed_drop': 'm/s', 'max_speed_rise': 'm/s',
}
ENVELOPE_FLOORS = {
    'max_speed': 0.1, 'max_yaw_rate': 0.1, 'max_accel': 0.5, 'max_yaw_accel': 0.5,
    'max_jerk': 5.0, 'speed_variation': 0.1, 'yaw_rate_variation': 0.1, 'yaw_rate_flips': 2.0,
    'max_pose_gap': 0.05, 'sum_pose_gap': 0.1, 'max_heading_gap': 0.05, 'sum_heading_gap': 0.1,
    'still_fraction': 1.0, 'still_yaw_rate': 0.1, 'max_span_accel': 0.5,
    'max_decel': 0.5, 'max_speedup': 0.5, 'max_speed_drop': 0.1, 'max_speed_rise': 0.1,
}
MAX_GAP = 0.5        # s: a longer step between samples is no step (its change measures read 0)
DIFF_SPAN = 0.05     # s: a derivative's shortest span
SPAN = 0.2           # s: the span of max_span_accel and of the speed drop and rise
SPAN_MAX = 0.3       # s: the longest span of max_span_accel
STILL_SPEED = 0.05   # m/s: standing still below it
FLIP_DEADBAND = 0.05  # rad/s: a yaw rate closer to 0 has no sign
HISTORY = 2 * MAX_GAP  # s: how far before a window's start its rows look (a derivative of a derivative)


def clean_samples(stamps, x, y, yaw, v, w):
    """The six inputs as float arrays of one length, keeping the finite samples that move time forward (ValueError
    when their lengths differ)."""
    arrays = [np.asarray(a, dtype=float).ravel() for a in (stamps, x, y, yaw, v, w)]
    n = len(arrays[0])
    if any(len(a) != n for a in arrays):
        raise ValueError('envelope: stamps, x, y, yaw, v and w must have one length, got %s'
                         % ', '.join(str(len(a)) for a in arrays))
    keep = np.isfinite(np.stack(arrays)).all(axis=0) if n else np.zeros(0, dtype=bool)
    t = np.where(keep, arrays[0], -np.inf)
    before = np.concatenate(([-np.inf], np.maximum.accumulate(t)[:-1])) if n else t
    keep &= t > before
    return [a[keep] for a in arrays]


def out_of_range_samples(stamps, x, y, yaw, v, w):
    """Which samples (a bool array) hold a value out of any physical range: a finite stamp with a position,
    speed or yaw rate that is not finite, or a speed or yaw rate beyond +-CLIP (``features.base.CLIP``).
    ``clean_samples`` drops them; the envelope trigger fires on the windows that hold one. A heading that cannot
    be read (a zero quaternion: some odometry has none) is only dropped."""
    t, x, y, v, w = (np.asarray(a, dtype=float).ravel() for a in (stamps, x, y, v, w))
    with np.errstate(invalid='ignore'):
        beyond = ~(np.abs(v) <= CLIP) | ~(np.abs(w) <= CLIP) | ~np.isfinite(x) | ~np.isfinite(y)
    return np.isfinite(t) & beyond


def _wrap(angle):
    return np.arctan2(np.sin(angle), np.cos(angle))


def _reference(t, span, longest):
    """Per sample, the index of the newest sample at least ``span`` s earlier and whether it is at most ``longest``
    s earlier (and exists)."""
    j = np.searchsorted(t, t - span, side='right') - 1
    ok = j >= 0
    j = np.maximum(j, 0)
    ok &= (t - t[j]) <= longest
    return j, ok


def _rate(values, t, j, ok):
    """(values - values[j]) / (t - t[j]) where ``ok``, else 0."""
    dt = np.where(ok, t - t[j], 1.0)
    return np.where(ok, (values - values[j]) / dt, 0.0)


def _range_reduce(ufunc, values, lo, hi):
    """``ufunc.reduce(values[lo[k]:hi[k]])`` along axis 0 for every k (each ``lo < hi``)."""
    index = np.empty(2 * len(lo), dtype=np.intp)
    index[0::2] = lo
    index[1::2] = hi
    padded = np.concatenate([values, values[-1:]])   # so hi == len(values) is a valid index
    return ufunc.reduceat(padded, index, axis=0)[0::2]


def _steps(t, x, y, yaw, v, w):
    """Per sample, its step from the sample before: ``(step, pose, wheels, turned, rate_turn)``: whether it is one
    (not the first, at most MAX_GAP), the pose's (dx, dy) and the twist-predicted one (mean speed x dt along the
    mean heading) as (n, 2) arrays, the heading change and the yaw-rate-integrated one (mean yaw rate x dt)."""
    dt = np.diff(t, prepend=t[:1])
    step = np.concatenate(([False], dt[1:] <= MAX_GAP))
    turned = _wrap(np.diff(yaw, prepend=yaw[:1]))
    mid_heading = np.concatenate((yaw[:1], yaw[:-1])) + 0.5 * turned
    travelled = 0.5 * (v + np.concatenate((v[:1], v[:-1]))) * dt
    pose = np.stack([np.diff(x, prepend=x[:1]), np.diff(y, prepend=y[:1])], axis=1)
    wheels = np.stack([travelled * np.cos(mid_heading), travelled * np.sin(mid_heading)], axis=1)
    rate_turn = 0.5 * (w + np.concatenate((w[:1], w[:-1]))) * dt
    return step, pose, wheels, turned, rate_turn


def _per_sample(t, x, y, yaw, v, w):
    """The per-sample measures: (maxima (n, 13), sums (n, 6)), the columns `_SOURCE` names."""
    n = len(t)
    speed = np.abs(v)
    step, pose, wheels, turned, rate_turn = _steps(t, x, y, yaw, v, w)

    def stepped(values):
        return np.where(step, values, 0.0)
    dv = stepped(np.abs(np.diff(v, prepend=v[:1])))
    dw = stepped(np.abs(np.diff(w, prepend=w[:1])))
    pose_gap = stepped(np.hypot(*(pose - wheels).T))
    heading_gap = stepped(np.abs(turned - rate_turn))

    j, ok = _reference(t, DIFF_SPAN, MAX_GAP)
    accel = _rate(v, t, j, ok)
    yaw_accel = _rate(w, t, j, ok)
    speed_rate = _rate(speed, t, j, ok)
    jerk = np.abs(_rate(accel, t, j, ok & ok[j]))
    js, oks = _reference(t, SPAN, SPAN_MAX)
    span_accel = np.abs(_rate(v, t, js, oks))

    first = np.searchsorted(t, t - SPAN, side='left')   # the oldest sample of the 0.2 s before each
    has = first < np.arange(n)
    lo, hi = np.where(has, first, 0), np.where(has, np.arange(n), 1)
    drop = np.where(has, _range_reduce(np.maximum, speed, lo, hi) - speed, 0.0)
    rise = np.where(has, speed - _range_reduce(np.minimum, speed, lo, hi), 0.0)

    significant = np.flatnonzero(np.abs(w) > FLIP_DEADBAND)
    flips = np.zeros(n)
    signs = np.sign(w[significant])
    flips[significant[1:][signs[1:] != signs[:-1]]] = 1.0
    still = speed < STILL_SPEED

    maxima = np.stack([speed, np.abs(w), np.abs(accel), np.abs(yaw_accel), jerk, pose_gap, heading_gap,
                       np.where(still, np.abs(w), 0.0), span_accel, np.maximum(-speed_rate, 0.0),
                       np.maximum(speed_rate, 0.0), np.maximum(drop, 0.0), np.maximum(rise, 0.0)], axis=1)
    sums = np.stack([dv, dw, flips, pose_gap, heading_gap, still.astype(float)], axis=1)
    return maxima, sums


# Where each column comes from: ('max', index into maxima) or ('sum', index into sums) or ('fraction', sums index)
_SOURCE = {
    'max_speed': ('max', 0), 'max_yaw_rate': ('max', 1), 'max_accel': ('max', 2), 'max_yaw_accel': ('max', 3),
    'max_jerk': ('max', 4), 'speed_variation': ('sum', 0), 'yaw_rate_variation': ('sum', 1),
    'yaw_rate_flips': ('sum', 2), 'max_pose_gap': ('max', 5), 'sum_pose_gap': ('sum', 3),
    'max_heading_gap': ('max', 6), 'sum_heading_gap': ('sum', 4), 'still_fraction': ('fraction', 5),
    'still_yaw_rate': ('max', 7), 'max_span_accel': ('max', 8), 'max_decel': ('max', 9),
    'max_speedup': ('max', 10), 'max_speed_drop': ('max', 11), 'max_speed_rise': ('max', 12),
}


def envelope_grid(first, last, window=1.0, stride=0.25):
    """The window ends of samples from ``first`` to ``last`` s: multiples of ``stride`` from ``first + window``
    to ``last`` (an empty array when there are none)."""
    if not (window > 0 and stride > 0):
        raise ValueError('envelope: window and stride must be positive, got %r and %r' % (window, stride))
    k0 = np.ceil((first + window) / stride - 1e-9)
    k1 = np.floor(last / stride + 1e-9)
    return np.arange(k0, k1 + 1) * stride if k1 >= k0 else np.zeros(0)


def envelope_rows(stamps, x, y, yaw, v, w, ends, window=1.0):
    """The rows of the windows of ``window`` s ending at ``ends``: (the ends kept (those with two samples or
    more), an (n, 19) matrix). The samples must reach ``HISTORY`` s before the first window for its rows to be
    those of ``envelope_windows``."""
    t, x, y, yaw, v, w = clean_samples(stamps, x, y, yaw, v, w)
    ends = np.asarray(ends, dtype=float).ravel()
    if len(t) < 2 or not len(ends):
        return np.zeros(0), np.zeros((0, len(ENVELOPE_COLUMNS)))
    lo = np.searchsorted(t, ends - window, side='right')
    hi = np.searchsorted(t, ends, side='right')
    full = hi - lo >= 2
    ends, lo, hi = ends[full], lo[full], hi[full]
    if not len(ends):
        return ends, np.zeros((0, len(ENVELOPE_COLUMNS)))
    maxima, sums = _per_sample(t, x, y, yaw, v, w)
    window_max = _range_reduce(np.maximum, maxima, lo, hi)
    totals = np.concatenate([np.zeros((1, sums.shape[1])), np.cumsum(sums, axis=0)])
    window_sum = totals[hi] - totals[lo]
    count = (hi - lo).astype(float)
    matrix = np.empty((len(ends), len(ENVELOPE_COLUMNS)))
    for column, name in enumerate(ENVELOPE_COLUMNS):
        how, index = _SOURCE[name]
        if how == 'max':
            matrix[:, column] = window_max[:, index]
        elif how == 'sum':
            matrix[:, column] = window_sum[:, index]
        else:
            matrix[:, column] = window_sum[:, index] / count
    return ends, np.maximum(matrix, 0.0)


def step_details(stamps, x, y, yaw, v, w, end, window=1.0):
    """What the largest pose and heading gaps of the window ending at ``end`` were, in words:
    ``{'max_pose_gap': 'pose moved 1.20 m in a step while the wheels reported 0.10 m', 'max_heading_gap':
    'heading turned 0.50 rad in a step, the yaw rate 0.01 rad'}`` (empty without a step)."""
    t, x, y, yaw, v, w = clean_samples(stamps, x, y, yaw, v, w)
    step, pose, wheels, turned, rate_turn = _steps(t, x, y, yaw, v, w)
    inside = np.flatnonzero(step & (t > end - window) & (t <= end))
    if not len(inside):
        return {}
    i = inside[np.argmax(np.hypot(*(pose[inside] - wheels[inside]).T))]
    k = inside[np.argmax(np.abs(turned[inside] - rate_turn[inside]))]
    return {'max_pose_gap': 'pose moved %.2f m in a step while the wheels reported %.2f m'
                            % (np.hypot(*pose[i]), np.hypot(*wheels[i])),
            'max_heading_gap': 'heading turned %.2f rad in a step, the yaw rate %.2f rad' % (turned[k], rate_turn[k])}


def envelope_windows(stamps, x, y, yaw, v, w, window=1.0, stride=0.25):
    """Window end stamps (n,) and the (n, 19) ``ENVELOPE_COLUMNS`` matrix of odometry samples in time order
    (stamps s, pose x y m, heading rad, forward speed m/s, yaw rate rad/s): one row per window of ``window`` s
    ending every ``stride`` s (see the module docstring)."""
    t = clean_samples(stamps, x, y, yaw, v, w)[0]
    if len(t) < 2:
        return np.zeros(0), np.zeros((0, len(ENVELOPE_COLUMNS)))
    return envelope_rows(stamps, x, y, yaw, v, w, envelope_grid(t[0], t[-1], window, stride), window)


def odometry_samples(records):
    """``(stamps, x, y, yaw, v, w)`` arrays of nav_msgs/Odometry ``records`` (``Record``s; serialized ones of
    the layout ``motion`` reads are read from their bytes, the others from their message): the stamp, the
    position, the heading of the orientation, the forward speed (twist linear x) and the yaw rate (twist angular
    z). A message that cannot be read gives NaN (``envelope_windows`` drops it)."""
    records = list(records)
    values = np.full((len(records), 13), np.nan)
    raw = [i for i, r in enumerate(records) if r.msg is None and r.raw is not None and
           OdometrySet.reads_raw(r.connection)]
    if raw:
        values[raw] = read_odometry_block_raw([records[i].raw for i in raw])
    for i in sorted(set(range(len(records))) - set(raw)):
        try:
            values[i] = read_odometry(records[i].msg)
        except (AttributeError, TypeError, ValueError, OverflowError):
            pass
    qx, qy, qz, qw = values[:, 3], values[:, 4], values[:, 5], values[:, 6]
    with np.errstate(invalid='ignore'):
        norm = qx * qx + qy * qy + qz * qz + qw * qw
        yaw = np.where(norm > 1e-12, np.arctan2(2.0 * (qw * qz + qx * qy), qw * qw + qx * qx - qy * qy - qz * qz),
                       np.nan)
    stamps = np.array([r.stamp for r in records], dtype=float)
    return stamps, values[:, 0], values[:, 1], yaw, values[:, 7], values[:, 12]
