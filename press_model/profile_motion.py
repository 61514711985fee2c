"""A crank motion read from a planned profile (the profile.csv that `servo-press plan` writes).

The profile is sampled in time (the press controller's set-point rate) from the start of a stroke at TDC,
one crank turn, then the dwell at TDC. :func:`read_profile_motion` keeps the turn, leaves out the dwell
rows and returns a :class:`motion.TabulatedSpeed` that repeats every turn, so that any cycle the planner
made (or a user's own set-point table in the same columns) can be analysed like a job's ``[motion]``.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from press_io.errors import PressDataError
from .motion import TabulatedSpeed
from .readers import is_file, read_text_file

COLUMNS = ("time_s", "crank_angle_deg", "crank_speed_rad_s", "crank_accel_rad_s2")  # the columns used, of profile.csv
TURN_TOL_DEG = 1e-5  # the turn may miss 360 deg by this (profile.csv keeps 10 significant digits)
PERIODIC_TOL = 1e-6  # start and end speed may differ by this fraction of the top speed


def read_profile_motion(path) -> TabulatedSpeed:
    """The crank motion of one turn of a profile CSV (columns :data:`COLUMNS`, SI units, angle in deg).

    Refuses, naming the file, row and value: missing columns or non-numbers, time not rising, a crank
    that turns back, a profile shorter than one turn, a standstill inside the turn, rows after the turn
    that move the crank (anything but the dwell), and start and end speeds that differ (not periodic).
    """
    src = str(path)
    if not is_file(Path(src)):
        raise PressDataError(src, "--profile", src, "must be an existing profile CSV (the profile.csv that `servo-press plan` writes)")
    rows = list(csv.reader(read_text_file(Path(src), "--profile").splitlines()))
    if not rows:
        raise PressDataError(src, "header", "", f"is empty: a profile needs the columns {', '.join(COLUMNS)}")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise PressDataError(src, "header", ",".join(header), f"lacks the column(s) {', '.join(missing)} (profile.csv of `servo-press plan` has them)")
    cols = [header.index(c) for c in COLUMNS]
    data = np.empty((len(rows) - 1, len(COLUMNS)))
    for i, row in enumerate(rows[1:]):
        for j, c in enumerate(cols):
            cell = row[c].strip() if c < len(row) else ""
            try:
                data[i, j] = float(cell)
            except ValueError:
                data[i, j] = math.nan
            if not math.isfinite(data[i, j]):
                raise PressDataError(src, f"row {i + 2}, {COLUMNS[j]}", cell, "must be a finite number")
    if len(data) < 3:
        raise PressDataError(src, "rows", len(data), "must be at least 3 samples over one crank turn")
    t, ang, sd, acc = data.T
    if np.any(np.diff(t) <= 0):
        i = int(np.argmax(np.diff(t) <= 0)) + 1
        raise PressDataError(src, f"row {i + 2}, time_s", float(t[i]), "must rise from row to row")
    if np.any(np.diff(ang) < 0) or np.any(sd < 0):
        i = int(np.argmax(np.diff(ang) < 0)) + 1 if np.any(np.diff(ang) < 0) else int(np.argmax(sd < 0))
        raise PressDataError(src, f"row {i + 2}, crank_angle_deg", float(ang[i]),
                             "the crank must turn forward only (angle never falling, speed >= 0)")
    reached = np.flatnonzero(ang >= ang[0] + 360.0 - TURN_TOL_DEG)
    if not len(reached):
        raise PressDataError(src, "crank_angle_deg", f"{ang[0]:.6g} .. {ang[-1]:.6g}",
                             f"covers {ang[-1] - ang[0]:.6g} deg: a profile must run one full crank turn (360 deg, unwrapped)")
    on_end = np.flatnonzero(np.abs(ang - ang[0] - 360.0) <= TURN_TOL_DEG)  # consecutive rows: the angle never falls
    if not len(on_end):
        end = int(reached[0])
        raise PressDataError(src, f"row {end + 2}, crank_angle_deg", float(ang[end]),
                             f"runs past one turn from {ang[0]:.6g} deg without a sample at {ang[0] + 360.0:.6g} deg; end the turn on a sample")
    # the turn ends at the last of those rows that the crank still moved to: a stroke that creeps to its end angle
    # (a jerk-limited stop) reaches the tolerance while still moving; the rows after it are the dwell
    moved = [int(i) for i in on_end[1:] if ang[i] > ang[i - 1]]
    end = moved[-1] if moved else int(on_end[0])
    after = slice(end + 1, None)
    if np.any(ang[after] != ang[end]) or np.any(sd[after] != 0.0):
        i = end + 1 + int(np.argmax((ang[after] != ang[end]) | (sd[after] != 0.0)))
        raise PressDataError(src, f"row {i + 2}", f"{ang[i]:.6g} deg, {sd[i]:.6g} rad/s",
                             "after the turn only the dwell may follow (crank at rest at the end angle); give one turn")
    inner = np.flatnonzero((sd[1:end] <= 0.0) | (np.diff(ang[: end + 1])[:-1] <= 0.0)) + 1
    if len(inner):
        i = int(inner[0])
        raise PressDataError(src, f"row {i + 2}, crank_speed_rad_s", float(sd[i]),
                             f"the crank stands still at {ang[i]:.6g} deg inside the turn (t = {t[i]:.6g} s): the responses "
                             "weight each crank angle by the time spent there, so only the turn's ends may be at rest")
    top = float(np.max(sd[: end + 1]))
    if top <= 0.0 or abs(sd[end] - sd[0]) > PERIODIC_TOL * top:
        raise PressDataError(src, "crank_speed_rad_s", f"{sd[0]:.6g} at the start, {sd[end]:.6g} at the end",
                             "must be the same at both ends of the turn so that the motion repeats (a periodic cycle)")
    theta = np.radians(ang[: end + 1])
    theta[-1] = theta[0] + 2.0 * math.pi  # the turn closes exactly
    speed = sd[: end + 1].copy()
    speed[-1] = speed[0]
    return TabulatedSpeed(theta, speed, acc[: end + 1].copy(), t[: end + 1] - t[0])
