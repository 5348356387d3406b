"""The simulated BWIBot and its labelled anomalies.

The paper evaluated CC-Log on a BWIBot simulated in Gazebo. Gazebo is not available here, so cc_log ships
this light kinematic simulator instead; it is also what the demo drives when there is no robot.

The robot
    A BWIBot v2 base (Segway RMP 110, differential drive) touring a fixed office floor: corridors around a
    loop, offices and a lab behind doors, an elevator lobby and an open atrium (``FloorPlan``). The robot
    picks a destination, plans the shortest route on the floor graph (Dijkstra), turns in place towards
    it, follows it with pure pursuit under indoor speed and acceleration limits (``BWIBOT_LIMITS``),
    slows for corners and doors, stops and waits a few seconds at the destination, and goes on.

What it publishes
    ``nav_msgs/Odometry`` on ``/odom`` (frame ``odom`` -> ``base_link``) at ``rate`` Hz: the wheel odometry,
    i.e. the pose integrated from measured wheel speeds, with a wheel-scale error, white speed noise, a
    slowly wandering yaw-rate bias (slow drift) and jittered stamps. Optionally ``sensor_msgs/Imu`` on
    ``/imu/data`` (body acceleration, centripetal term and gravity with noise, gyro with bias, orientation
    with slow yaw drift). Optionally (``commands``) what the navigation stack says: ``geometry_msgs/Twist``
    on ``/cmd_vel`` at ``COMMAND_RATE`` Hz (the planner's velocity command: the controller's, or the failing
    planner's during a planning failure) and a move_base-like ``actionlib_msgs/GoalStatusArray`` on
    ``/move_base/status`` at ``STATUS_RATE`` Hz (the current goal ACTIVE while the robot heads for a
    destination, SUCCEEDED once there; a planning failure ends with its goal ABORTED, published at once, and
    the robot going on under a new goal). Ground truth on ``/sim/anomaly`` (``std_msgs/String`` holding JSON,
    one message when an anomaly starts and one when it ends). Optionally (``camera``, ``scan``) a 320x240 rgb8
    ``sensor_msgs/Image`` on ``/camera/image_raw`` at 15 Hz and a ``sensor_msgs/LaserScan`` on ``/scan`` at 10 Hz,
    ray-cast against the floor plan's walls from the true pose (``sim_sensors``).

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

Ground truth is a list of dicts ``{'type', 'start', 'end'}``: the messages changed by an anomaly are those
with ``start <= stamp < end``; ``end`` is the stamp of the first nominal message after it (the message
whose difference to its predecessor still shows the end of the anomaly, e.g. the jump back).

The same anomaly models (``_draw_plan`` / ``_command``) drive the simulated base and ``inject_anomalies``,
which puts them into a recorded odometry stream at any rate (e.g. real 10 Hz robot data) and keeps every
message outside the anomalies unchanged.

Everything here is pure and deterministic: the same configuration and seed give identical messages.
``rospy`` and ``rosbag`` are not imported (``simulate_to_bag`` writes the bag with ``formats.bag_writer``).
"""
import collections
import copy
import heapq
import io
import json
import math
import random
import struct

import genpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu
from std_msgs.msg import String

from cc_log.sim import sensors as sim_sensors
from cc_log.sim.sensors import CAMERA_TOPIC, SCAN_TOPIC  # noqa: F401

ANOMALY_TYPES = ('planning_failure', 'collision', 'sudden_acceleration', 'excessive_twisting',
                 'localization_jump', 'wheels_slipping')

ODOM_TOPIC = '/odom'
IMU_TOPIC = '/imu/data'
CMD_TOPIC = '/cmd_vel'
STATUS_TOPIC = '/move_base/status'
TRUTH_TOPIC = '/sim/anomaly'
COMMAND_RATE = 20.0  # Hz of /cmd_vel (at most the odometry rate)
STATUS_RATE = 2.0    # Hz of /move_base/status
ACTIVE, SUCCEEDED, ABORTED = 1, 3, 4  # actionlib_msgs/GoalStatus values used
ODOM_FRAME = 'odom'
BASE_FRAME = 'base_link'
IMU_FRAME = 'imu_link'
DEFAULT_START_TIME = 1600000000.0  # stamps of a simulated run start here (2020-09-13), unless told
TRUTH_FORMAT = 'cc_log.sim.truth/1'
GRAVITY = 9.80665

Limits = collections.namedtuple('Limits', 'max_speed max_accel max_decel max_yaw_rate max_yaw_accel')
Limits.__doc__ = 'Nominal limits of a base: m/s, m/s^2 (speeding up), m/s^2 (braking), rad/s, rad/s^2.'

# BWIBot v2 on a Segway RMP 110, as configured for indoor navigation.
BWIBOT_LIMITS = Limits(max_speed=1.0, max_accel=0.8, max_decel=1.0, max_yaw_rate=1.0, max_yaw_accel=2.0)

MAX_ANOMALY_SECONDS = 10.0   # no anomaly's active phase lasts longer (simulator)
_SOFT_DECEL = 0.5            # braking the planner plans with (m/s^2), below the limit
_MOVING = 0.3                # m/s: the base counts as driving
_CATCH_UP = 0.8              # m/s: peak extra speed with which injected odometry gets back onto the recording


# ---------------------------------------------------------------------------------------------------------
# Configuration

