"""Complete strokes of a drive log: every crank angle covered as often as the log's samples cover it, whatever angle
the log starts and ends at, its angle convention, its sample jitter, a lead-in at rest or a recording correction,
and the same count wherever it is reported (the grid, the summary, the adequacy verdict).

The logs are SYNTHETIC, made here (no noise, seed-free): tests/test_drive_log.py's closed-form crank motion
theta(t) = theta0 + w0 t + depth sin(w0 t) at 12 strokes/min (a period of exactly 2500 samples at 500 Hz), torque
f(theta) of that file. The expected count is worked out in time, independently of the reader's angle steps: each
sample stands for its time and half the interval to each neighbour (N samples stand for N sample intervals), a
sample at rest for no rotation, and a torque sample delayed by d for the crank angle at its time less d. A crank
angle g is covered in turn k when g + 360 k lies in the crank rotation those times span; the complete strokes are
the fewest turns any grid angle is covered in.
"""
import math

import numpy as np
import pytest

from calibration.identification.adequacy import assess
from calibration.traces.drive_log import HEADER, grid_rows, read_log_rows, summary
from test_drive_log import DEPTH, G, F2_MAX, RATED, smooth_torque

SPM = 12.0
W0 = 2.0 * math.pi * SPM / 60.0  # rad/s mean crank speed
RATE = 500.0  # Hz
PER_TURN = int(round(RATE * 60.0 / SPM))  # 2500 samples a turn
H = W0 * (1.0 + DEPTH) / RATE  # rad: the widest sample step in crank angle
NOTE = "synthetic drive log made by tests/test_drive_log_strokes.py (truth: f(theta) of tests/test_drive_log.py, no noise)"


def theta_at(t, start_deg):
    """rad: the crank angle of the moving crank at times t (s)."""
    return math.radians(start_deg) + W0 * t + DEPTH * np.sin(W0 * t)


def make(tmp_path, start_deg=0.0, extra=0, jitter=0.0, wrap="encoder", rest=0, delay_s=0.0, offset_deg=0.0):
    """A SYNTHETIC log of 3 x 2500 + ``extra`` moving samples from ``start_deg`` (the first at t = 0), each time moved by
    up to ``jitter`` sample steps (uniform, seed 0), ``rest`` rows at rest before and after, the torque channel
    ``delay_s`` behind the angle, the encoder reading ``offset_deg`` high, the angle written as ``wrap`` says
    ('encoder' [0, 360), 'signed' (-180, 180], 'continuous' unwrapped). Returns (path, (lo, hi) the crank rotation in
    deg its torque samples stand for, worked out in time, as the encoder reads it)."""
    dt = 1.0 / RATE
    n = 3 * PER_TURN + extra
    t = np.arange(n) * dt + np.random.default_rng(0).uniform(-jitter, jitter, n) * dt * (jitter > 0)
    t[0] = 0.0
    th = theta_at(t, start_deg)
    speed = W0 * (1.0 + DEPTH * np.cos(W0 * t))
    torque = smooth_torque(theta_at(t - delay_s, start_deg))
    # the samples' rotation in time: from half the first interval before the first to half the last after the last
    lo, hi = theta_at(t[0] - delay_s - 0.5 * (t[1] - t[0]), start_deg), theta_at(t[-1] - delay_s + 0.5 * (t[-1] - t[-2]), start_deg)
    if rest:  # at rest before the first and after the last moving sample: those rows stand for no rotation
        assert not delay_s, "a delayed torque at rest is not made here"
        before, after = -dt * np.arange(rest, 0, -1), t[-1] + dt * np.arange(1, rest + 1)
        lo, hi = th[0], th[-1]
        t = np.concatenate((before, t, after))
        th = np.concatenate((np.full(rest, th[0]), th, np.full(rest, th[-1])))
        speed = np.concatenate((np.zeros(rest), speed, np.zeros(rest)))
        torque = np.concatenate((np.full(rest, torque[0]), torque, np.full(rest, torque[-1])))
    deg = np.degrees(th) + offset_deg
    if wrap == "encoder":
        deg = np.mod(deg, 360.0)
    elif wrap == "signed":
        deg = np.mod(deg + 180.0, 360.0) - 180.0
    rpm = speed * G * 60.0 / (2.0 * math.pi)
    rows = [f"{a:.6f},{b:.9f},{c:.4f},{d:.3f}" for a, b, c, d in zip(t, deg, rpm, torque)]
    path = tmp_path / "log.csv"
    path.write_text("\n".join([f"# {NOTE}", HEADER, *rows]) + "\n", encoding="utf-8")
    return path, (math.degrees(lo) + offset_deg, math.degrees(hi) + offset_deg)


def covered_strokes(lo_deg, hi_deg):
    """The fewest turns in which any grid angle (0, 1, .. 359 deg) lies within [lo, hi] (deg, unwrapped)."""
    g = np.arange(360.0)
    return int(np.min(np.floor((hi_deg - g) / 360.0) - np.ceil((lo_deg - g) / 360.0) + 1))


