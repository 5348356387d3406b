"""Slower copies of nominal driving: the same paths driven with stops and slow stretches (a bench experiment of
``bench/detection_runs.py --slowed N [--braking B]``; not adopted, docs/RESULTS.md "Every real run with odometry").

A robot that drove a path nominally may drive it slower, stop on it and start again: that is nominal too. A
short training run often never does (a few minutes of cruising), and a one-class model then flags the robot's
first stop. ``slowed(records, ...)`` re-times nominal odometry along its own path: a speed factor ``s(t)`` in
[0, 1] (1 = as recorded) that ramps down to a stop or a crawl and back up at the run's own acceleration and
deceleration (``sim.nominal_envelope``; at least ``braking`` when given). Positions and orientations are the
recorded path at the re-timed instant (linear / normalized-linear interpolation), twists the recorded twist
there times ``s``, delayed by as much as the recording's twist lags its pose (``twist_lag``); the copy's stamps
are evenly spaced at the run's rate.
"""
import bisect
import copy
import math
import random

import numpy as np

from cc_log.base.records import Record

STOP_SECONDS = (1.0, 8.0)     # how long a stop holds
CRAWL_SECONDS = (3.0, 10.0)   # how long a slow stretch holds
CRAWL_FACTOR = (0.05, 0.5)    # its speed factor
CRUISE_SECONDS = (4.0, 15.0)  # recorded time driven as recorded between two slowdowns


def _lerp(a, b, f):
    return a + (b - a) * f


def _nlerp(q0, q1, f):
    if q0[0] * q1[0] + q0[1] * q1[1] + q0[2] * q1[2] + q0[3] * q1[3] < 0.0:
        q1 = tuple(-c for c in q1)
    q = [_lerp(a, b, f) for a, b in zip(q0, q1)]
    norm = math.sqrt(sum(c * c for c in q)) or 1.0
    return [c / norm for c in q]


def speed_profile(duration, dt, ramp_down, ramp_up, rng):
    """Speed factors, one per copy step of ``dt`` seconds, until ``duration`` seconds of the recording are
    driven: cruising (1), then a stop or a crawl reached at ``ramp_down`` and left at ``ramp_up`` (factor per
    second), and so on."""
    factors = []
    driven = 0.0
    while driven < duration:
        cruise = rng.uniform(*CRUISE_SECONDS)
        steps = int(cruise / dt)
        factors += [1.0] * steps
        driven += steps * dt
        if rng.random() < 0.5:
            low, hold = 0.0, rng.uniform(*STOP_SECONDS)
        else:
            low, hold = rng.uniform(*CRAWL_FACTOR), rng.uniform(*CRAWL_SECONDS)
        s = 1.0
        while s > low:
            s = max(low, s - ramp_down * dt)
            factors.append(s)
            driven += s * dt
        factors += [low] * int(hold / dt)
        driven += low * int(hold / dt) * dt
        while s < 1.0:
            s = min(1.0, s + ramp_up * dt)
            factors.append(s)
            driven += s * dt
    return factors


def state(msg):
    """``(position, orientation quaternion, twist: linear then angular)`` of a nav_msgs/Odometry, as tuples."""
    pose, twist = msg.pose.pose, msg.twist.twist
    p = (pose.position.x, pose.position.y, pose.position.z)
    q = (pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w)
    v = (twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y, twist.angular.z)
    return p, q, v


def _yaw(q):
    return math.atan2(2.0 * (q[3] * q[2] + q[0] * q[1]), 1.0 - 2.0 * (q[1] * q[1] + q[2] * q[2]))