def parse_anomaly_types(value, name='anomaly_types'):
    """Anomaly types from a list/tuple or a comma-separated string ('all' or '' = every type).

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
    for item in items:
        if item not in ANOMALY_TYPES:
            raise ValueError('%s: unknown anomaly type %r (choose from %s)'
                             % (name, item, ', '.join(ANOMALY_TYPES)))
    return tuple(items)


class SimConfig(object):
    """What to simulate.

    rate           odometry (and IMU) messages per second
    seed           integer seed: the same seed gives identical output
    minutes        simulated minutes; 0 = run until stopped (``Simulator.messages`` never ends)
    anomalies      how many anomalies to inject, spread over the run (types taken in a seeded shuffled
                   order, cycling through ``anomaly_types``)
    anomaly_types  which types to use (tuple, or comma-separated string)
    imu            also publish sensor_msgs/Imu on /imu/data
    commands       also publish /cmd_vel and /move_base/status (see the module docstring)
    camera, scan   also publish the camera's images and the laser scans (``sim_sensors``; off: cheap tests)
    start_time     stamp (float seconds) of the first message
    gap            at least this many seconds of nominal driving between anomalies (and before the first)
    warmup         seconds of nominal driving before the first anomaly
    jitter         standard deviation (s) of stamp jitter; 0 for exact 1/rate spacing
    noise          scale of all sensor noise and drift (1 = realistic, 0 = perfect sensors)
    """

    def __init__(self, rate=100.0, seed=0, minutes=10.0, anomalies=6, anomaly_types=ANOMALY_TYPES, imu=False,
                 start_time=DEFAULT_START_TIME, gap=20.0, warmup=20.0, jitter=0.0005, noise=1.0, commands=False,
                 camera=False, scan=False):
        self.rate = rate
        self.seed = seed
        self.minutes = minutes
        self.anomalies = anomalies
        self.anomaly_types = anomaly_types
        self.imu = imu
        self.start_time = start_time
        self.gap = gap
        self.warmup = warmup
        self.jitter = jitter
        self.noise = noise
        self.commands = commands
        self.camera = camera
        self.scan = scan

    def validate(self):
        """Check and normalise the fields; raise ValueError('<field>: <what is wrong>')."""
        def number(name, low=None, high=None, integer=False):
            value = getattr(self, name)
            if isinstance(value, bool):
                raise ValueError('%s: expected a number, got %r' % (name, value))
            try:
                value = int(value) if integer else float(value)
            except (TypeError, ValueError):
                raise ValueError('%s: expected %s, got %r' % (name, 'an integer' if integer else 'a number',
                                                              getattr(self, name)))
            if integer and float(getattr(self, name)) != value:
                raise ValueError('%s: expected an integer, got %r' % (name, getattr(self, name)))
            if not math.isfinite(value) or (low is not None and value < low) or (high is not None and value > high):
                raise ValueError('%s: %r is out of range [%s, %s]' % (name, getattr(self, name), low, high))
            setattr(self, name, value)
        number('rate', 1.0, 1000.0)
        number('seed', integer=True)
        number('minutes', 0.0, 24 * 60.0)
        number('anomalies', 0, 100000, integer=True)
        number('start_time', 0.0, 4e9)
        number('gap', 0.0, 3600.0)
        number('warmup', 0.0, 3600.0)
        number('jitter', 0.0, 0.2 / self.rate)
        number('noise', 0.0, 10.0)
        self.anomaly_types = parse_anomaly_types(self.anomaly_types)
        self.imu = bool(self.imu)
        self.commands, self.camera, self.scan = bool(self.commands), bool(self.camera), bool(self.scan)
        if self.anomalies and self.minutes > 0:
            slot = self.slot_seconds()
            need = self.gap + MAX_ANOMALY_SECONDS
            if slot < need:
                raise ValueError('anomalies: %d anomalies need %.0f s each (gap %g s + up to %g s of anomaly); '
                                 '%g minutes give %.1f s each' % (self.anomalies, need, self.gap,
                                                                  MAX_ANOMALY_SECONDS, self.minutes, slot))
        return self

    def slot_seconds(self):
        """Seconds of run per anomaly (a fixed 60 s when the run is unlimited)."""
        if self.minutes <= 0 or not self.anomalies:
            return max(60.0, 2.0 * (self.gap + MAX_ANOMALY_SECONDS))
        return (self.minutes * 60.0 - self.warmup - self.gap / 2.0) / self.anomalies

    def to_dict(self):
        """The configuration as plain JSON-able values."""
        return collections.OrderedDict(
            (name, list(value) if isinstance(value, tuple) else value)
            for name, value in sorted(vars(self).items()))

    def __repr__(self):
        return 'SimConfig(%s)' % ', '.join('%s=%r' % item for item in sorted(vars(self).items()))


# ---------------------------------------------------------------------------------------------------------
# The floor

class FloorPlan(object):
    """A building floor as a graph: named nodes at (x, y) metres, edges with a kind that sets the speed."""

    SPEEDS = {'corridor': 1.0, 'passage': 0.8, 'atrium': 0.8, 'door': 0.35, 'room': 0.5}

    def __init__(self, nodes, edges, destinations, start):
        self.nodes = dict(nodes)
        self.edges = list(edges)
        self.destinations = list(destinations)
        self.start = start
        self._adjacent = collections.defaultdict(list)
        for a, b, kind in self.edges:
            if a not in self.nodes or b not in self.nodes or kind not in self.SPEEDS:
                raise ValueError('floor: bad edge %r' % ((a, b, kind),))
            length = math.hypot(self.nodes[b][0] - self.nodes[a][0], self.nodes[b][1] - self.nodes[a][1])
            self._adjacent[a].append((b, kind, length))
            self._adjacent[b].append((a, kind, length))

    @classmethod
    def bwi_floor(cls):
        """An office floor after the BWI lab's (Gates Dell Complex): a 40 m x 20 m corridor loop with a
        central corridor and elevator lobby, offices, lab, kitchen and conference room behind doors, and an
        open atrium east of the loop."""
        nodes = {
            'S0': (0.0, 0.0), 'S1': (10.0, 0.0), 'S2': (20.0, 0.0), 'S3': (30.0, 0.0), 'S4': (40.0, 0.0),
            'N0': (0.0, 20.0), 'N1': (10.0, 20.0), 'N2': (20.0, 20.0), 'N3': (30.0, 20.0), 'N4': (40.0, 20.0),
            'W1': (0.0, 10.0), 'E1': (40.0, 10.0), 'LOBBY': (20.0, 10.0),
            'ATRIUM_GATE': (44.0, 10.0), 'ATRIUM': (52.0, 10.0), 'ATRIUM_SW': (48.0, 4.0),
            'ATRIUM_NW': (48.0, 16.0), 'ATRIUM_SE': (56.0, 4.0), 'ATRIUM_NE': (56.0, 16.0),
            'LAB_DOOR': (-1.2, 10.0), 'LAB': (-5.0, 10.0),
            'OFFICE1_DOOR': (10.0, -1.2), 'OFFICE1': (10.0, -4.5),
            'OFFICE2_DOOR': (30.0, -1.2), 'OFFICE2': (30.0, -4.5),
            'OFFICE3_DOOR': (10.0, 21.2), 'OFFICE3': (10.0, 24.5),
            'KITCHEN_DOOR': (30.0, 21.2), 'KITCHEN': (30.0, 24.5),
            'CONFERENCE_DOOR': (21.2, 10.0), 'CONFERENCE': (25.0, 10.0),
        }
        corridor = [('S0', 'S1'), ('S1', 'S2'), ('S2', 'S3'), ('S3', 'S4'), ('N0', 'N1'), ('N1', 'N2'),
                    ('N2', 'N3'), ('N3', 'N4'), ('S0', 'W1'), ('W1', 'N0'), ('S4', 'E1'), ('E1', 'N4'),
                    ('S2', 'LOBBY'), ('LOBBY', 'N2')]
        atrium = [('ATRIUM_GATE', 'ATRIUM'), ('ATRIUM_GATE', 'ATRIUM_SW'), ('ATRIUM_GATE', 'ATRIUM_NW'),
                  ('ATRIUM', 'ATRIUM_SW'), ('ATRIUM', 'ATRIUM_NW'), ('ATRIUM', 'ATRIUM_SE'),
                  ('ATRIUM', 'ATRIUM_NE'), ('ATRIUM_SW', 'ATRIUM_SE'), ('ATRIUM_NW', 'ATRIUM_NE'),
                  ('ATRIUM_SE', 'ATRIUM_NE')]
        rooms = [('W1', 'LAB'), ('S1', 'OFFICE1'), ('S3', 'OFFICE2'), ('N1', 'OFFICE3'), ('N3', 'KITCHEN'),
                 ('LOBBY', 'CONFERENCE')]
        edges = [(a, b, 'corridor') for a, b in corridor] + [(a, b, 'atrium') for a, b in atrium]
        edges.append(('E1', 'ATRIUM_GATE', 'passage'))
        for hall, room in rooms:
            edges.append((hall, room + '_DOOR', 'door'))
            edges.append((room + '_DOOR', room, 'room'))
        destinations = ['LAB', 'OFFICE1', 'OFFICE2', 'OFFICE3', 'KITCHEN', 'CONFERENCE', 'LOBBY', 'ATRIUM',
                        'ATRIUM_SE', 'ATRIUM_NE']
        return cls(nodes, edges, destinations, start='LAB')

    def route(self, start, goal):
        """Shortest route from node ``start`` to node ``goal``: (node names, kinds of the edges)."""
        queue = [(0.0, start)]
        best = {start: (0.0, None, None)}
        done = set()
        while queue:
            cost, node = heapq.heappop(queue)
            if node in done:
                continue
            done.add(node)
            if node == goal:
                break
            for other, kind, length in sorted(self._adjacent[node]):
                new = cost + length / self.SPEEDS[kind]   # time-shortest
                if other not in best or new < best[other][0] - 1e-12:
                    best[other] = (new, node, kind)
                    heapq.heappush(queue, (new, other))
        if goal not in done:
            raise ValueError('floor: no route from %s to %s' % (start, goal))
        names, kinds = [goal], []
        while names[-1] != start:
            _, previous, kind = best[names[-1]]
            names.append(previous)
            kinds.append(kind)
        return names[::-1], kinds[::-1]


class _Path(object):
    """A polyline with per-segment speed limits, followed by pure pursuit."""

    def __init__(self, points, speeds, limits):
        self.points = points
        self.speeds = speeds
        self.lengths = [math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(points, points[1:])]
        self.cumulative = [0.0]
        for length in self.lengths:
            self.cumulative.append(self.cumulative[-1] + length)
        self.total = self.cumulative[-1]
        corner = [0.0] * len(points)   # speed allowed at each vertex
        for j in range(1, len(points) - 1):
            a, b, c = points[j - 1], points[j], points[j + 1]
            turn = abs(_wrap(math.atan2(c[1] - b[1], c[0] - b[0]) - math.atan2(b[1] - a[1], b[0] - a[0])))
            corner[j] = max(0.15, min(speeds[j - 1], speeds[j]) * max(0.0, 1.0 - turn / (0.55 * math.pi)))
        self.corner = corner
        self.segment = 0
        self.limits = limits

    def progress(self, x, y):
        """Advance along the path to the robot's projection; return the arc length there."""
        while True:
            i = self.segment
            a, b = self.points[i], self.points[i + 1]
            length = self.lengths[i]
            along = ((x - a[0]) * (b[0] - a[0]) + (y - a[1]) * (b[1] - a[1])) / length if length > 1e-9 else length
            if along >= length and i + 2 < len(self.points):
                self.segment += 1
                continue
            return self.cumulative[i] + min(max(along, 0.0), length)

    def point_at(self, s):
        s = min(max(s, 0.0), self.total)
        i = self.segment
        while i + 1 < len(self.lengths) and self.cumulative[i + 1] < s:
            i += 1
        a, b = self.points[i], self.points[i + 1]
        f = (s - self.cumulative[i]) / self.lengths[i] if self.lengths[i] > 1e-9 else 1.0
        return a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])

    def speed_at(self, s):
        """Target speed at arc length s: segment limit, braking for the coming corners and the goal."""
        i = self.segment
        speed = self.speeds[i]
        for j in range(i + 1, min(i + 6, len(self.points))):
            ahead = max(0.0, self.cumulative[j] - s - (0.05 if j == len(self.points) - 1 else 0.0))
            speed = min(speed, math.sqrt(self.corner[j] ** 2 + 2.0 * _SOFT_DECEL * ahead))
        return speed


