"""The base's kinematics: its nominal limits and the acceleration-limited twist.

Shared by the simulated base (``world``), the route follower (``floor``), the anomaly models (``anomalies``)
and the injection into recorded odometry (``inject``).
"""
import collections
import math

Limits = collections.namedtuple('Limits', 'max_speed max_accel max_decel max_yaw_rate max_yaw_accel')
Limits.__doc__ = 'Nominal limits of a base: m/s, m/s^2 (speeding up), m/s^2 (braking), rad/s, rad/s^2.'

# BWIBot v2 on a Segway RMP 110, as configured for indoor navigation.
BWIBOT_LIMITS = Limits(max_speed=1.0, max_accel=0.8, max_decel=1.0, max_yaw_rate=1.0, max_yaw_accel=2.0)


def wrap(angle):
    """``angle`` in [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def clamp(value, low, high):
    """``value`` bounded to [low, high]."""
    return low if value < low else high if value > high else value


def limit(target, current, down, up, dt):
    """Move ``current`` towards ``target`` by at most ``up * dt`` upwards / ``down * dt`` downwards."""
    return clamp(target, current - down * dt, current + up * dt)


def limit_speed(target, current, limits, dt):
    """Acceleration-limited speed: braking (towards 0) at max_decel, speeding up at max_accel."""
    if current >= 0:
        return limit(target, current, limits.max_decel, limits.max_accel, dt)
    return limit(target, current, limits.max_accel, limits.max_decel, dt)


def limit_yaw(target, current, limits, dt):
    """Yaw rate limited in acceleration (max_yaw_accel) and in size (max_yaw_rate)."""
    return clamp(limit(target, current, limits.max_yaw_accel, limits.max_yaw_accel, dt),
                 -limits.max_yaw_rate, limits.max_yaw_rate)


def integrate(x, y, yaw, v, w, dt):
    """The pose (x, y, yaw) after driving at ``v`` m/s and turning at ``w`` rad/s for ``dt`` s (midpoint heading)."""
    heading = yaw + 0.5 * w * dt
    return x + v * dt * math.cos(heading), y + v * dt * math.sin(heading), yaw + w * dt
