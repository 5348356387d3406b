"""The simulated BWIBot: ``Simulator``, the robot driving its floor, with its sensors and its anomalies.

The robot
    A BWIBot v2 base (Segway RMP 110, differential drive) touring a fixed office floor (``floor.FloorPlan``).
    The robot picks a destination, plans the shortest route on the floor graph, turns in place towards it,
    follows it with pure pursuit under indoor speed and acceleration limits (``kinematics.BWIBOT_LIMITS``),
    slows for corners and doors, stops and waits a few seconds at the destination, and goes on. At the
    armed times it shows an anomaly (``anomalies``) instead of driving nominally.

What it publishes (``messages``)
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
    one message when an anomaly starts and one when it ends; ``truth``). Optionally (``camera``, ``scan``) a
    320x240 rgb8 ``sensor_msgs/Image`` on ``/camera/image_raw`` at 15 Hz and a ``sensor_msgs/LaserScan`` on
    ``/scan`` at 10 Hz, ray-cast against the floor plan's walls from the true pose (``sensors``).
"""
import collections
import math
import random

from cc_log.sim import anomalies, sensors
from cc_log.sim.anomalies import MAX_ANOMALY_SECONDS
from cc_log.sim.config import SimConfig
from cc_log.sim.floor import FloorPlan, Path
from cc_log.sim.kinematics import BWIBOT_LIMITS, clamp, integrate, limit_speed, limit_yaw, wrap
from cc_log.sim.messages import (ABORTED, ACTIVE, CMD_TOPIC, IMU_ITEM, IMU_TOPIC, ODOM_ITEM, ODOM_TOPIC,
                                 STATUS_TOPIC, SUCCEEDED, TRUTH_TOPIC, goal_status, message, ros_time, twist)
from cc_log.sim.truth import truth_entry, truth_event