def _wrap(angle):
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _clamp(value, low, high):
    return low if value < low else high if value > high else value


def _limit(target, current, down, up, dt):
    """Move ``current`` towards ``target`` by at most ``up * dt`` upwards / ``down * dt`` downwards."""
    return _clamp(target, current - down * dt, current + up * dt)


def _limit_speed(target, current, limits, dt):
    """Acceleration-limited speed: braking (towards 0) at max_decel, speeding up at max_accel."""
    if current >= 0:
        return _limit(target, current, limits.max_decel, limits.max_accel, dt)
    return _limit(target, current, limits.max_accel, limits.max_decel, dt)


def _limit_yaw(target, current, limits, dt):
    return _clamp(_limit(target, current, limits.max_yaw_accel, limits.max_yaw_accel, dt),
                  -limits.max_yaw_rate, limits.max_yaw_rate)


# ---------------------------------------------------------------------------------------------------------
# Anomaly models, shared by the simulator and inject_anomalies

_NEEDS_MOTION = ('collision', 'sudden_acceleration', 'excessive_twisting', 'wheels_slipping')
_MOVES_BASE = ('planning_failure', 'collision', 'sudden_acceleration', 'excessive_twisting')


def _draw_plan(kind, rng, v0, scale=None):
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


def _command(plan, tau, v0, w0, v_nom, w_nom):
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
    if kind == 'collision':
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


