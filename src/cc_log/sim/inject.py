"""The simulator's anomaly models put into recorded odometry: ``inject_anomalies``, ``nominal_envelope``.

The same models (``anomalies.draw_plan`` / ``anomalies.command``) that drive the simulated base are put into a
recorded odometry stream at any rate (e.g. real 10 Hz robot data); every message outside the anomalies stays
unchanged.
"""
import copy
import math
import random

from cc_log.sim import anomalies
from cc_log.sim.anomalies import ANOMALY_TYPES, parse_anomaly_types
from cc_log.sim.kinematics import BWIBOT_LIMITS, Limits, integrate, limit, limit_speed, limit_yaw, wrap
from cc_log.sim.messages import yaw_of
from cc_log.sim.truth import truth_entry

_MOVING = 0.3                # m/s: the base counts as driving
# The peak extra speed with which injected odometry gets back onto the recording, a share of limits.max_speed
# (0.8 m/s for the BWIBot's 1 m/s: a return at the robot's own scale, not the BWIBot's on every robot).
_CATCH_UP = 0.8


def _moving_average(values, half):
    """The mean of each value and its ``half`` neighbours on either side (fewer at the ends)."""
    n = len(values)
    prefix = [0.0]
    for value in values:
        prefix.append(prefix[-1] + value)
    out = []
    for i in range(n):
        lo, hi = max(0, i - half), min(n, i + half + 1)
        out.append((prefix[hi] - prefix[lo]) / (hi - lo))
    return out


def _smoothstep_parts(u):
    """(s, ds/du) of the smoothstep 3u^2 - 2u^3."""
    return u * u * (3.0 - 2.0 * u), 6.0 * u * (1.0 - u)