def _correlation(a, b):
    """Pearson's correlation of two equal-length sequences (0 when either does not vary)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if len(a) < 3 or a.std() == 0.0 or b.std() == 0.0:
        return 0.0
    return float(np.corrcoef(a, b)[0, 1])


def twist_lag(t, states, max_lag=1.0):
    """Seconds by which the reported twist lags the pose (>= 0): the shift that best correlates the yaw rate
    and the speed from pose differences with the reported yaw rate and speed (some odometry filters its
    twist, e.g. the Husky's lags its pose by 0.5 s)."""
    steps = [(i, t[i + 1] - t[i]) for i in range(len(t) - 1) if t[i + 1] > t[i]]
    if len(steps) < 10:
        return 0.0
    yaw_rate, speed, w, v = [], [], [], []
    for i, dt in steps:
        (p0, q0, v0), (p1, q1, v1) = states[i], states[i + 1]
        turn = (_yaw(q1) - _yaw(q0) + math.pi) % (2.0 * math.pi) - math.pi
        yaw_rate.append(turn / dt)
        speed.append(math.sqrt(sum((b - a) ** 2 for a, b in zip(p0, p1))) / dt)
        w.append(0.5 * (v0[5] + v1[5]))
        v.append(0.5 * (math.sqrt(sum(c * c for c in v0[:3])) + math.sqrt(sum(c * c for c in v1[:3]))))
    dt = sorted(d for _, d in steps)[len(steps) // 2]
    best = (-2.0, 0)
    for shift in range(0, int(max_lag / dt) + 1):
        n = len(w) - shift
        score = (_correlation(yaw_rate[:n], w[shift:]) + _correlation(speed[:n], v[shift:]))
        best = max(best, (score, -shift))
    return -best[1] * dt


def _sample(t, values, at, lerp):
    i = min(max(bisect.bisect_right(t, at) - 1, 0), len(t) - 2)
    f = 0.0 if t[i + 1] <= t[i] else min(max((at - t[i]) / (t[i + 1] - t[i]), 0.0), 1.0)
    return i, lerp(values[i], values[i + 1], f)


def slowed(records, seed=0, envelope=None, braking=None):
    """A slower copy (list of Records, same topic) of ``records``, one continuous run of nav_msgs/Odometry
    Records in time order; ``envelope``: its ``sim.Limits`` (default: ``sim.nominal_envelope(records)``).
    A twist that lags the pose (``twist_lag``) lags it in the copy by as much."""
    from cc_log.sim import nominal_envelope
    if len(records) < 10:
        raise ValueError('records: %d odometry messages, too few to re-time' % len(records))
    envelope = envelope or nominal_envelope(records)
    t = [r.stamp for r in records]
    steps = sorted(b - a for a, b in zip(t, t[1:]) if b > a)
    dt = steps[len(steps) // 2]
    states = [state(r.msg) for r in records]
    lag = twist_lag(t, states)
    delay = int(round(lag / dt))
    speeds = sorted(abs(v[0]) for _, _, v in states)
    typical = max(speeds[int(0.9 * (len(speeds) - 1))], 0.1)
    rng = random.Random('%d:slowed' % int(seed))
    decel = max(envelope.max_decel, braking or 0.0)
    accel = max(envelope.max_accel, braking or 0.0)
    factors = speed_profile(t[-1] - t[0] - lag, dt, decel / typical, accel / typical, rng)
    poses = [(p, q) for p, q, _ in states]
    twists = [v for _, _, v in states]
    lerp_pose = lambda a, b, f: ([_lerp(x, y, f) for x, y in zip(a[0], b[0])], _nlerp(a[1], b[1], f))  # noqa: E731
    lerp_twist = lambda a, b, f: [_lerp(x, y, f) for x, y in zip(a, b)]  # noqa: E731
    out = []
    taus = []
    tau = t[0]
    for k, s in enumerate(factors):
        if tau + lag > t[-1]:
            break
        taus.append(tau)
        i, (p, q) = _sample(t, poses, tau, lerp_pose)
        j = max(k - delay, 0)    # the twist describes the motion ``delay`` steps earlier
        _, v = _sample(t, twists, taus[j] + lag, lerp_twist)
        msg = copy.deepcopy(records[i].msg)
        stamp = t[0] + k * dt
        msg.header.stamp = type(msg.header.stamp).from_sec(stamp)
        pose, twist = msg.pose.pose, msg.twist.twist
        pose.position.x, pose.position.y, pose.position.z = p
        o = pose.orientation
        o.x, o.y, o.z, o.w = q
        v = [factors[j] * c for c in v]
        twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y, twist.angular.z = v
        out.append(Record(stamp, records[i].topic, msg))
        tau += s * dt
    return out