def _offset(plan, tau):
    """Pose offset (dx, dy, dyaw) of a localization jump ``tau`` seconds in; None for other types."""
    if plan['type'] != 'localization_jump':
        return None
    current = (0.0, 0.0, 0.0)
    for at, offset in plan['offsets']:
        if tau >= at:
            current = offset
    return current


def _truth_entry(kind, start, end):
    return collections.OrderedDict((('type', kind), ('start', start), ('end', end)))


def _schedule_types(types, count, rng):
    """``count`` anomaly types: seeded shuffles of ``types``, one after another."""
    order = []
    while len(order) < count:
        cycle = list(types)
        rng.shuffle(cycle)
        order.extend(cycle)
    return order[:count]


# ---------------------------------------------------------------------------------------------------------
# Messages

def _time(seconds):
    """genpy.Time at whole nanoseconds, and the float it stands for (so stamps compare exactly)."""
    nanos = int(round(seconds * 1e9))
    stamp = genpy.Time(nanos // 1000000000, nanos % 1000000000)
    return stamp, stamp.to_sec()


def _yaw_of(q):
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


_POSE_COVARIANCE = (1e-3, 0.0, 0.0, 0.0, 0.0, 0.0,
                    0.0, 1e-3, 0.0, 0.0, 0.0, 0.0,
                    0.0, 0.0, 1e6, 0.0, 0.0, 0.0,
                    0.0, 0.0, 0.0, 1e6, 0.0, 0.0,
                    0.0, 0.0, 0.0, 0.0, 1e6, 0.0,
                    0.0, 0.0, 0.0, 0.0, 0.0, 0.03)
_TWIST_COVARIANCE = (1e-3, 0.0, 0.0, 0.0, 0.0, 0.0,
                     0.0, 1e-3, 0.0, 0.0, 0.0, 0.0,
                     0.0, 0.0, 1e6, 0.0, 0.0, 0.0,
                     0.0, 0.0, 0.0, 1e6, 0.0, 0.0,
                     0.0, 0.0, 0.0, 0.0, 1e6, 0.0,
                     0.0, 0.0, 0.0, 0.0, 0.0, 0.03)
_IMU_ORIENTATION_COVARIANCE = (2.5e-3, 0.0, 0.0, 0.0, 2.5e-3, 0.0, 0.0, 0.0, 1e-2)
_IMU_GYRO_COVARIANCE = (2.5e-5, 0.0, 0.0, 0.0, 2.5e-5, 0.0, 0.0, 0.0, 2.5e-5)
_IMU_ACCEL_COVARIANCE = (2.5e-3, 0.0, 0.0, 0.0, 2.5e-3, 0.0, 0.0, 0.0, 2.5e-3)
_POSE_COVARIANCE_BYTES = struct.pack('<36d', *_POSE_COVARIANCE)
_TWIST_COVARIANCE_BYTES = struct.pack('<36d', *_TWIST_COVARIANCE)
_IMU_ORIENTATION_COVARIANCE_BYTES = struct.pack('<9d', *_IMU_ORIENTATION_COVARIANCE)
_IMU_GYRO_COVARIANCE_BYTES = struct.pack('<9d', *_IMU_GYRO_COVARIANCE)
_IMU_ACCEL_COVARIANCE_BYTES = struct.pack('<9d', *_IMU_ACCEL_COVARIANCE)


def _twist(v, w):
    msg = Twist()
    msg.linear.x = v
    msg.angular.z = w
    return msg


def _odometry(stamp, seq, x, y, yaw, v, w):
    msg = Odometry()
    msg.header.seq = seq
    msg.header.stamp = stamp
    msg.header.frame_id = ODOM_FRAME
    msg.child_frame_id = BASE_FRAME
    msg.pose.pose.position.x = x
    msg.pose.pose.position.y = y
    msg.pose.pose.orientation.z = math.sin(yaw / 2.0)
    msg.pose.pose.orientation.w = math.cos(yaw / 2.0)
    msg.pose.covariance = _POSE_COVARIANCE
    msg.twist.twist.linear.x = v
    msg.twist.twist.angular.z = w
    msg.twist.covariance = _TWIST_COVARIANCE
    return msg


_ODOM, _IMU = 'odom', 'imu'
_HEADER = struct.Struct('<3I')
_ODOM_POSE = struct.Struct('<7d')
_ODOM_TWIST = struct.Struct('<6d')
_IMU_ORIENTATION = struct.Struct('<4d')
_VECTOR = struct.Struct('<3d')


def _string_bytes(text):
    data = text.encode('utf-8')
    return struct.pack('<I', len(data)) + data


def _doubles(values):
    return struct.pack('<%dd' % len(values), *values)


_ODOM_FRAMES = _string_bytes(ODOM_FRAME) + _string_bytes(BASE_FRAME)
_IMU_FRAME_BYTES = _string_bytes(IMU_FRAME)


def _message(item):
    """The ROS message of a simulator item."""
    if not isinstance(item, tuple):
        return item
    kind, stamp, seq, values = item
    if kind == _ODOM:
        return _odometry(stamp, seq, *values)
    qz, qw, gx, gy, gz, ax, ay, az = values
    msg = Imu()
    msg.header.seq = seq
    msg.header.stamp = stamp
    msg.header.frame_id = IMU_FRAME
    msg.orientation.z, msg.orientation.w = qz, qw
    msg.orientation_covariance = _IMU_ORIENTATION_COVARIANCE
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = gx, gy, gz
    msg.angular_velocity_covariance = _IMU_GYRO_COVARIANCE
    msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = ax, ay, az
    msg.linear_acceleration_covariance = _IMU_ACCEL_COVARIANCE
    return msg


def _serialized(item):
    """The serialized bytes of a simulator item: the same bytes genpy writes for ``_message(item)``."""
    if not isinstance(item, tuple):
        buffer = io.BytesIO()
        item.serialize(buffer)
        return buffer.getvalue()
    kind, stamp, seq, values = item
    header = _HEADER.pack(seq & 0xffffffff, stamp.secs, stamp.nsecs)
    if kind == _ODOM:
        x, y, yaw, v, w = values
        return b''.join((header, _ODOM_FRAMES,
                         _ODOM_POSE.pack(x, y, 0.0, 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)),
                         _POSE_COVARIANCE_BYTES, _ODOM_TWIST.pack(v, 0.0, 0.0, 0.0, 0.0, w),
                         _TWIST_COVARIANCE_BYTES))
    qz, qw, gx, gy, gz, ax, ay, az = values
    return b''.join((header, _IMU_FRAME_BYTES, _IMU_ORIENTATION.pack(0.0, 0.0, qz, qw),
                     _IMU_ORIENTATION_COVARIANCE_BYTES, _VECTOR.pack(gx, gy, gz), _IMU_GYRO_COVARIANCE_BYTES,
                     _VECTOR.pack(ax, ay, az), _IMU_ACCEL_COVARIANCE_BYTES))


