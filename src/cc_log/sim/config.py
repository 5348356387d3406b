"""What to simulate: ``SimConfig``, checked and normalised by ``validate``."""
import collections
import math

from cc_log.sim.anomalies import ANOMALY_TYPES, MAX_ANOMALY_SECONDS, SIM_ONLY_TYPES, parse_anomaly_types

DEFAULT_START_TIME = 1600000000.0  # stamps of a simulated run start here (2020-09-13), unless told


class SimConfig(object):
    """What to simulate.

    rate           odometry (and IMU) messages per second
    seed           integer seed: the same seed gives identical output
    minutes        simulated minutes; 0 = run until stopped (``Simulator.messages`` never ends)
    anomalies      how many anomalies to inject, spread over the run (types taken in a seeded shuffled
                   order, cycling through ``anomaly_types``)
    anomaly_types  which types to use (tuple, or comma-separated string): of ANOMALY_TYPES, or SIM_ONLY_TYPES
                   named (``soft_collision``, best with ``imu`` and ``commands``)
    imu            also publish sensor_msgs/Imu on /imu/data
    commands       also publish /cmd_vel and /move_base/status (see ``cc_log.sim.world``)
    camera, scan   also publish the camera's images and the laser scans (``sensors``; off: cheap tests)
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
        self.anomaly_types = parse_anomaly_types(self.anomaly_types, extra=SIM_ONLY_TYPES)
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
