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
from cc_log.sim.kinematics import BWIBOT_LIMITS, Limits, integrate, limit, limit_speed, limit_yaw
from cc_log.sim.messages import yaw_of
from cc_log.sim.truth import truth_entry

_MOVING = 0.3                # m/s: the base counts as driving


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


def inject_anomalies(records, types=ANOMALY_TYPES, seed=0, topic=None, warmup=20.0, gap=20.0,
                     limits=BWIBOT_LIMITS, scale=None):
    """Put the simulator's anomaly models into a recorded odometry stream.

    ``records``: Record(stamp, topic, msg) in time order (other topics pass through untouched); ``topic``:
    the odometry topic (default: the first topic carrying nav_msgs/Odometry). One anomaly per entry of
    ``types``, in that order, spread evenly over the stream after ``warmup`` seconds and at least ``gap``
    seconds apart; types that need a moving robot start where it drives (>= 0.3 m/s when it can).

    Inside an anomaly the twist follows the model plus the recording's own noise (the residual of the
    recorded twist around its 0.5 s moving average, scaled down when the model is slower), and the pose is
    integrated from that twist (the mean twist of each step, turned by half the step's turn: a wheeled base's
    odometry, which never moves sideways); then the base gets back to the recorded twist within ``limits`` and
    the anomaly ends (``end``). From there on the recording goes on from where the anomaly left the base: every
    later pose is the recorded one moved rigidly (turned about z and shifted) so that it continues the injected
    track, as a robot's integrated odometry carries an offset; the twist is the recorded one. The motion the
    features see after ``end`` is the recording's (every feature set but ``raw`` is the same wherever the robot
    is and whichever way it faces), and there is no sideways slide back onto the recorded track. Messages
    before the first anomaly are the input's own; modified messages are copies; the input is not changed.

    ``scale``: the recorded robot's nominal envelope (a ``Limits``, e.g. ``nominal_envelope`` of its nominal
    driving) to inject anomalies at its own scale: every magnitude (deceleration of a collision, acceleration
    and extra speed of a surge, twisting amplitude, jump distance and turn, a planning failure's rates) is the
    BWIBot's times the envelope's ratio to ``BWIBOT_LIMITS``; slipping holds the pose whatever the scale. None
    (default): the BWIBot's magnitudes in m/s and rad/s. ``limits`` bounds the return to the recorded twist.

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

    recorded = (list(x), list(y), list(yaw))
    new = {}   # index in odom -> (x, y, yaw, v, w); x, y, yaw: the recorded track, carried by each anomaly
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
        if kind != 'localization_jump' and end - 1 in modified:
            _carry(modified[end - 1], end - 1, x, y, yaw)
        truth.append(truth_entry(kind, t[i0], t[end]))
        earliest = t[end] + gap

    out = list(records)
    x0, y0, yaw0 = recorded
    for i in range(n):
        if i in new:
            nx, ny, nyaw, nv, nw = new[i]
        elif (x[i], y[i], yaw[i]) != (x0[i], y0[i], yaw0[i]):
            nx, ny, nyaw, nv, nw = x[i], y[i], yaw[i], v[i], w[i]
        else:
            continue
        record = odom[i]
        msg = copy.deepcopy(record.msg)
        pose = msg.pose.pose
        pose.position.x, pose.position.y = nx, ny
        q = pose.orientation
        half_turn = 0.5 * (nyaw - yaw0[i])
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


def _carry(pose, last, x, y, yaw):
    """Move the track after index ``last`` rigidly (in place) so that it goes on from ``pose`` (x, y, yaw) where
    the recorded track went on from its own pose at ``last``."""
    px, py, pyaw = x[last], y[last], yaw[last]
    turn = pose[2] - pyaw
    c, s = math.cos(turn), math.sin(turn)
    for j in range(last + 1, len(x)):
        dx, dy = x[j] - px, y[j] - py
        x[j], y[j], yaw[j] = pose[0] + c * dx - s * dy, pose[1] + s * dx + c * dy, yaw[j] + turn


def _with_noise(cv, cw, v, w, v_s, w_s):
    """The model's twist plus the recording's own noise (its residual around the moving average), scaled
    down when the model moves slower than the recording (a base at rest reads no wheel noise)."""
    scale = min(1.0, (abs(cv) + 0.3 * abs(cw)) / max(abs(v_s) + 0.3 * abs(w_s), 0.05))
    return cv + scale * (v - v_s), cw + scale * (w - w_s)


def _inject_one(plan, i0, t, x, y, yaw, v, w, v_s, w_s, limits):
    """One anomaly from index i0: {index: (x, y, yaw, v, w)} and the index of the first message after it (the
    twist back to the recorded one)."""
    kind = plan['type']
    n = len(t)
    out = {}
    pose = (x[i0 - 1], y[i0 - 1], yaw[i0 - 1])           # the pose the anomaly starts from
    last = (v[i0 - 1], w[i0 - 1])                          # the twist of the message before
    v0, w0 = v_s[i0], w_s[i0]
    sv, sw = v_s[i0 - 1], w_s[i0 - 1]                     # smooth (noise-free) twist of the model

    def drive(i, ov, ow):
        """The message i drives at (ov, ow): its pose after the step from the message before."""
        nonlocal pose, last
        dt = max(t[i] - t[i - 1], 0.0)
        pose = integrate(pose[0], pose[1], pose[2], 0.5 * (last[0] + ov), 0.5 * (last[1] + ow), dt)
        last = (ov, ow)
        out[i] = pose + (ov, ow)

    i = i0
    # the anomaly itself
    while i < n and t[i] - t[i0] < plan['duration']:
        tau = t[i] - t[i0]
        dt = max(t[i] - t[i - 1], 0.0)
        if kind == 'localization_jump':
            dx, dy, dyaw = anomalies.jump_offset(plan, tau)
            out[i] = (x[i] + dx, y[i] + dy, yaw[i] + dyaw, v[i], w[i])
        elif kind == 'wheels_slipping':
            out[i] = pose + (v[i], w[i])
        else:
            cv, cw, limited = anomalies.command(plan, tau, v0, w0, v_s[i], w_s[i])
            if limited:
                cv = limit_speed(cv, sv, limits, dt)
                cw = limit_yaw(cw, sw, limits, dt)
            sv, sw = cv, cw
            drive(i, *_with_noise(cv, cw, v[i], w[i], v_s[i], w_s[i]))
        i += 1
    if kind in anomalies.MOVES_BASE:
        # back to the recorded twist within the base's limits
        while i < n and (abs(sv - v_s[i]) > 0.02 or abs(sw - w_s[i]) > 0.05) and t[i] - t[i0] < plan['duration'] + 10.0:
            dt = max(t[i] - t[i - 1], 0.0)
            sv = limit_speed(v_s[i], sv, limits, dt)
            sw = limit(w_s[i], sw, limits.max_yaw_accel, limits.max_yaw_accel, dt)
            drive(i, *_with_noise(sv, sw, v[i], w[i], v_s[i], w_s[i]))
            i += 1
    return out, min(i, n)