def truth_event(event, entry):
    """The std_msgs/String (JSON) announcing that an anomaly started ('start', end null) or ended ('end')."""
    data = collections.OrderedDict((('event', event), ('type', entry['type']), ('start', entry['start']),
                                    ('end', entry['end'] if event == 'end' else None)))
    return String(data=json.dumps(data))


# ---------------------------------------------------------------------------------------------------------
# The simulator

class Simulator(object):
    """Simulated BWIBot: ``step()`` advances one tick (1/rate s) and returns its messages as
    ``[(topic, stamp, msg)]`` in time order; ``messages()`` iterates over the whole run. ``truth`` lists
    the anomalies that have ended so far ({'type', 'start', 'end'}); ``done`` is True at the end of a
    finite run."""

    def __init__(self, config=None, floor=None, limits=BWIBOT_LIMITS):
        self.config = config = (config or SimConfig()).validate()
        self.floor = floor or FloorPlan.bwi_floor()
        self.limits = limits
        self.dt = 1.0 / config.rate
        self.total_ticks = int(round(config.minutes * 60.0 * config.rate)) if config.minutes > 0 else None
        self.tick = 0
        self.truth = []
        self.skipped = []        # anomaly types that could not be placed before the end of the run
        seed = config.seed
        self._rng_route = random.Random('%d:route' % seed)
        self._rng_noise = random.Random('%d:noise' % seed)
        self._rng_imu = random.Random('%d:imu' % seed)
        self._rng_jitter = random.Random('%d:jitter' % seed)
        self._rng_anomaly = random.Random('%d:anomaly' % seed)
        noise = config.noise
        # sensor errors: wheel-scale errors, white noise, a slowly wandering yaw-rate bias (drift)
        self._scale_v = _clamp(self._rng_noise.gauss(0.0, 0.01 * noise), -0.02 * noise, 0.02 * noise)
        self._scale_w = _clamp(self._rng_noise.gauss(0.0, 0.02 * noise), -0.03 * noise, 0.03 * noise)
        self._bias_w = self._rng_noise.gauss(0.0, 3e-4 * noise)
        self._sigma_v = 0.004 * noise
        self._sigma_w = 0.008 * noise
        self._bias_walk = 3e-5 * noise * math.sqrt(self.dt)
        self._imu_gyro_bias = self._rng_imu.gauss(0.0, 2e-3 * noise)
        self._imu_yaw_drift = 0.0
        # the true base
        sx, sy = self.floor.nodes[self.floor.start]
        self.x, self.y, self.yaw = sx, sy, 0.0
        self.distance = 0.0                   # metres the true base has driven (its path length)
        self.v = self.w = 0.0                 # body twist
        self._cmd_v = self._cmd_w = 0.0        # what the controller commands (acceleration-limited)
        self._node = self.floor.start
        self._path = None
        self._mode = 'dwell'
        self._dwell_until = 2.0
        self._goal = 0                         # number of the current move_base goal (0: none yet)
        self._goal_status = None
        self._command_every = max(1, int(round(config.rate / COMMAND_RATE)))
        self._status_every = max(1, int(round(config.rate / STATUS_RATE)))
        # the odometry estimate (integrated wheel speeds, starting at 0)
        self.odom_x = self.odom_y = self.odom_yaw = 0.0
        # anomalies
        slot = config.slot_seconds()
        order = _schedule_types(config.anomaly_types, config.anomalies, self._rng_anomaly)
        spare = max(0.0, slot - config.gap - MAX_ANOMALY_SECONDS)
        armed = [config.warmup + index * slot + self._rng_anomaly.uniform(0.0, 0.5 * spare)
                 for index in range(len(order))]
        # an armed anomaly waits for the base to be driving (fast enough) until its deadline, so that the
        # next one still gets its gap
        self._pending = collections.deque(
            (at, max(at, config.warmup + (index + 1) * slot - config.gap - MAX_ANOMALY_SECONDS), kind)
            for index, (at, kind) in enumerate(zip(armed, order)))
        self._active = None
        self._last_end = -config.gap
        self._next_stamp = self._stamp_for(0)
        self._sensors = (sim_sensors.Sensors(self.floor, seed, config.rate, config.camera, config.scan)
                         if config.camera or config.scan else None)

    # -- time -------------------------------------------------------------------------------------------
    def _stamp_for(self, tick):
        jitter = self.config.jitter
        offset = _clamp(self._rng_jitter.gauss(0.0, jitter), -4 * jitter, 4 * jitter) if jitter else 0.0
        return _time(self.config.start_time + tick * self.dt + offset)

    @property
    def done(self):
        return self.total_ticks is not None and self.tick >= self.total_ticks

    @property
    def time(self):
        """Simulated seconds since the start."""
        return self.tick * self.dt

    def messages(self):
        """Yield (topic, stamp, msg) in time order until the end of the run (forever when minutes=0)."""
        while not self.done:
            for item in self.step():
                yield item

    # -- one tick ---------------------------------------------------------------------------------------
    def step(self):
        """Advance one tick; return [(topic, stamp, msg)] sorted by stamp."""
        return [(topic, stamp, _message(item)) for topic, stamp, item in self._advance()]

    def _advance(self):
        """Advance one tick; return [(topic, stamp, item)] sorted by stamp, where item is a message
        (std_msgs/String) or a tuple of values (_ODOM or _IMU, genpy.Time stamp, seq, values)."""
        if self.done:
            return []
        dt, limits, config = self.dt, self.limits, self.config
        k = self.tick
        t = k * dt
        stamp, stamp_s = self._next_stamp
        self._next_stamp = self._stamp_for(k + 1)
        out = []
        active = self._active
        if active is not None and k >= active['end_tick']:
            entry = _truth_entry(active['type'], active['start'], stamp_s)
            self.truth.append(entry)
            out.append((TRUTH_TOPIC, stamp_s, truth_event('end', entry)))
            if active['type'] == 'planning_failure' and config.commands:
                # move_base gives up on the goal (its recoveries failed), the robot goes on under a new goal
                out.append((STATUS_TOPIC, stamp_s, self._status(stamp, ABORTED)))
                self._goal += 1
            self._cmd_v, self._cmd_w = self.v, self.w       # the controller takes over from where the base is
            self._last_end = t
            self._active = active = None

        v_cmd, w_cmd = self._control(t)

        if active is None:
            active = self._maybe_start(k, t, stamp_s, out)
        if active is not None:
            plan = active['plan']
            tau = (k - active['start_tick']) * dt
            v_b, w_b, limited = _command(plan, tau, active['v0'], active['w0'], v_cmd, w_cmd)
            if limited:
                v_b = _limit_speed(v_b, self.v, limits, dt)
                w_b = _limit_yaw(w_b, self.w, limits, dt)
                if plan['type'] == 'planning_failure':
                    self._cmd_v, self._cmd_w = v_b, w_b      # the failing planner is in charge
            wheel_v, wheel_w = v_b, w_b
            if plan['type'] == 'wheels_slipping':
                # stuck: the body stops within ~0.3 s and gets going again in the last 0.5 s; the wheels
                # keep turning at the commanded speed
                remaining = plan['duration'] - tau
                grip = _clamp(max(1.0 - tau / 0.3, 1.0 - (remaining - dt) / 0.5), 0.0, 1.0)
                v_b, w_b = wheel_v * grip, wheel_w * grip
        else:
            v_b, w_b = v_cmd, w_cmd
            wheel_v, wheel_w = v_b, w_b
            plan = None

        accel = (v_b - self.v) / dt
        # the true base
        heading = self.yaw + 0.5 * w_b * dt
        self.x += v_b * dt * math.cos(heading)
        self.y += v_b * dt * math.sin(heading)
        self.yaw += w_b * dt
        self.distance += abs(v_b) * dt
        self.v, self.w = v_b, w_b

        # wheel odometry
        noise = self._rng_noise
        self._bias_w += noise.gauss(0.0, self._bias_walk) - 0.001 * dt * self._bias_w
        meas_v = wheel_v * (1.0 + self._scale_v) + noise.gauss(0.0, self._sigma_v)
        meas_w = wheel_w * (1.0 + self._scale_w) + self._bias_w + noise.gauss(0.0, self._sigma_w)
        if plan is None or plan['type'] != 'wheels_slipping':
            heading = self.odom_yaw + 0.5 * meas_w * dt
            self.odom_x += meas_v * dt * math.cos(heading)
            self.odom_y += meas_v * dt * math.sin(heading)
            self.odom_yaw += meas_w * dt
        px, py, pyaw = self.odom_x, self.odom_y, self.odom_yaw
        if plan is not None and plan['type'] == 'localization_jump':
            dx, dy, dyaw = _offset(plan, (k - active['start_tick']) * dt)
            px, py, pyaw = px + dx, py + dy, pyaw + dyaw
        out.append((ODOM_TOPIC, stamp_s, (_ODOM, stamp, k, (px, py, pyaw, meas_v, meas_w))))

        if config.imu:
            out.append(self._imu(k, t, accel))
        if config.commands:
            if k % self._command_every == 0:
                out.append((CMD_TOPIC, stamp_s, _twist(self._cmd_v, self._cmd_w)))
            if k % self._status_every == 0 and self._goal:
                out.append((STATUS_TOPIC, stamp_s, self._status(stamp, self._goal_status)))
        if self._sensors is not None:
            collision = active['start_tick'] if active is not None and active['type'] == 'collision' else None
            out.extend(self._sensors.frames(k, stamp, stamp_s, (self.x, self.y, self.yaw), collision))
        self.tick += 1
        if len(out) > 1:
            out.sort(key=lambda item: item[1])
        return out

    def _status(self, stamp, status):
        """The move_base-like status of the current goal."""
        from actionlib_msgs.msg import GoalID, GoalStatus, GoalStatusArray
        array = GoalStatusArray()
        array.header.stamp = stamp
        array.status_list = [GoalStatus(goal_id=GoalID(id='goal_%d' % self._goal), status=status)]
        return array

    def _imu(self, k, t, accel):
        rng, noise = self._rng_imu, self.config.noise
        jitter = self.config.jitter
        offset = _clamp(rng.gauss(0.0, jitter), -4 * jitter, 4 * jitter) if jitter else 0.0
        stamp, stamp_s = _time(self.config.start_time + t + offset)
        self._imu_yaw_drift += rng.gauss(0.0, 2e-4 * noise * math.sqrt(self.dt))
        yaw = self.yaw + self._imu_yaw_drift
        gyro_x = rng.gauss(0.0, 0.005 * noise)
        gyro_y = rng.gauss(0.0, 0.005 * noise)
        gyro_z = self.w + self._imu_gyro_bias + rng.gauss(0.0, 0.005 * noise)
        accel_x = accel + rng.gauss(0.0, 0.05 * noise)
        accel_y = self.v * self.w + rng.gauss(0.0, 0.05 * noise)
        accel_z = GRAVITY + rng.gauss(0.0, 0.05 * noise)
        return IMU_TOPIC, stamp_s, (_IMU, stamp, k, (math.sin(yaw / 2.0), math.cos(yaw / 2.0), gyro_x, gyro_y,
                                                     gyro_z, accel_x, accel_y, accel_z))

    def _maybe_start(self, k, t, stamp_s, out):
        """Start the next armed anomaly when its time has come and the base is in a state to show it."""
        if not self._pending:
            return None
        armed, deadline, kind = self._pending[0]
        if t < armed or t < self._last_end + self.config.gap:
            return None
        driving = self._mode == 'drive'
        ready = {'planning_failure': driving, 'localization_jump': True,
                 'collision': driving and self._cmd_v >= 0.6}.get(kind, driving and self._cmd_v >= 0.4)
        if not ready and t < deadline:
            return None
        plan = _draw_plan(kind, self._rng_anomaly, self.v)
        ticks = max(1, int(round(plan['duration'] * self.config.rate)))
        if self.total_ticks is not None and k + ticks + int(self.config.rate) >= self.total_ticks:
            self._pending.popleft()
            self.skipped.append(kind)
            return None
        self._pending.popleft()
        self._active = {'type': kind, 'plan': plan, 'start_tick': k, 'end_tick': k + ticks,
                        'start': stamp_s, 'v0': self.v, 'w0': self.w}
        out.append((TRUTH_TOPIC, stamp_s, truth_event('start', _truth_entry(kind, stamp_s, None))))
        return self._active

    # -- the navigation stack ---------------------------------------------------------------------------
    def _new_route(self):
        choices = [name for name in self.floor.destinations if name != self._node]
        goal = self._rng_route.choice(choices)
        names, kinds = self.floor.route(self._node, goal)
        points = [(self.x, self.y)] + [self.floor.nodes[name] for name in names[1:]]
        speeds = [FloorPlan.SPEEDS[kind] for kind in kinds]
        self._path = _Path(points, speeds, self.limits)
        self._node = goal
        self._mode = 'turn'
        self._goal += 1
        self._goal_status = ACTIVE

    def _control(self, t):
        """The planner and pure-pursuit controller: acceleration-limited (v, w) command for this tick."""
        limits, dt = self.limits, self.dt
        v_target = w_target = curvature = 0.0
        if self._mode == 'dwell':
            if t >= self._dwell_until and abs(self._cmd_v) < 1e-3:
                self._new_route()
        if self._mode != 'dwell':
            path = self._path
            s = path.progress(self.x, self.y)
            remaining = path.total - s
            gx, gy = path.points[-1]
            if remaining < 0.1 or math.hypot(gx - self.x, gy - self.y) < 0.1:
                self._mode = 'dwell'
                self._goal_status = SUCCEEDED
                self._dwell_until = t + self._rng_route.uniform(2.0, 6.0)
            else:
                lookahead = 0.5 + 0.6 * max(self._cmd_v, 0.0)
                lx, ly = path.point_at(s + lookahead)
                alpha = _wrap(math.atan2(ly - self.y, lx - self.x) - self.yaw)
                if self._mode == 'drive' and abs(alpha) > 1.0:
                    self._mode = 'turn'
                if self._mode == 'turn':
                    if abs(alpha) < 0.15:
                        self._mode = 'drive'
                    else:
                        w_target = math.copysign(min(limits.max_yaw_rate, max(0.3, 1.5 * abs(alpha))), alpha)
                if self._mode == 'drive':
                    distance = max(math.hypot(lx - self.x, ly - self.y), 1e-3)
                    curvature = 2.0 * math.sin(alpha) / distance
                    v_target = min(path.speed_at(s), limits.max_speed)
                    v_target = max(v_target, 0.08)
                    if abs(curvature) > 1e-6:
                        v_target = min(v_target, limits.max_yaw_rate / abs(curvature))
        v = _limit_speed(v_target, self._cmd_v, limits, dt)
        if self._mode == 'drive':
            w_target = v * curvature
        w = _limit_yaw(w_target, self._cmd_w, limits, dt)
        self._cmd_v, self._cmd_w = v, w
        return v, w