COMMAND_RATE = 20.0  # Hz of /cmd_vel (at most the odometry rate)
STATUS_RATE = 2.0    # Hz of /move_base/status
GRAVITY = 9.80665


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
        self._scale_v = clamp(self._rng_noise.gauss(0.0, 0.01 * noise), -0.02 * noise, 0.02 * noise)
        self._scale_w = clamp(self._rng_noise.gauss(0.0, 0.02 * noise), -0.03 * noise, 0.03 * noise)
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
        order = anomalies.schedule_types(config.anomaly_types, config.anomalies, self._rng_anomaly)
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
        self._sensors = (sensors.Sensors(self.floor, seed, config.rate, config.camera, config.scan)
                         if config.camera or config.scan else None)

    # -- time -------------------------------------------------------------------------------------------
    def _stamp_for(self, tick):
        jitter = self.config.jitter
        offset = clamp(self._rng_jitter.gauss(0.0, jitter), -4 * jitter, 4 * jitter) if jitter else 0.0
        return ros_time(self.config.start_time + tick * self.dt + offset)

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
        return [(topic, stamp, message(item)) for topic, stamp, item in self.advance()]

    def advance(self):
        """Advance one tick; return [(topic, stamp, item)] sorted by stamp, where item is a ROS message or,
        for odometry and IMU, a tuple of values (ODOM_ITEM or IMU_ITEM, genpy.Time stamp, seq, values) that
        ``messages.message`` builds and ``messages.serialized`` writes (cheaper than ``step``)."""
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
            entry = truth_entry(active['type'], active['start'], stamp_s)
            self.truth.append(entry)
            out.append((TRUTH_TOPIC, stamp_s, truth_event('end', entry)))
            if active['type'] == 'planning_failure' and config.commands:
                # move_base gives up on the goal (its recoveries failed), the robot goes on under a new goal
                out.append((STATUS_TOPIC, stamp_s, goal_status(stamp, self._goal, ABORTED)))
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
            v_b, w_b, limited = anomalies.command(plan, tau, active['v0'], active['w0'], v_cmd, w_cmd)
            if limited:
                v_b = limit_speed(v_b, self.v, limits, dt)
                w_b = limit_yaw(w_b, self.w, limits, dt)
                if plan['type'] == 'planning_failure':
                    self._cmd_v, self._cmd_w = v_b, w_b      # the failing planner is in charge
            wheel_v, wheel_w = v_b, w_b
            if plan['type'] == 'wheels_slipping':
                # stuck: the body stops within ~0.3 s and gets going again in the last 0.5 s; the wheels
                # keep turning at the commanded speed
                remaining = plan['duration'] - tau
                grip = clamp(max(1.0 - tau / 0.3, 1.0 - (remaining - dt) / 0.5), 0.0, 1.0)
                v_b, w_b = wheel_v * grip, wheel_w * grip
        else:
            v_b, w_b = v_cmd, w_cmd
            wheel_v, wheel_w = v_b, w_b
            plan = None

        accel = (v_b - self.v) / dt
        # the true base
        self.x, self.y, self.yaw = integrate(self.x, self.y, self.yaw, v_b, w_b, dt)
        self.distance += abs(v_b) * dt
        self.v, self.w = v_b, w_b

        # wheel odometry
        noise = self._rng_noise
        self._bias_w += noise.gauss(0.0, self._bias_walk) - 0.001 * dt * self._bias_w
        meas_v = wheel_v * (1.0 + self._scale_v) + noise.gauss(0.0, self._sigma_v)
        meas_w = wheel_w * (1.0 + self._scale_w) + self._bias_w + noise.gauss(0.0, self._sigma_w)
        if plan is None or plan['type'] != 'wheels_slipping':
            self.odom_x, self.odom_y, self.odom_yaw = integrate(self.odom_x, self.odom_y, self.odom_yaw,
                                                                meas_v, meas_w, dt)
        px, py, pyaw = self.odom_x, self.odom_y, self.odom_yaw
        if plan is not None and plan['type'] == 'localization_jump':
            dx, dy, dyaw = anomalies.jump_offset(plan, (k - active['start_tick']) * dt)
            px, py, pyaw = px + dx, py + dy, pyaw + dyaw
        out.append((ODOM_TOPIC, stamp_s, (ODOM_ITEM, stamp, k, (px, py, pyaw, meas_v, meas_w))))

        if config.imu:
            shock = anomalies.impact(plan, (k - active['start_tick']) * dt) if plan is not None else (0.0, 0.0)
            out.append(self._imu(k, t, accel, shock))
        if config.commands:
            if k % self._command_every == 0:
                out.append((CMD_TOPIC, stamp_s, twist(self._cmd_v, self._cmd_w)))
            if k % self._status_every == 0 and self._goal:
                out.append((STATUS_TOPIC, stamp_s, goal_status(stamp, self._goal, self._goal_status)))
        if self._sensors is not None:
            hit = active is not None and active['type'] in ('collision', 'soft_collision')
            collision = active['start_tick'] if hit else None
            out.extend(self._sensors.frames(k, stamp, stamp_s, (self.x, self.y, self.yaw), collision))
        self.tick += 1
        if len(out) > 1:
            out.sort(key=lambda item: item[1])
        return out

    def _imu(self, k, t, accel, shock=(0.0, 0.0)):
        """The IMU item at tick ``k``: ``accel`` the base's forward acceleration, ``shock`` (x, z) an impact's."""
        rng, noise = self._rng_imu, self.config.noise
        jitter = self.config.jitter
        offset = clamp(rng.gauss(0.0, jitter), -4 * jitter, 4 * jitter) if jitter else 0.0
        stamp, stamp_s = ros_time(self.config.start_time + t + offset)
        self._imu_yaw_drift += rng.gauss(0.0, 2e-4 * noise * math.sqrt(self.dt))
        yaw = self.yaw + self._imu_yaw_drift
        gyro_x = rng.gauss(0.0, 0.005 * noise)
        gyro_y = rng.gauss(0.0, 0.005 * noise)
        gyro_z = self.w + self._imu_gyro_bias + rng.gauss(0.0, 0.005 * noise)
        accel_x = accel + shock[0] + rng.gauss(0.0, 0.05 * noise)
        accel_y = self.v * self.w + rng.gauss(0.0, 0.05 * noise)
        accel_z = GRAVITY + shock[1] + rng.gauss(0.0, 0.05 * noise)
        return IMU_TOPIC, stamp_s, (IMU_ITEM, stamp, k, (math.sin(yaw / 2.0), math.cos(yaw / 2.0), gyro_x, gyro_y,
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
                 'collision': driving and self._cmd_v >= 0.6, 'soft_collision': driving and self._cmd_v >= 0.6,
                 }.get(kind, driving and self._cmd_v >= 0.4)
        if not ready and t < deadline:
            return None
        plan = anomalies.draw_plan(kind, self._rng_anomaly, self.v)
        ticks = max(1, int(round(plan['duration'] * self.config.rate)))
        if self.total_ticks is not None and k + ticks + int(self.config.rate) >= self.total_ticks:
            self._pending.popleft()
            self.skipped.append(kind)
            return None
        self._pending.popleft()
        self._active = {'type': kind, 'plan': plan, 'start_tick': k, 'end_tick': k + ticks,
                        'start': stamp_s, 'v0': self.v, 'w0': self.w}
        out.append((TRUTH_TOPIC, stamp_s, truth_event('start', truth_entry(kind, stamp_s, None))))
        return self._active

    # -- the navigation stack ---------------------------------------------------------------------------
    def _new_route(self):
        choices = [name for name in self.floor.destinations if name != self._node]
        goal = self._rng_route.choice(choices)
        names, kinds = self.floor.route(self._node, goal)
        points = [(self.x, self.y)] + [self.floor.nodes[name] for name in names[1:]]
        speeds = [FloorPlan.SPEEDS[kind] for kind in kinds]
        self._path = Path(points, speeds, self.limits)
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
                alpha = wrap(math.atan2(ly - self.y, lx - self.x) - self.yaw)
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
        v = limit_speed(v_target, self._cmd_v, limits, dt)
        if self._mode == 'drive':
            w_target = v * curvature
        w = limit_yaw(w_target, self._cmd_w, limits, dt)
        self._cmd_v, self._cmd_w = v, w
        return v, w


# ---------------------------------------------------------------------------------------------------------