CASES = {  # name: (make's arguments, the complete strokes the samples hold)
    "starts at 0": (dict(), 3),
    "starts at 1e-9 deg": (dict(start_deg=1e-9), 3),
    "starts at -1e-9 deg": (dict(start_deg=-1e-9), 3),
    "starts at 1e-4 deg": (dict(start_deg=1e-4), 3),
    "starts at 359.99 deg": (dict(start_deg=359.99), 3),
    "starts at 0.3 deg": (dict(start_deg=0.3), 3),
    "starts mid-stroke": (dict(start_deg=180.5), 3),
    "one sample past three turns": (dict(start_deg=0.3, extra=1), 3),
    "one sample short, from 0": (dict(extra=-1), 3),
    # three samples (0.6 deg) short of three turns: the 0.6 deg before the start are covered twice; 0 deg lies there
    # when the log starts at 0.3 or at 180.5 deg (then 180 deg), not when it starts at 0 (the 0.6 deg before 0)
    "three samples short, from 0": (dict(extra=-3), 3),
    "three samples short, from 0.3 deg": (dict(start_deg=0.3, extra=-3), 2),
    "three samples short, mid-stroke": (dict(start_deg=180.5, extra=-3), 2),
    "jittered sample times": (dict(start_deg=0.3, jitter=0.1), 3),
    "signed angle (-180, 180]": (dict(start_deg=0.3, wrap="signed"), 3),
    "continuous angle": (dict(start_deg=0.3, wrap="continuous"), 3),
    "continuous angle from -1e-9 deg": (dict(start_deg=-1e-9, wrap="continuous"), 3),
    "at rest before and after": (dict(start_deg=0.3, rest=50), 3),
    "at rest before and after, from 0": (dict(rest=50), 3),
    # a recording correction as calibrate makes it (calibration/identification/recording.py): the torque channel 1 or 3
    # ms behind the angle, the encoder 0.05 or 0.3 deg high or low; a correction once read these logs as 2 strokes
    "torque 1 ms behind": (dict(delay_s=0.001), 3),
    "torque 3 ms behind": (dict(delay_s=0.003), 3),
    "torque 2 ms ahead": (dict(delay_s=-0.002), 3),
    "encoder 0.05 deg high": (dict(offset_deg=0.05), 3),
    "encoder 0.05 deg low": (dict(offset_deg=-0.05), 3),
    "encoder 0.3 deg high": (dict(offset_deg=0.3), 3),
    "encoder 0.15 deg low": (dict(offset_deg=-0.15), 3),
    # ... and corrected by an estimate a little off (then the first sample lies a hair past 0 deg, or just before it)
    "encoder 0.3 deg high, corrected by 0.26": (dict(offset_deg=0.3, correction=(0.0, 0.26)), 3),
    "encoder 0.3 deg low, corrected by -0.26": (dict(offset_deg=-0.3, correction=(0.0, -0.26)), 3),
    "torque 2 ms behind, corrected by 2.3 ms": (dict(delay_s=0.002, correction=(0.0023, 0.0)), 3),
}


@pytest.mark.parametrize("name", CASES)
def test_every_complete_stroke_of_a_log_is_counted_and_reported_alike(tmp_path, name):
    kw, strokes = dict(CASES[name][0]), CASES[name][1]
    correction = kw.pop("correction", (kw.get("delay_s", 0.0), kw.get("offset_deg", 0.0)))
    path, (lo, hi) = make(tmp_path, **kw)
    shift = np.degrees(W0 * (1.0 + DEPTH)) * (correction[0] - kw.get("delay_s", 0.0)) + correction[1]  # deg, at t = 0's speed
    assert covered_strokes(lo - shift, hi - shift) == strokes  # the case's count, worked out in time
    log = grid_rows(read_log_rows(path), G, RATED, 1.0, correction=correction)
    count = np.sum(np.isfinite(log.stroke_torque), axis=0)
    assert log.strokes == strokes == int(np.min(count))
    # the points read beyond an end sample are the torque there: the line through the two end samples, within half a
    # step, errs at most 3/8 f'' h^2 (3 x linear interpolation's bound), plus the file's rounding (a correction that
    # is off moves the curve along the angle: not checked there)
    if shift == 0.0:
        assert np.max(np.abs(log.torque - smooth_torque(log.theta))) <= 3.0 * F2_MAX * H ** 2 / 8.0 + 2e-3
    text = summary(log)
    assert text.count(f"; {strokes} complete strokes in ") == 1
    turns = float(text.split(" complete strokes in ")[1].split(" turns")[0])
    # never rounded up to a whole number of turns the log does not span and its complete strokes do not fill
    assert math.floor(turns) <= max(strokes, math.floor(log.rotation_deg / 360.0))
    verdict = assess(log.stroke_torque, log.torque, smooth_torque(log.theta), np.ones(log.theta.size, bool), 1, 0.05)
    assert verdict.strokes == log.strokes