# ---------------------------------------------------------------------------------------------------------
# Files

def truth_path(bag_path):
    """The sidecar ground-truth file of a bag: ``<bag>.truth.json``."""
    return bag_path + '.truth.json'


def _atomic_write(path, data):
    from cc_log.core.safe_files import AtomicFile
    with AtomicFile(path, overwrite=True) as stream:
        stream.write(data)


def write_truth(path, truth, topic=ODOM_TOPIC, config=None, source='cc_log.sim'):
    """Write a ground-truth sidecar: {"format", "source", "topic", "config", "anomalies": [...]}."""
    document = collections.OrderedDict((
        ('format', TRUTH_FORMAT), ('source', source), ('topic', topic),
        ('config', config.to_dict() if hasattr(config, 'to_dict') else config),
        ('anomalies', [_truth_entry(e['type'], e['start'], e['end']) for e in truth])))
    _atomic_write(path, (json.dumps(document, indent=1) + '\n').encode('utf-8'))
    return path


def load_truth(path):
    """The anomalies of a ground-truth sidecar (or of a bare JSON list): [{'type', 'start', 'end'}]."""
    with open(path) as stream:
        document = json.load(stream)
    entries = document['anomalies'] if isinstance(document, dict) else document
    return [_truth_entry(e['type'], float(e['start']), float(e['end'])) for e in entries]