def inject_anomalies(records, types=ANOMALY_TYPES, seed=0, topic=None, warmup=20.0, gap=20.0,
                     limits=BWIBOT_LIMITS, scale=None):
    """Put the simulator's anomaly models into a recorded odometry stream.

    ``records``: Record(stamp, topic, msg) in time order (other topics pass through untouched); ``topic``:
    the odometry topic (default: the first topic carrying nav_msgs/Odometry). One anomaly per entry of
    ``types``, in that order, spread evenly over the stream after ``warmup`` seconds and at least ``gap``
    seconds apart; types that need a moving robot start where it drives (>= 0.3 m/s when it can).

    Inside an anomaly the twist follows the model plus the recording's own noise (the residual of the
    recorded twist around its 0.5 s moving average, scaled down when the model is slower), and the pose is
    integrated from that twist; then the base gets back to the recorded speed within its limits and the
    pose blends smoothly back onto the recorded track (at most 0.8 ``limits.max_speed`` faster or slower than recorded:
    0.8 m/s for the BWIBot, 8.7 m/s for a car whose envelope reaches 10.9 m/s),
    so every message from ``end`` on is the recorded one. Modified messages are copies; the input is not changed.

    ``scale``: the recorded robot's nominal envelope (a ``Limits``, e.g. ``nominal_envelope`` of its nominal
    driving) to inject anomalies at its own scale: every magnitude (deceleration of a collision, acceleration
    and extra speed of a surge, twisting amplitude, jump distance and turn, a planning failure's rates) is the
    BWIBot's times the envelope's ratio to ``BWIBOT_LIMITS``; slipping holds the pose whatever the scale. None
    (default): the BWIBot's magnitudes in m/s and rad/s. ``limits`` still bounds the return to the recording.

    Returns ``(records, truth)``: a new list of records and [{'type', 'start', 'end'}]. Raises ValueError
    when the anomalies do not fit into the stream.
    """
    types = parse_anomaly_types(types, 'types')
    if scale is not None and not all(float(value) > 0.0 for value in scale):
        raise ValueError('scale: %r must be positive in every field' % (tuple(scale),))
    records = list(records)
    if topic is None:
        topic = next((r.topic for r in records if getattr(r.msg, '_type', '') == 'nav_msgs/Odometry'), None)
        if topic is None:
            raise ValueError('topic: no nav_msgs/Odometry in the records')
    positions = [i for i, r in enumerate(records) if r.topic == topic]
    if len(positions) < 10:
        raise ValueError('topic: %d odometry messages on %s, too few' % (len(positions), topic))
    odom = [records[i] for i in positions]
    t = [r.stamp for r in odom]
    x = [r.msg.pose.pose.position.x for r in odom]
    y = [r.msg.pose.pose.position.y for r in odom]
    yaw = [yaw_of(r.msg.pose.pose.orientation) for r in odom]
    v = [r.msg.twist.twist.linear.x for r in odom]
    w = [r.msg.twist.twist.angular.z for r in odom]
    n = len(odom)
    steps = sorted(b - a for a, b in zip(t, t[1:]) if b > a)
    if not steps:
        raise ValueError('records: odometry stamps do not advance')
    rate = 1.0 / steps[len(steps) // 2]
    half = max(1, int(round(0.25 * rate)))
    v_s, w_s = _moving_average(v, half), _moving_average(w, half)
    rng = random.Random('%d:inject' % int(seed))
    duration = t[-1] - t[0]
    slot = (duration - warmup - gap / 2.0) / len(types) if types else 0.0
    if types and slot < gap + 5.0:
        raise ValueError('types: %d anomalies with warmup %g s and gap %g s do not fit into %.1f s of odometry'
                         % (len(types), warmup, gap, duration))

    new = {}   # index in odom -> (x, y, yaw, v, w)
    truth = []
    earliest = t[0] + warmup
    index_of = lambda stamp, lo=0: next((i for i in range(lo, n) if t[i] >= stamp), n)  # noqa: E731
    for number, kind in enumerate(types):
        target = max(t[0] + warmup + number * slot + rng.uniform(0.0, 0.2 * slot), earliest)
        lo = index_of(target)
        hi = index_of(target + max(0.3 * slot, 1.0), lo)
        if lo >= n - 2:
            raise ValueError('types: no room left for %s after %.1f s' % (kind, target - t[0]))
        i0 = lo
        if kind in anomalies.NEEDS_MOTION:
            moving = [i for i in range(max(lo, 1), max(hi, lo + 1)) if i < n and v_s[i] >= _MOVING]
            i0 = moving[0] if moving else max(range(lo, max(hi, lo + 1)), key=lambda i: v_s[min(i, n - 1)])
        i0 = max(i0, 1)
        plan = anomalies.draw_plan(kind, rng, v_s[i0], scale)
        modified, end = _inject_one(plan, i0, t, x, y, yaw, v, w, v_s, w_s, limits)
        if end >= n:
            raise ValueError('types: %s at %.1f s does not end before the odometry does'
                             % (kind, t[i0] - t[0]))
        new.update(modified)
        truth.append(truth_entry(kind, t[i0], t[end]))
        earliest = t[end] + gap

    out = list(records)
    for i, (nx, ny, nyaw, nv, nw) in sorted(new.items()):
        record = odom[i]
        msg = copy.deepcopy(record.msg)
        pose = msg.pose.pose
        pose.position.x, pose.position.y = nx, ny
        q = pose.orientation
        half_turn = 0.5 * (nyaw - yaw[i])
        c, s = math.cos(half_turn), math.sin(half_turn)       # rotate the recorded orientation about z
        q.x, q.y, q.z, q.w = c * q.x - s * q.y, c * q.y + s * q.x, c * q.z + s * q.w, c * q.w - s * q.z
        msg.twist.twist.linear.x = nv
        msg.twist.twist.angular.z = nw
        out[positions[i]] = type(record)(record.stamp, record.topic, msg)
    return out, truth


def nominal_envelope(records, topic=None, floor=0.1):
    """The largest speed, acceleration, deceleration, yaw rate and yaw acceleration (a ``Limits``) that the
    odometry on ``topic`` of nominal ``records`` shows, each of the twist's 0.5 s moving average (the smoothing
    ``inject_anomalies`` uses) and its slope over that span; at least ``floor`` times the BWIBot's limit (a
    robot that stood still). ``inject_anomalies(..., scale=)`` takes it."""
    odom = [r for r in records if (r.topic == topic if topic else getattr(r.msg, '_type', '') == 'nav_msgs/Odometry')]
    if len(odom) < 10:
        raise ValueError('topic: %d odometry messages on %s, too few for an envelope'
                         % (len(odom), topic or 'nav_msgs/Odometry'))
    t = [r.stamp for r in odom]
    steps = sorted(b - a for a, b in zip(t, t[1:]) if b > a)
    if not steps:
        raise ValueError('records: odometry stamps do not advance')
    half = max(1, int(round(0.25 / steps[len(steps) // 2])))
    v = _moving_average([r.msg.twist.twist.linear.x for r in odom], half)
    w = _moving_average([r.msg.twist.twist.angular.z for r in odom], half)
    pairs = [(i - half, i + half) for i in range(half, len(odom) - half) if t[i + half] > t[i - half]]
    dv = [(v[b] - v[a]) / (t[b] - t[a]) for a, b in pairs] or [0.0]
    dw = [abs(w[b] - w[a]) / (t[b] - t[a]) for a, b in pairs] or [0.0]
    found = Limits(max(abs(x) for x in v), max(dv), -min(dv), max(abs(x) for x in w), max(dw))
    return Limits(*(max(value, floor * bound) for value, bound in zip(found, BWIBOT_LIMITS)))


def _with_noise(cv, cw, v, w, v_s, w_s):
    """The model's twist plus the recording's own noise (its residual around the moving average), scaled
    down when the model moves slower than the recording (a base at rest reads no wheel noise)."""
    scale = min(1.0, (abs(cv) + 0.3 * abs(cw)) / max(abs(v_s) + 0.3 * abs(w_s), 0.05))
    return cv + scale * (v - v_s), cw + scale * (w - w_s)


def _inject_one(plan, i0, t, x, y, yaw, v, w, v_s, w_s, limits):
    """One anomaly from index i0: {index: (x, y, yaw, v, w)} and the index of the first unchanged message."""
    kind = plan['type']
    n = len(t)
    out = {}
    ax, ay, ayaw = x[i0 - 1], y[i0 - 1], yaw[i0 - 1]     # the pose the anomaly starts from
    v0, w0 = v_s[i0], w_s[i0]
    sv, sw = v_s[i0 - 1], w_s[i0 - 1]                     # smooth (noise-free) twist of the model
    i = i0
    # the anomaly itself
    while i < n and t[i] - t[i0] < plan['duration']:
        tau = t[i] - t[i0]
        dt = max(t[i] - t[i - 1], 0.0)
        if kind == 'localization_jump':
            dx, dy, dyaw = anomalies.jump_offset(plan, tau)
            out[i] = (x[i] + dx, y[i] + dy, yaw[i] + dyaw, v[i], w[i])
        elif kind == 'wheels_slipping':
            out[i] = (ax, ay, ayaw, v[i], w[i])
        else:
            cv, cw, limited = anomalies.command(plan, tau, v0, w0, v_s[i], w_s[i])
            if limited:
                cv = limit_speed(cv, sv, limits, dt)
                cw = limit_yaw(cw, sw, limits, dt)
            sv, sw = cv, cw
            ov, ow = _with_noise(cv, cw, v[i], w[i], v_s[i], w_s[i])
            ax, ay, ayaw = integrate(ax, ay, ayaw, ov, ow, dt)
            out[i] = (ax, ay, ayaw, ov, ow)
        i += 1
    if kind == 'localization_jump':
        return out, i
    if kind in anomalies.MOVES_BASE:
        # back to the recorded twist within the base's limits
        while i < n and (abs(sv - v_s[i]) > 0.02 or abs(sw - w_s[i]) > 0.05) and t[i] - t[i0] < plan['duration'] + 10.0:
            dt = max(t[i] - t[i - 1], 0.0)
            sv = limit_speed(v_s[i], sv, limits, dt)
            sw = limit(w_s[i], sw, limits.max_yaw_accel, limits.max_yaw_accel, dt)
            ov, ow = _with_noise(sv, sw, v[i], w[i], v_s[i], w_s[i])
            ax, ay, ayaw = integrate(ax, ay, ayaw, ov, ow, dt)
            out[i] = (ax, ay, ayaw, ov, ow)
            i += 1
    if i >= n:
        return out, n
    # blend the pose back onto the recorded track, starting from index i (twist: recorded + the blend's)
    last = i - 1
    if last not in out:
        return out, i
    dx, dy = out[last][0] - x[last], out[last][1] - y[last]
    dyaw = wrap(out[last][2] - yaw[last])
    # smoothstep blend: peak extra speed 1.5 * distance / span <= the catch-up speed, peak extra yaw rate <= 0.6 rad/s
    span = max(2.0, 1.5 * math.hypot(dx, dy) / (_CATCH_UP * limits.max_speed), 2.5 * abs(dyaw))
    t_b = t[last]
    while i < n and t[i] - t_b < span:
        u = (t[i] - t_b) / span
        s, ds = _smoothstep_parts(u)
        keep = 1.0 - s
        nyaw = yaw[i] + keep * dyaw
        ex, ey = -dx * ds / span, -dy * ds / span           # extra world velocity of the blend
        out[i] = (x[i] + keep * dx, y[i] + keep * dy, nyaw,
                  v[i] + ex * math.cos(nyaw) + ey * math.sin(nyaw), w[i] - dyaw * ds / span)
        i += 1
    return out, i
