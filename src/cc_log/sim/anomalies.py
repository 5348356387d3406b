"""The anomaly kinds and their models, shared by the simulator (``world``) and ``inject``.

Anomalies (``ANOMALY_TYPES``), each a separate event with nominal driving (at least ``gap`` seconds)
between events:

- ``planning_failure``: the planner oscillates back and forth or spins in place instead of progressing
  (within the base's limits).
- ``collision``: the base stops dead (deceleration far above the limit), then stands still for seconds.
- ``sudden_acceleration``: the base surges (several m/s^2) well above its top speed, then brakes back.
- ``excessive_twisting``: the yaw rate oscillates with large amplitude (yaw acceleration far above the
  limit) while the base drives on.
- ``localization_jump``: the odometry pose jumps (metres, tens of degrees), once or twice, and jumps back
  at the end, while the twist stays smooth.
- ``wheels_slipping``: the wheels keep turning (the twist says the base is moving) while the pose does not
  move.

Simulator only, never part of ``ANOMALY_TYPES`` (so never drawn unless named, and not for ``inject``, which
changes odometry alone): ``SIM_ONLY_TYPES``:

- ``soft_collision``: the base runs into something that gives (a person, a cart) and stops no harder than
  its own nominal stops: at ``SOFT_DECEL`` of the braking its planner plans with (``floor.PLANNED_DECEL``, half
  the base's ``max_decel``; a stop from cruise speed at the limit is a harder one than nominal driving ever
  makes, which odometry features see), then stands still for seconds while the planner keeps commanding motion;
  the IMU feels the impact as a short ringing acceleration spike (``impact``). Meant to be invisible to odometry
  features: only the IMU or the command against the motion should tell it.

A model is a plan (``draw_plan``: durations in seconds, so any rate works) and the twist it makes the base
drive ``tau`` seconds in (``command``; ``jump_offset`` for the pose of a localization jump). The ground truth
of the anomalies is ``truth``'s.
"""
import math

from cc_log.sim.floor import PLANNED_DECEL
from cc_log.sim.kinematics import BWIBOT_LIMITS

ANOMALY_TYPES = ('planning_failure', 'collision', 'sudden_acceleration', 'excessive_twisting',
                 'localization_jump', 'wheels_slipping')
MAX_ANOMALY_SECONDS = 10.0   # no anomaly's active phase lasts longer (simulator)
NEEDS_MOTION = ('collision', 'sudden_acceleration', 'excessive_twisting', 'wheels_slipping')  # start where it drives
MOVES_BASE = ('planning_failure', 'collision', 'sudden_acceleration', 'excessive_twisting')  # change the twist
SIM_ONLY_TYPES = ('soft_collision',)  # named explicitly (SimConfig.anomaly_types) only: IMU and commands needed
SOFT_DECEL = (0.6, 0.9)               # a soft collision's deceleration, as a fraction of the planned braking
IMPACT_PEAK = (5.0, 15.0)             # m/s^2: the spike's amplitude (0.5-1.5 g)
IMPACT_HZ = (20.0, 35.0)              # its ringing frequency
IMPACT_DECAY = (0.02, 0.05)           # s: its decay time constant


def parse_anomaly_types(value, name='anomaly_types', extra=()):
    """Anomaly types from a list/tuple or a comma-separated string ('all' or '' = every type of
    ``ANOMALY_TYPES``); ``extra``: more types accepted when named (``SIM_ONLY_TYPES``).

    Returns a tuple; raises ValueError naming ``name`` on an unknown type.
    """
    if value is None:
        return ANOMALY_TYPES
    if isinstance(value, str):
        text = value.strip()
        if text in ('', 'all'):
            return ANOMALY_TYPES
        items = [item.strip() for item in text.split(',') if item.strip()]
    else:
        items = [str(item).strip() for item in value]
    if not items:
        raise ValueError('%s: no anomaly type given (choose from %s)' % (name, ', '.join(ANOMALY_TYPES)))
    known = ANOMALY_TYPES + tuple(extra)
    for item in items:
        if item not in known:
            raise ValueError('%s: unknown anomaly type %r (choose from %s)'
                             % (name, item, ', '.join(known)))
    return tuple(items)