def simulate_to_bag(path, config=None, truth_file=None, compression='lz4', progress=None):
    """Simulate a whole run straight into a bag (no roscore) and its ground truth next to it.

    Writes ``path`` (odometry; IMU, commands, camera and scan when configured; /sim/anomaly events;
    ``compression`` 'lz4', 'bz2' or 'none') and the sidecar ``truth_file`` (default ``<path>.truth.json``);
    ``progress(done, total)`` is called now and then with simulated ticks. Returns the truth list.
    """
    from cc_log.core import raw_message
    from cc_log.storage.bag import bag_writer
    from cc_log.core.safe_files import AtomicFile
    config = (config or SimConfig()).validate()
    if config.minutes <= 0:
        raise ValueError('minutes: a bag needs a finite run (minutes > 0)')
    if compression not in bag_writer.COMPRESSIONS:
        raise ValueError('compression: expected lz4, bz2 or none, got %r' % (compression,))
    simulator = Simulator(config)
    kinds = {ODOM_TOPIC: Odometry, IMU_TOPIC: Imu, TRUTH_TOPIC: String, CMD_TOPIC: Twist}
    headers = {}

    def messages():
        total = simulator.total_ticks
        every = max(1, int(config.rate * 10))
        while not simulator.done:
            for topic, stamp, item in simulator._advance():
                if topic not in headers:  # filled before write_bag reads it, at the topic's first message
                    headers[topic] = raw_message.class_header(topic, kinds.get(topic) or type(item))
                when = item[1] if isinstance(item, tuple) else _time(stamp)[0]
                yield topic, when.secs, when.nsecs, _serialized(item)
            if progress is not None and simulator.tick % every == 0:
                progress(simulator.tick, total)
        if progress is not None:
            progress(total, total)

    with AtomicFile(path, overwrite=True) as stream:
        bag_writer.write_bag(stream, messages(), headers, chunk_threshold=1024 * 1024, compression=compression)
    write_truth(truth_file or truth_path(path), simulator.truth, ODOM_TOPIC, config)
    return simulator.truth


