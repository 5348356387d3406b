"""The physics envelope's features on synthetic odometry (pure numpy, no roscore)."""
import numpy as np
import pytest

from cc_log.features.envelope import (
    ENVELOPE_COLUMNS, ENVELOPE_FLOORS, ENVELOPE_UNITS, HISTORY, envelope_rows, envelope_windows)

RATE = 50.0
COL = {name: i for i, name in enumerate(ENVELOPE_COLUMNS)}


def drive(v, w, t0=1000.0, rate=RATE, stamps=None):
    """Samples of a unicycle following speeds ``v`` and yaw rates ``w`` (arrays), integrated by the trapezoid rule."""
    v, w = np.asarray(v, float), np.asarray(w, float)
    t = t0 + np.arange(len(v)) / rate if stamps is None else np.asarray(stamps, float)
    dt = np.diff(t, prepend=t[0])
    mean_v = 0.5 * (v + np.concatenate((v[:1], v[:-1])))    # the trapezoid rule, as the features predict
    mean_w = 0.5 * (w + np.concatenate((w[:1], w[:-1])))
    yaw = np.cumsum(mean_w * dt)
    heading = yaw - 0.5 * mean_w * dt
    x = np.cumsum(mean_v * dt * np.cos(heading))
    y = np.cumsum(mean_v * dt * np.sin(heading))
    return t, x, y, yaw, v, w


def column_max(samples, name):
    ends, matrix = envelope_windows(*samples)
    assert len(ends) == matrix.shape[0] > 0
    return float(matrix[:, COL[name]].max())


def test_the_interface_names_19_non_negative_columns_with_units_and_floors():
    assert len(ENVELOPE_COLUMNS) == len(set(ENVELOPE_COLUMNS)) == 19
    assert set(ENVELOPE_UNITS) == set(ENVELOPE_FLOORS) == set(ENVELOPE_COLUMNS)
    assert all(ENVELOPE_FLOORS[name] > 0 for name in ENVELOPE_COLUMNS)
    rng = np.random.default_rng(1)
    samples = drive(rng.uniform(-1, 2, 500), rng.uniform(-1, 1, 500))
    ends, matrix = envelope_windows(*samples)
    assert matrix.shape == (len(ends), 19) and np.all(matrix >= 0) and np.all(np.isfinite(matrix))
    # windows end on the grid of multiples of the stride, the first one a full window after the first sample
    assert np.allclose(ends / 0.25, np.round(ends / 0.25)) and ends[0] >= samples[0][0] + 1.0
    assert np.allclose(np.diff(ends), 0.25) and ends[-1] <= samples[0][-1]


def test_a_constant_straight_run_has_near_zero_change_features():
    samples = drive(np.full(500, 1.5), np.zeros(500))
    ends, matrix = envelope_windows(*samples)
    assert matrix[:, COL['max_speed']] == pytest.approx(1.5)
    for name in ('max_yaw_rate', 'max_accel', 'max_yaw_accel', 'max_jerk', 'speed_variation', 'yaw_rate_variation',
                 'yaw_rate_flips', 'max_pose_gap', 'sum_pose_gap', 'max_heading_gap', 'sum_heading_gap',
                 'still_fraction', 'still_yaw_rate', 'max_span_accel', 'max_decel', 'max_speedup',
                 'max_speed_drop', 'max_speed_rise'):
        assert matrix[:, COL[name]].max() == pytest.approx(0.0, abs=1e-9), name


def test_a_step_in_speed_raises_the_acceleration_and_the_speed_drop():
    v = np.full(500, 2.0)
    v[250:] = 0.5           # a 1.5 m/s drop between two samples
    samples = drive(v, np.zeros(500))
    # the derivative spans the newest sample at least 0.05 s back: 3 steps of 0.02 s at 50 Hz
    assert column_max(samples, 'max_accel') == pytest.approx(1.5 / 0.06)
    assert column_max(samples, 'max_decel') == pytest.approx(1.5 / 0.06)
    assert column_max(samples, 'max_speedup') == pytest.approx(0.0)
    assert column_max(samples, 'max_speed_drop') == pytest.approx(1.5)
    assert column_max(samples, 'max_speed_rise') == pytest.approx(0.0)
    assert column_max(samples, 'speed_variation') == pytest.approx(1.5)
    assert column_max(samples, 'max_span_accel') == pytest.approx(1.5 / 0.2)
    assert column_max(samples, 'max_jerk') > 100.0
    assert column_max(samples, 'max_pose_gap') < 1e-9    # pose and twist still agree