def draw_plan(kind, rng, v0, scale=None):
    """Draw the parameters of one anomaly of ``kind`` (durations in seconds, so any rate works).

    ``v0`` is the speed at the start. ``scale``: a robot's nominal envelope (``Limits``); the magnitudes are
    then the BWIBot's multiplied by the envelope's ratio to ``BWIBOT_LIMITS`` (None: the BWIBot's, unchanged).
    Returns a dict with at least 'type' and 'duration'.
    """
    def ratio(field):
        return 1.0 if scale is None else float(getattr(scale, field)) / getattr(BWIBOT_LIMITS, field)

    plan = {'type': kind}
    if kind == 'planning_failure':
        plan['variant'] = rng.choice(('spin', 'oscillate'))
        plan['duration'] = rng.uniform(5.0, 9.0)
        plan['direction'] = rng.choice((-1.0, 1.0))
        plan['yaw_rate'] = rng.uniform(0.7, 0.95) * ratio('max_yaw_rate')   # within the limit
        plan['speed'] = rng.uniform(0.2, 0.3) * ratio('max_speed')          # oscillation amplitude
        plan['period'] = rng.uniform(1.6, 2.4)
    elif kind == 'collision':
        plan['stop_time'] = rng.uniform(0.03, 0.06)                     # v0 -> 0 in tens of ms
        if scale is not None:   # the deceleration of that stop from the BWIBot's top speed, in the robot's ratio
            decel = BWIBOT_LIMITS.max_speed / plan['stop_time'] * ratio('max_decel')
            plan['stop_time'] = max(max(v0, 0.0) / decel, 1e-3)
        plan['duration'] = rng.uniform(3.0, 6.0)
    elif kind == 'soft_collision':
        plan['decel'] = rng.uniform(*SOFT_DECEL) * PLANNED_DECEL * ratio('max_decel')
        plan['stop_time'] = max(max(v0, 0.0) / plan['decel'], 1e-3)
        plan['duration'] = plan['stop_time'] + rng.uniform(3.0, 6.0)
        plan['peak'] = rng.uniform(*IMPACT_PEAK)
        plan['frequency'] = rng.uniform(*IMPACT_HZ)
        plan['decay'] = rng.uniform(*IMPACT_DECAY)
        plan['vertical'] = rng.uniform(0.2, 0.5)   # share of the spike felt along z (the base pitches)
    elif kind == 'sudden_acceleration':
        plan['accel'] = rng.uniform(3.0, 5.0) * ratio('max_accel')
        plan['peak'] = min(max(v0, 0.0) + rng.uniform(0.9, 1.3) * ratio('max_speed'), 2.2 * ratio('max_speed'))
        plan['rise'] = (plan['peak'] - max(v0, 0.0)) / plan['accel']
        plan['hold'] = rng.uniform(0.5, 1.0)
        plan['brake'] = rng.uniform(2.0, 3.0) * ratio('max_decel')
        plan['duration'] = plan['rise'] + plan['hold'] + plan['peak'] / plan['brake'] + 0.2
    elif kind == 'excessive_twisting':
        plan['amplitude'] = rng.uniform(1.5, 2.2) * ratio('max_yaw_rate')   # rad/s on top of the nominal rate
        plan['frequency'] = rng.uniform(1.0, 1.5)
        plan['duration'] = rng.randint(4, 7) / plan['frequency']        # whole cycles
    elif kind == 'localization_jump':
        plan['duration'] = rng.uniform(2.0, 4.0)
        jumps = rng.randint(1, 2)
        offsets = []
        for index in range(jumps):
            distance = rng.uniform(0.6, 2.0) * ratio('max_speed')   # 0.6-2 s of top speed
            bearing = rng.uniform(-math.pi, math.pi)
            yaw = rng.choice((-1.0, 1.0)) * min(rng.uniform(0.1, 0.45) * ratio('max_yaw_rate'), 0.5 * math.pi)
            offsets.append((index * plan['duration'] / jumps,
                            (distance * math.cos(bearing), distance * math.sin(bearing), yaw)))
        plan['offsets'] = offsets
    elif kind == 'wheels_slipping':
        plan['duration'] = rng.uniform(3.0, 6.0)
    else:
        raise ValueError('anomaly_types: unknown anomaly type %r' % (kind,))
    return plan


def command(plan, tau, v0, w0, v_nom, w_nom):
    """The base's twist ``tau`` seconds into an anomaly.

    ``v0, w0``: twist at its start; ``v_nom, w_nom``: what nominal driving would do now. Returns
    ``(v, w, limited)``; ``limited`` means the command still goes through the base's acceleration limits.
    """
    kind = plan['type']
    if kind == 'planning_failure':
        if plan['variant'] == 'spin':
            return 0.0, plan['direction'] * plan['yaw_rate'], True
        phase = 2.0 * math.pi * tau / plan['period']
        return (plan['speed'] * math.sin(phase),
                plan['direction'] * plan['yaw_rate'] * (1.0 if math.cos(phase) >= 0 else -1.0), True)
    if kind in ('collision', 'soft_collision'):
        f = max(0.0, 1.0 - tau / plan['stop_time'])
        return v0 * f, w0 * f, False
    if kind == 'sudden_acceleration':
        start = max(v0, 0.0)
        if tau < plan['rise']:
            v = start + plan['accel'] * tau
        elif tau < plan['rise'] + plan['hold']:
            v = plan['peak']
        else:
            v = max(v_nom, plan['peak'] - plan['brake'] * (tau - plan['rise'] - plan['hold']))
        return v, w_nom, False
    if kind == 'excessive_twisting':
        return v_nom, w_nom + plan['amplitude'] * math.sin(2.0 * math.pi * plan['frequency'] * tau), False
    return v_nom, w_nom, False  # localization_jump, wheels_slipping: the base drives on as commanded


def impact(plan, tau):
    """The acceleration (x, z in m/s^2, body frame) a soft collision's impact adds to the IMU ``tau`` seconds in:
    a decaying ring, braking first; (0, 0) for other types."""
    if plan['type'] != 'soft_collision' or tau < 0.0:
        return 0.0, 0.0
    ring = plan['peak'] * math.exp(-tau / plan['decay']) * math.sin(2.0 * math.pi * plan['frequency'] * tau)
    return -ring, plan['vertical'] * ring


def jump_offset(plan, tau):
    """Pose offset (dx, dy, dyaw) of a localization jump ``tau`` seconds in; None for other types."""
    if plan['type'] != 'localization_jump':
        return None
    current = (0.0, 0.0, 0.0)
    for at, offset in plan['offsets']:
        if tau >= at:
            current = offset
    return current


def schedule_types(types, count, rng):
    """``count`` anomaly types: seeded shuffles of ``types``, one after another."""
    order = []
    while len(order) < count:
        cycle = list(types)
        rng.shuffle(cycle)
        order.extend(cycle)
    return order[:count]