# ---------------------------------------------------------------------------------------------------------
# Injecting the anomaly models into recorded odometry

def _moving_average(values, half):
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
    pose blends smoothly back onto the recorded track (at most ~0.8 m/s faster or slower than recorded),
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
    yaw = [_yaw_of(r.msg.pose.pose.orientation) for r in odom]
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
        if kind in _NEEDS_MOTION:
            moving = [i for i in range(max(lo, 1), max(hi, lo + 1)) if i < n and v_s[i] >= _MOVING]
            i0 = moving[0] if moving else max(range(lo, max(hi, lo + 1)), key=lambda i: v_s[min(i, n - 1)])
        i0 = max(i0, 1)
        plan = _draw_plan(kind, rng, v_s[i0], scale)
        modified, end = _inject_one(plan, i0, t, x, y, yaw, v, w, v_s, w_s, limits)
        if end >= n:
            raise ValueError('types: %s at %.1f s does not end before the odometry does'
                             % (kind, t[i0] - t[0]))
        new.update(modified)
        truth.append(_truth_entry(kind, t[i0], t[end]))
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
    return Limits(*(max(value, floor * limit) for value, limit in zip(found, BWIBOT_LIMITS)))


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
            dx, dy, dyaw = _offset(plan, tau)
            out[i] = (x[i] + dx, y[i] + dy, yaw[i] + dyaw, v[i], w[i])
        elif kind == 'wheels_slipping':
            out[i] = (ax, ay, ayaw, v[i], w[i])
        else:
            cv, cw, limited = _command(plan, tau, v0, w0, v_s[i], w_s[i])
            if limited:
                cv = _limit_speed(cv, sv, limits, dt)
                cw = _limit_yaw(cw, sw, limits, dt)
            sv, sw = cv, cw
            ov, ow = _with_noise(cv, cw, v[i], w[i], v_s[i], w_s[i])
            heading = ayaw + 0.5 * ow * dt
            ax += ov * dt * math.cos(heading)
            ay += ov * dt * math.sin(heading)
            ayaw += ow * dt
            out[i] = (ax, ay, ayaw, ov, ow)
        i += 1
    if kind == 'localization_jump':
        return out, i
    if kind in _MOVES_BASE:
        # back to the recorded twist within the base's limits
        while i < n and (abs(sv - v_s[i]) > 0.02 or abs(sw - w_s[i]) > 0.05) and t[i] - t[i0] < plan['duration'] + 10.0:
            dt = max(t[i] - t[i - 1], 0.0)
            sv = _limit_speed(v_s[i], sv, limits, dt)
            sw = _limit(w_s[i], sw, limits.max_yaw_accel, limits.max_yaw_accel, dt)
            ov, ow = _with_noise(sv, sw, v[i], w[i], v_s[i], w_s[i])
            heading = ayaw + 0.5 * ow * dt
            ax += ov * dt * math.cos(heading)
            ay += ov * dt * math.sin(heading)
            ayaw += ow * dt
            out[i] = (ax, ay, ayaw, ov, ow)
            i += 1
    if i >= n:
        return out, n
    # blend the pose back onto the recorded track, starting from index i (twist: recorded + the blend's)
    last = i - 1
    if last not in out:
        return out, i
    dx, dy = out[last][0] - x[last], out[last][1] - y[last]
    dyaw = _wrap(out[last][2] - yaw[last])
    # smoothstep blend: peak extra speed 1.5 * distance / span <= _CATCH_UP, peak extra yaw rate <= 0.6 rad/s
    span = max(2.0, 1.5 * math.hypot(dx, dy) / _CATCH_UP, 2.5 * abs(dyaw))
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