def test_a_pose_jump_raises_the_pose_and_heading_gaps():
    t, x, y, yaw, v, w = drive(np.full(500, 1.0), np.zeros(500))
    x, yaw = x.copy(), yaw.copy()
    x[300:] += 1.2          # the pose jumps 1.2 m ahead while the wheels report 0.02 m
    yaw[300:] += 0.5
    ends, matrix = envelope_windows(t, x, y, yaw, v, w)
    assert matrix[:, COL['max_pose_gap']].max() == pytest.approx(np.hypot(0.02 * np.cos(0.25) - 1.22,
                                                                          0.02 * np.sin(0.25)), rel=0.05)
    assert matrix[:, COL['sum_pose_gap']].max() >= matrix[:, COL['max_pose_gap']].max()
    assert matrix[:, COL['max_heading_gap']].max() == pytest.approx(0.5)
    quiet = ends < t[300] - 1e-9
    assert matrix[quiet, COL['max_pose_gap']].max() < 1e-9
    assert matrix[quiet, COL['max_heading_gap']].max() < 1e-9


def test_a_spin_in_place_raises_the_yaw_rate_and_the_yaw_rate_while_standing():
    w = np.zeros(500)
    w[200:300] = 3.0
    samples = drive(np.zeros(500), w)
    assert column_max(samples, 'max_yaw_rate') == pytest.approx(3.0)
    assert column_max(samples, 'still_yaw_rate') == pytest.approx(3.0)
    assert column_max(samples, 'still_fraction') == pytest.approx(1.0)
    assert column_max(samples, 'max_yaw_accel') == pytest.approx(3.0 / 0.06)
    assert column_max(samples, 'max_heading_gap') < 1e-9


def test_yaw_rate_sign_flips_are_counted_outside_the_deadband():
    w = np.where(np.arange(500) // 10 % 2 == 0, 0.5, -0.5)    # a flip every 0.2 s
    w[::7] = 0.01          # near zero: no sign, no flip
    samples = drive(np.full(500, 1.0), w)
    assert column_max(samples, 'yaw_rate_flips') == pytest.approx(5.0, abs=1.0)


def test_irregular_stamps_and_a_dropped_sample_make_no_false_extremes():
    rng = np.random.default_rng(2)
    n = 1000
    regular = drive(1.0 + 0.5 * np.sin(np.arange(n) / 50.0), 0.3 * np.cos(np.arange(n) / 80.0))
    reference = envelope_windows(*regular)[1].max(axis=0)
    # jittered stamps (+-4 ms at 50 Hz), the values those of the motion at the stamps
    stamps = 1000.0 + np.arange(n) / RATE + rng.uniform(-0.004, 0.004, n)
    stamps[1::2] = 1000.0 + np.arange(1, n, 2) / RATE + 0.009     # two samples 1-10 ms apart
    phase = (stamps - 1000.0) * RATE
    jittered = drive(1.0 + 0.5 * np.sin(phase / 50.0), 0.3 * np.cos(phase / 80.0), stamps=stamps)
    dropped = tuple(np.delete(a, [400, 401, 402, 700]) for a in regular)
    for samples in (jittered, dropped):
        ends, matrix = envelope_windows(*samples)
        for name in ('max_accel', 'max_yaw_accel', 'max_decel', 'max_speedup', 'max_span_accel',
                     'max_speed_drop', 'max_speed_rise', 'max_jerk'):
            assert matrix[:, COL[name]].max() <= 1.5 * reference[COL[name]] + 0.05, name
        for name in ('max_pose_gap', 'max_heading_gap'):
            assert matrix[:, COL[name]].max() < 0.01, name


def test_bad_samples_are_dropped_and_mismatched_lengths_refused():
    t, x, y, yaw, v, w = drive(np.full(300, 1.0), np.zeros(300))
    v = v.copy()
    v[100] = np.nan
    t = t.copy()
    t[200] = t[150]        # time going backwards: dropped
    ends, matrix = envelope_windows(t, x, y, yaw, v, w)
    assert np.all(np.isfinite(matrix)) and matrix[:, COL['max_accel']].max() < 1e-9
    assert envelope_windows(t[:1], x[:1], y[:1], yaw[:1], v[:1], w[:1])[1].shape == (0, 19)
    with pytest.raises(ValueError, match='^envelope: stamps, x, y, yaw, v and w must have one length'):
        envelope_windows(t, x[:-1], y, yaw, v, w)
    with pytest.raises(ValueError, match='^envelope: window and stride must be positive'):
        envelope_windows(t, x, y, yaw, v, w, stride=0)


def test_a_window_from_the_recent_samples_only_equals_the_whole_runs_row():
    """What a live trigger computes from a ring of the last window + HISTORY seconds is the offline row."""
    rng = np.random.default_rng(3)
    samples = drive(rng.uniform(0, 2, 800), rng.uniform(-1, 1, 800))
    ends, matrix = envelope_windows(*samples)
    for k in (0, 10, 30, len(ends) - 1):
        ring = samples[0] > ends[k] - 1.0 - HISTORY
        got_ends, row = envelope_rows(*(a[ring] for a in samples), ends=[ends[k]])
        assert got_ends[0] == ends[k] and np.allclose(row[0], matrix[k])


def test_a_long_run_is_fast():
    import time
    n = 25 * 60 * 66
    samples = drive(np.ones(n), np.zeros(n), rate=66.0)
    start = time.perf_counter()
    ends, _ = envelope_windows(*samples)
    assert len(ends) > 5900 and time.perf_counter() - start < 2.0
