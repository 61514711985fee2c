"""Servo drive logs: read a measured (or synthetic) log onto the crank-angle grid, and write one.

A drive log is a CSV file. Lines starting with ``#`` before the header are comments (metadata, kept);
the header names the four columns ``time_s, crank_angle_deg, motor_speed_rpm, motor_torque_Nm`` (in
any order, spaces after the commas allowed): time in s, crank angle in degrees (wrapping at 360 or
not), motor speed at the motor shaft in rpm (crank speed = motor speed / gear ratio) and torque per
motor in N m. A log whose comments contain the word "synthetic" is synthetic: the reader says so and
keeps that comment as the label, so that every report can say so. A comment ``# recorded: <ISO-8601>``
dates the log (:func:`recorded_time`; ``servo-press monitor`` orders a press's logs by it).

Reading unwraps the crank angle and brings each turn onto the uniform grid of Eq. 22 (from
theta_c = 0, :func:`press_model.cycle.crank_grid`) by linear interpolation in the unwrapped angle.
Turn k covers the unwrapped angles [360 k, 360 (k + 1)) deg; partial first and last turns give the grid
points they cover, each end sample standing for half a sample step beyond it (N samples cover N steps of rotation). Interpolation, not bin averaging: the process force steps at die contact, and a bin
mean would smear that step onto the neighbouring grid point.

Bad rows are repaired only where that is safe, each repair stated in :attr:`DriveLog.warnings`;
everything else raises :class:`press_io.errors.PressDataError` naming the line, the column or the
crank angle, and the fix. The thresholds are in ``press_model/data/drive_log.toml``. Refused, with
the reason: two rows with the same time but different values (which one the drive meant is unknown;
averaging them would invent a sample), a crank angle that falls back or jumps, rows out of time
order that do not give a forward-turning crank when sorted, a speed column that disagrees with the
crank angle, torque that looks like kN m, and less than one full turn.
"""
from __future__ import annotations

import dataclasses
import hashlib
import io
import math
import re
import sys
from dataclasses import dataclass
from datetime import datetime, timezone
from functools import lru_cache
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from press_model.cycle import crank_grid
from press_model.limits import LIMITS_FILE, run_limits
from press_io.errors import PressDataError
from press_io.outputs import atomic_write_text, versions
from press_model.readers import FieldReader, is_file, read_text_with_digest, read_toml

from calibration.traces.units import TORQUE_UNITS

COLUMNS = ("time_s", "crank_angle_deg", "motor_speed_rpm", "motor_torque_Nm")
HEADER = ", ".join(COLUMNS)
TORQUE_COLUMN = COLUMNS[3]  # a log of several motors may hold one column per motor instead: motor_torque_Nm_1 ... _M
_PER_MOTOR_READ = "\0motor"  # the header's place of a motor's own torque column after the first (read, averaged)
FORCE_COLUMN = "process_force_N"  # optional: the force on the slide from the cushion or part (N, up positive as the job's)
SETTINGS_FILE = "drive_log.toml"
_RPM_TO_DEG_S = 6.0  # 1 rpm = 360 deg / 60 s
_RPM_TO_RAD_S = 2.0 * math.pi / 60.0
_LISTED = 5  # message length only: how many lines or ranges one sentence names before "and N more"
_WRITER = "written by calibration.traces.drive_log"
_SAME_ANGLE_DEG = 1e-7  # a grid point this close to a force step lies on it: above the rounding of an unwrapped angle in deg (1e-16 relative of up to 1e5 deg) and the BDC search's tolerance (1e-10 rad, 6e-9 deg), far below a sample step (0.01 deg and more)
_GLITCH_SHARE = 0.01  # torque samples beyond the glitch bound in at most this share of the rows are isolated glitches (dropped); more is a unit or press mismatch, left to check_against_model
RECORDED = "recorded:"  # comment prefix of the date a log was recorded, e.g. '# recorded: 2025-03-03T08:00:00+00:00'


# --- settings ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DriveLogSettings:
    """The thresholds of ``drive_log.toml`` (units as in the file: deg, or 1 for ratios)."""

    source: str
    min_rows: int
    gap_factor: float
    max_interpolated_gap_deg: float
    backward_tolerance_deg: float
    angle_jump_relative: float
    angle_jump_floor_deg: float
    speed_mismatch_tolerance: float
    speed_floor_fraction_of_max: float
    min_torque_fraction_of_rated: float
    glitch_torque_ratio_of_peak: float
    max_gap_turns: float
    max_crank_angle_deg: float
    torque_channels_cancel_ratio: float
    min_torque_scale: float
    max_torque_scale: float
    sample_match_relative: float
    same_recording_share: float
    time_decimals: int
    angle_decimals: int
    speed_decimals: int
    torque_decimals: int


def parse_settings(raw: Mapping, source: str) -> DriveLogSettings:
    """Validate the parsed TOML of a drive-log settings file; misspelled or unknown keys are refused."""
    rd = FieldReader(source, raw)

    def decimals(key):
        val = rd.integer(("write", key), ge=0)
        if val > 12:
            rd.fail(("write", key), val, "must be a whole number from 0 to 12 (float64 holds about 15 digits)")
        return val

    cfg = DriveLogSettings(
        source=source,
        min_rows=rd.integer(("read", "min_rows"), ge=2),
        gap_factor=rd.number(("repair", "gap_factor"), gt=1.0),
        max_interpolated_gap_deg=rd.number(("repair", "max_interpolated_gap_deg"), ge=0.0, lt=360.0, unit="deg"),
        backward_tolerance_deg=rd.number(("repair", "backward_tolerance_deg"), ge=0.0, lt=180.0, unit="deg"),
        angle_jump_relative=rd.number(("check", "angle_jump_relative"), gt=0.0),
        angle_jump_floor_deg=rd.number(("check", "angle_jump_floor_deg"), ge=0.0, lt=180.0, unit="deg"),
        speed_mismatch_tolerance=rd.number(("check", "speed_mismatch_tolerance"), gt=0.0, lt=1.0),
        speed_floor_fraction_of_max=rd.number(("check", "speed_floor_fraction_of_max"), ge=0.0, lt=1.0),
        min_torque_fraction_of_rated=rd.number(("check", "min_torque_fraction_of_rated"), ge=0.0, lt=1.0),
        glitch_torque_ratio_of_peak=rd.number(("check", "glitch_torque_ratio_of_peak"), gt=1.0),
        max_gap_turns=rd.number(("check", "max_gap_turns"), gt=0.0),
        max_crank_angle_deg=rd.number(("check", "max_crank_angle_deg"), gt=360.0, unit="deg"),
        torque_channels_cancel_ratio=rd.number(("check", "torque_channels_cancel_ratio"), gt=0.0, lt=1.0),
        min_torque_scale=rd.number(("model", "min_torque_scale"), gt=0.0, lt=1.0),
        max_torque_scale=rd.number(("model", "max_torque_scale"), gt=1.0),
        sample_match_relative=rd.number(("identity", "sample_match_relative"), gt=0.0, lt=1e-2),
        same_recording_share=rd.number(("identity", "same_recording_share"), gt=0.0, lt=1.0),
        time_decimals=decimals("time_decimals"),
        angle_decimals=decimals("angle_decimals"),
        speed_decimals=decimals("speed_decimals"),
        torque_decimals=decimals("torque_decimals"),
    )
    rd.reject_unread()
    return cfg


def load_settings(path: str | Path | None = None) -> DriveLogSettings:
    """Read a drive-log settings file; ``None`` reads the shipped ``press_model/data/drive_log.toml``."""
    raw, source = read_toml(path, SETTINGS_FILE if path is None else None, "<file>", "must be an existing drive-log settings TOML file")
    return parse_settings(raw, source)


@lru_cache(maxsize=1)
def _shipped_settings() -> DriveLogSettings:
    """The shipped drive_log.toml, read once a process (every log read and model check takes it)."""
    return load_settings()


def _settings(settings) -> DriveLogSettings:
    if settings is None:
        return _shipped_settings()
    if isinstance(settings, DriveLogSettings):
        return settings
    if isinstance(settings, Mapping):
        return parse_settings(settings, "<drive-log settings>")
    raise PressDataError("<drive-log settings>", "settings", type(settings).__name__,
                         "must be None, a DriveLogSettings (load_settings) or the parsed drive_log.toml")


# --- the result ------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class DriveLog:
    """A drive log on the crank-angle grid. Arrays are read-only; units SI (rad, rad/s, N m per motor).

    ``theta`` (n,) rad from 0 in the chosen step; ``torque`` (n,) the stroke average; ``torque_spread``
    (n,) the sample standard deviation across strokes (NaN where one stroke covers the point);
    ``stroke_torque`` (S, n) each turn on the grid (NaN where the turn has no data); ``crank_speed``
    (n,) rad/s stroke-averaged, from the motor speed column; ``strokes`` the number of complete strokes: how
    many times the log covers every crank angle of the turn (a log that starts mid-turn has them across the rows
    of ``stroke_torque``, none of which is complete alone); ``rotation_deg`` the crank rotation the log spans.
    """

    source: str
    synthetic: bool
    label: str
    comments: tuple[str, ...]
    theta: np.ndarray
    torque: np.ndarray
    torque_spread: np.ndarray
    stroke_torque: np.ndarray
    crank_speed: np.ndarray
    strokes: int
    sample_rate_hz: float
    rotation_deg: float
    gear_ratio: float
    torque_unit: str
    warnings: tuple[str, ...]
    # (n,) the mean of *every* sample whose crank angle rounds to each grid point (NaN where none): the recording
    # estimate's curve (calibration/identification/recording.py). Interpolation reads two samples a grid point, this all of them
    # (some 7 to 17 a degree at 500 Hz), so off the force steps it has a fraction of the noise; across a step a bin
    # mean smears it, so Eq. 28 keeps ``torque``
    torque_binned: np.ndarray | None = None
    # (n,) rad: the mean of (sample angle - grid point) over each bin's samples (0 where none). A bin holds few
    # samples (4 to 17), so their mean angle sits off the grid point by up to a fraction of a sample step; the
    # estimate takes each bin mean at its own angle (calibration/identification/recording.py, :func:`bin_angle_correction`)
    angle_binned_offset: np.ndarray | None = None
    # (rows,) rad: the crank angle (unwrapped, corrected) of every torque sample the bin means hold, in time order: a
    # curve read at these angles and binned as the log is binned is the model's own bin mean, smear and all
    # (calibration/identification/recording.py, :func:`bin_smear`)
    torque_angles: np.ndarray | None = None
    # the channel map (calibration.traces.channel_map.ChannelMap) the columns were read through, None for a drive-log CSV: a
    # refusal that a unit, side or sign of the map explains names the map's key (check_against_model)
    channel_map: object | None = None
    rated_torque_Nm: float = math.nan  # the motor's rated torque the log was read with (N m; a map's '%' unit)
    # (rows, 4) the samples as read and kept (time s, crank angle deg as logged, motor speed rpm, torque N m), in time
    # order: what makes two logs the same recording (calibration/traces/log_identity.py)
    samples: np.ndarray | None = None
    # (S, n) N: the logged process force (column process_force_N) of each turn on the grid, at the angle channel's own
    # angles (a torque-channel delay does not move it), NaN where the turn has none; None when the log has no force
    stroke_force: np.ndarray | None = None
    # (n,) N: the mean logged force of every sample whose angle rounds to each grid point, over every turn (NaN where none;
    # None without a force column): a fraction of the interpolated curve's noise, but a step smeared onto its bin
    force_binned: np.ndarray | None = None
    # (T, n) N and (T, n) int: each turn's own bin means of the logged force (NaN where the turn has no sample in the bin)
    # and how many samples each holds (turn t: the samples whose grid index rounds into turn t); their scatter from turn
    # to turn is the force channel's noise (calibration/identification/force_noise.py). None without a force column
    stroke_force_binned: np.ndarray | None = None
    # (T, n) N m: each turn's own bin means of the torque, turns as ``stroke_force_binned``'s: the stroke's torque with a
    # fraction of one interpolated point's noise (the virtual tonnage of monitoring/tonnage.py reads it)
    stroke_torque_binned: np.ndarray | None = None
    stroke_force_counts: np.ndarray | None = None
    # (n,) rad/s: the stroke-to-stroke standard deviation of the crank speed (NaN where one stroke covers the point):
    # the speed's own noise, from which the calibration chooses how finely to fit it (calibration/identification/speed_fit.py)
    crank_speed_spread: np.ndarray | None = None
    # (rows, 3) every kept sample's time (s), crank angle (rad, unwrapped, corrected for the encoder offset) and crank
    # speed (rad/s from the motor speed column), in time order: the speed between the grid points, from which the
    # calibration takes the crank acceleration (calibration/identification/speed_fit.py)
    speed_samples: np.ndarray | None = None


def summary(log: DriveLog) -> str:
    """One paragraph for people: what the log is, how many strokes at what rate, and every repair made."""
    kind = f"SYNTHETIC log ({log.label})" if log.synthetic else "log (not marked synthetic)"
    step = math.degrees(log.theta[1] - log.theta[0])
    spread = log.torque_spread[np.isfinite(log.torque_spread)]
    spread_txt = (f", spread across strokes {math.sqrt(float(np.mean(spread ** 2))):.4g} N m RMS" if spread.size
                  else ", no grid point covered twice")
    repairs = (" Repairs: " + " ".join(log.warnings)) if log.warnings else " No repairs were needed."
    return (f"{log.source}: {kind}; {log.strokes} complete stroke{'s' if log.strokes != 1 else ''} in "
            f"{_turns_txt(log.rotation_deg / 360.0, log.strokes)} turns of crank rotation, sampled at {log.sample_rate_hz:.4g} Hz, "
            f"brought onto a {log.theta.size}-point grid ({step:g} deg) by linear interpolation within each turn; "
            f"torque per motor {np.min(log.torque):.4g} to {np.max(log.torque):.4g} N m{spread_txt}.{repairs}")


def _turns_txt(turns: float, strokes: int) -> str:
    """``turns`` to three digits, or to four decimals, cut, where three would round it up to a whole number of turns
    beyond ``strokes`` (2.9996 turns holding 2 complete strokes are not '3 turns')."""
    txt = f"{turns:.3g}"
    if math.floor(float(txt)) > math.floor(turns) and float(txt) > strokes:
        txt = f"{math.floor(turns * 1e4) / 1e4:.10g}"
    return txt


# --- the recording date ------------------------------------------------------------------------
def leading_comments(path: str | Path) -> tuple[str, ...]:
    """The comment lines (``#`` stripped) before a log's header, read without parsing the data rows."""
    p = Path(path)
    if not is_file(p):
        raise PressDataError(str(p), "<file>", str(p), "must be an existing drive-log CSV file")
    comments = []
    try:
        with p.open(encoding="utf-8") as fh:
            for i, line in enumerate(fh):
                s = line.removeprefix("\ufeff").strip() if i == 0 else line.strip()
                if s.startswith("#"):
                    comments.append(s[1:].strip())
                elif s:
                    break
    except UnicodeDecodeError as exc:
        raise PressDataError(str(p), "<file>", str(p), f"must be a UTF-8 text file ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise PressDataError(str(p), "<file>", str(p), f"must be a readable file ({exc.strerror})") from None
    return tuple(comments)


def recorded_time(comments: Sequence[str], source: str) -> tuple[str, datetime] | None:
    """The log's ``recorded: <ISO-8601>`` comment as (the text, the time in UTC), or None without one.

    A time without a UTC offset is read as UTC (say the offset when the presses log local time). Two
    ``recorded:`` lines, or one that is not an ISO-8601 date, raise :class:`PressDataError`.
    """
    found = [c[len(RECORDED):].strip() for c in comments if c.lower().startswith(RECORDED)]
    if not found:
        return None
    if len(found) > 1:
        raise PressDataError(source, "# recorded:", found, "must appear once: a log has one recording date; remove the others")
    return found[0], parse_recorded(found[0], source)


def parse_recorded(text: str, source: str) -> datetime:
    """An ISO-8601 date or date-time as a UTC datetime (no offset given: read as UTC)."""
    try:
        when = datetime.fromisoformat(text)
    except ValueError:
        raise PressDataError(source, "# recorded:", text, "must be an ISO-8601 date or date-time, e.g. "
                             "'# recorded: 2025-03-03T08:00:00+00:00'") from None
    return when.replace(tzinfo=timezone.utc) if when.tzinfo is None else when.astimezone(timezone.utc)


# --- writing ---------------------------------------------------------------------------------------
def write_drive_log(path: str | Path, time_s, crank_angle_deg, motor_speed_rpm, motor_torque_Nm,
                    comments: Sequence[str], settings=None, process_force_N=None) -> None:
    """Write a drive log atomically, with fixed decimals (``[write]`` of drive_log.toml).

    Angles are written wrapped into [0, 360) deg as an encoder gives them; torque in N m per motor.
    The comments come first (one ``# `` line each; mark synthetic data with the word "synthetic"),
    then a line naming the writer and the package versions, then the header. The same arrays and
    comments give a byte-identical file. ``process_force_N``: the optional fifth column (N, up positive), written
    with the torque's decimals. ``motor_torque_Nm`` of shape (M, rows), M > 1: each motor's own torque, written as the
    columns motor_torque_Nm_1 ... _M in its place (a reader takes their mean as the torque per motor).
    """
    cfg = _settings(settings)
    src = str(path)
    cols = []
    named = list(zip(COLUMNS[:3], (time_s, crank_angle_deg, motor_speed_rpm)))
    per_motor = np.ndim(motor_torque_Nm) == 2 and len(motor_torque_Nm) > 1
    named += ([(f"{TORQUE_COLUMN}_{i + 1}", q) for i, q in enumerate(motor_torque_Nm)] if per_motor else
              [(TORQUE_COLUMN, motor_torque_Nm)])
    if process_force_N is not None:
        named.append((FORCE_COLUMN, process_force_N))
    for name, values in named:
        try:
            arr = np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            raise PressDataError(src, name, type(values).__name__, "must be a 1-D array of numbers") from None
        if arr.ndim != 1 or not np.all(np.isfinite(arr)):
            raise PressDataError(src, name, f"array of shape {arr.shape}", "must be a 1-D array of finite numbers")
        cols.append(arr)
    if len({c.size for c in cols}) != 1:
        raise PressDataError(src, "columns", [c.size for c in cols], "must all have the same length")
    lines = []
    for c in comments:
        if not isinstance(c, str) or any(ch in c for ch in "\r\n\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"):
            raise PressDataError(src, "comments", c, "must be strings without line breaks (one per comment line)")
        lines.append(f"# {c}".rstrip())
    v = versions()
    stamp = f"# {_WRITER} (servo-press-twin {v['servo-press-twin']}, numpy {v['numpy']}, python {v['python']})"
    if stamp not in lines:
        lines.append(stamp)
    lines.append(",".join(name for name, _ in named))
    a = np.round(np.mod(cols[1], 360.0), cfg.angle_decimals)
    a[a >= 360.0] -= 360.0  # 359.9999999 rounds up to 360: that is 0 on the encoder
    cols[1] = a
    ft, fa, fn, fq = cfg.time_decimals, cfg.angle_decimals, cfg.speed_decimals, cfg.torque_decimals
    row = ",".join(f"{{:.{d}f}}" for d in (ft, fa, fn, *[fq] * (len(cols) - 3)))  # torques and the force: the torque's decimals
    lines.extend(row.format(*r) for r in zip(*(c.tolist() for c in cols)))  # Python floats: the same text, formatted ~2x faster
    atomic_write_text(Path(path), "\n".join(lines) + "\n")


# --- reading ---------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LogRows:
    """A drive log's rows as read from its file, before any check or grid: what :func:`grid_rows` brings onto the
    crank grid, once for every recording correction (channel delay, encoder offset) without reading the file again.

    ``data`` (rows, 4) in :data:`COLUMNS` order, NaN for an empty cell, the torque in ``torque_unit`` (read-only);
    ``lines`` (rows,) the 1-based line (or sample) number of each row; ``ignored`` extra header columns; ``notes``
    how another reader made the four columns (channel map, resampling), kept as warnings; ``data_key`` a digest of
    the data lines alone (comments left out): two files with the same ``data_key`` hold the same recording;
    ``file_sha256`` "sha256:<hex>" of the file's bytes as read (what a monitor result records); ``channel_map`` the map
    that made the columns of a trace, whose keys a unit or sign refusal names (None for a drive-log CSV).
    """

    source: str
    comments: tuple[str, ...]
    data: np.ndarray
    lines: np.ndarray
    ignored: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    torque_unit: str = "N*m"
    data_key: str = ""
    file_sha256: str = ""
    channel_map: object | None = None  # the ChannelMap that made the columns (calibration.traces.trace_log), None for a CSV
    force_N: np.ndarray | None = None  # (rows,) the process force column (N, NaN for an empty cell), None when not logged
    # (rows, M) each motor's own torque channel (in ``torque_unit``, NaN for an empty cell) where the log holds one per
    # motor (a CSV's motor_torque_Nm_1 ... _M, a map's list of torque channels; their mean is ``data``'s torque), named
    # by ``motor_channels``; None for one torque column (calibration/traces/motor_shares.py estimates the motors' shares)
    motor_torques: np.ndarray | None = None
    motor_channels: tuple[str, ...] = ()
    # s: the force column's lag behind the torque column, estimated (calibration/identification/force_delay.py): gridding
    # moves each force sample to the angle of its own time less the torque's delay correction and this; None: the force
    # is read on the angle channel's time, as logged
    force_lag_s: float | None = None

    def __post_init__(self):
        for arr in (self.data, self.lines, *(a for a in (self.force_N, self.motor_torques) if a is not None)):
            arr.flags.writeable = False  # gridded again for each correction: nothing may change the rows read


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def comments_and_header(lines: Sequence[str]) -> tuple[list[str], int | None]:
    """The ``#`` comment lines before the first other non-blank line (their text), and that line's index (the
    header row), None when there is none."""
    comments = []
    for i, line in enumerate(lines):
        s = line.strip()
        if s.startswith("#"):
            comments.append(s[1:].strip())
        elif s:
            return comments, i
    return comments, None


_NAN_CELLS = ["", "nan", "NaN", "NAN", "-nan", "+nan"]  # what float() reads as NaN, besides an empty cell


C_PARSER_ROWS = 50_000  # from this many lines pandas' parser pays for its import (below)


def _c_parser_pays(rows: int) -> bool:
    """Whether to read ``rows`` data lines with pandas' C parser (:func:`_c_rows`): where pandas is imported already,
    or from :data:`C_PARSER_ROWS` lines. Its import costs ~0.3 s of CPU, what the cell-by-cell reading spends on
    ~80,000 lines (7,900 lines, a 3-stroke calibration log, in 0.03 s): a calibration log is read faster without it."""
    return rows >= C_PARSER_ROWS or "pandas" in sys.modules


def _c_rows(lines: Sequence[str], header_at: int, names: list[str], order: list[int], force_at: int | None,
            motor_at: list[int]):
    """The data rows (rows, 4), their 1-based line numbers, the force column (or None), the motors' own torque columns
    (rows, M; None for one torque column, else their mean is the data's torque) and the digest's text, read by
    pandas' C parser as the cell-by-cell reading below gives them for a well-formed file (tests/test_drive_log.py
    compares the two); None where any line needs that reading (a blank or padded line, a comment, a cell count, a cell
    that is no number), which then skips or names it. A production log of 100 strokes at 500 Hz holds 220,000 rows:
    a tenth of a second here, seconds cell by cell; every check is on the whole text at once."""
    import pandas as pd

    rows = len(lines) - header_at - 1
    text = "\n".join(lines[header_at + 1:])
    padded = " " in text or "\t" in text or "\n\n" in text or text.startswith("\n")  # substring searches: C speed
    if rows == 0 or padded or text.count(",") != (len(names) - 1) * rows:
        return None
    wanted = sorted(set(order + motor_at + ([force_at] if force_at is not None else [])))
    try:  # a line with too many cells raises; the comma count leaves none with too few
        frame = pd.read_csv(io.StringIO(text), header=None, names=list(range(len(names))), usecols=wanted, dtype=float,
                            engine="c", keep_default_na=False, na_values=_NAN_CELLS, skip_blank_lines=False, comment=None)
    except (ValueError, pd.errors.ParserError):
        return None
    if len(frame) != rows:
        return None
    data = np.ascontiguousarray(frame[order].to_numpy(dtype=float)).reshape(-1, len(COLUMNS))
    forces = None if force_at is None else frame[force_at].to_numpy(dtype=float).copy()
    motors = None
    if motor_at:  # the torque per motor is the mean of the motors' own columns, summed in column order as below
        motors = np.ascontiguousarray(frame[motor_at].to_numpy(dtype=float))
        data[:, 3] = motors.sum(axis=1) / len(motor_at)
    return data, np.arange(header_at + 2, header_at + 2 + rows), forces, motors, lines[header_at].strip() + "\n" + text


def _parse(text: str, source: str, torque_unit: str = "N*m") -> LogRows:
    lines = text.removeprefix("\ufeff").splitlines()
    comments, header_at = comments_and_header(lines)
    if header_at is None:
        what = f"{len(comments)} comment lines and no data" if comments else "empty"
        raise PressDataError(source, "<file>", what, f"must hold the header line '{HEADER}' and the data rows below it")
    header = lines[header_at]
    for sep, called in ((";", "semicolon"), ("\t", "tab")):
        if header.count(sep) >= len(COLUMNS) - 1 and "," not in header:
            row = next((x for x in lines[header_at + 1:] if x.strip()), "")
            comma = " with decimal commas" if any(re.fullmatch(r"[-+]?\d*,\d+", c.strip()) for c in row.split(sep)) else ""
            raise PressDataError(source, f"header (line {header_at + 1})", header.strip()[:80].replace("\t", "\\t"),
                                 f"is {called}-separated{comma}; a drive log is comma-separated ('{HEADER}') with '.' as the "
                                 "decimal point: export it as CSV with ',' between cells and '.' in numbers (e.g. in a spreadsheet, "
                                 "set the list separator to ',' and the decimal separator to '.'), or read it as it is through a "
                                 "channel map (--log-format MAP.toml)")
    names = [c.strip() for c in header.split(",")]
    if _is_number(names[0]):
        raise PressDataError(source, f"line {header_at + 1}", lines[header_at].strip()[:80],
                             f"is data, but the header must come first: add the line '{HEADER}' above it")
    per_motor = _motor_columns(names, source, header_at)
    if per_motor:  # one torque column per motor: checked below as the one torque column they make
        names = [c if c not in per_motor else (TORQUE_COLUMN if c == per_motor[0] else _PER_MOTOR_READ + c) for c in names]
        # (motor 1's column stands for the torque column; the others are read beside it)
    extra = [c for c in names if c not in COLUMNS and c != FORCE_COLUMN and not c.startswith(_PER_MOTOR_READ)]
    if extra and set(COLUMNS) <= set(names) and len(set(names)) == len(names) and all(extra):
        ignored = tuple(extra)  # drives export more (current, bus voltage ...): read the four, say which were left
    else:
        ignored = ()
    core = [c for c in names if c != FORCE_COLUMN] if names.count(FORCE_COLUMN) == 1 else names
    core = [c for c in core if not c.startswith(_PER_MOTOR_READ)]
    if not ignored and (len(core) != len(COLUMNS) or set(core) != set(COLUMNS)):
        missing = [c for c in COLUMNS if c not in names]
        twice = sorted({c for c in names if names.count(c) > 1})
        unknown = [c for c in names if c not in COLUMNS and c not in twice and c != FORCE_COLUMN and not c.startswith(_PER_MOTOR_READ)]
        detail = "; ".join(p for p in (f"missing {', '.join(missing)}" if missing else "",
                                        f"unknown {', '.join(map(repr, unknown))}" if unknown else "",
                                        f"{', '.join(map(repr, twice))} named twice: keep one" if twice else "") if p)
        raise PressDataError(source, f"header (line {header_at + 1})", header.strip()[:200],  # as written, not as renamed
                             f"must name the four columns '{HEADER}' (any order; {detail}); "
                             "torque per motor in N m, motor speed in rpm at the motor shaft")
    order = [names.index(c) for c in COLUMNS]
    force_at = names.index(FORCE_COLUMN) if FORCE_COLUMN in names else None
    motor_at = [names.index(TORQUE_COLUMN), *(names.index(_PER_MOTOR_READ + c) for c in per_motor[1:])] if per_motor else []
    fast = _c_rows(lines, header_at, names, order, force_at, motor_at) if _c_parser_pays(len(lines) - header_at - 1) else None
    if fast is not None:
        data, numbers, forces, motors, body = fast
        return LogRows(source, tuple(comments), data, numbers, ignored, (), torque_unit, _digest(body.encode()), force_N=forces,
                       motor_torques=motors, motor_channels=tuple(per_motor))
    rows, numbers, forces, motors = [], [], [], []
    for i in range(header_at + 1, len(lines)):
        s = lines[i].strip()
        if not s:
            continue
        if s.startswith("#"):
            raise PressDataError(source, f"line {i + 1}", s[:80], "comments must come before the header line; move it up")
        cells = s.split(",")
        if len(cells) != len(names):
            raise PressDataError(source, f"line {i + 1}", s[:80], f"must hold {len(names)} comma-separated cells "
                                 f"({', '.join(names)}), not {len(cells)}; use '.' as the decimal point (a decimal "
                                 "comma splits a number in two)")
        vals = []
        for name, cell in zip(names, cells):
            if name not in COLUMNS and name != FORCE_COLUMN and not name.startswith(_PER_MOTOR_READ):
                vals.append(math.nan)
                continue
            c = cell.strip()
            if not c:
                vals.append(math.nan)
                continue
            try:
                vals.append(float(c))
            except ValueError:
                raise PressDataError(source, f"line {i + 1}, column {header.split(',')[len(vals)].strip()}", c[:40],
                                     "must be a number (use '.' as the decimal point; leave the cell empty or "
                                     "write nan for a missing value)") from None
        if motor_at:  # the torque per motor is the mean of the motors' own columns
            motors.append([vals[k] for k in motor_at])
            vals[motor_at[0]] = sum(motors[-1]) / len(motor_at)
        rows.append([vals[k] for k in order])
        if force_at is not None:
            forces.append(vals[force_at])
        numbers.append(i + 1)
    data = np.array(rows, dtype=float).reshape(-1, len(COLUMNS))
    body = "\n".join(s for s in (ln.strip() for ln in lines[header_at:]) if s)
    return LogRows(source, tuple(comments), data, np.array(numbers, dtype=int), ignored, (), torque_unit, _digest(body.encode()),
                   force_N=None if force_at is None else np.array(forces, dtype=float),
                   motor_torques=np.array(motors, dtype=float).reshape(-1, len(per_motor)) if per_motor else None,
                   motor_channels=tuple(per_motor))


def _motor_columns(names: list[str], source: str, header_at: int) -> list[str]:
    """The header's torque columns of one motor each (``motor_torque_Nm_1`` ... ``motor_torque_Nm_M``, in motor order),
    [] when it has none; refused beside a ``motor_torque_Nm`` column or with a motor missing from the numbering."""
    found = {int(m.group(1)): c for c in names if (m := re.fullmatch(rf"{TORQUE_COLUMN}_(\d+)", c))}
    if not found:
        return []
    if TORQUE_COLUMN in names:
        raise PressDataError(source, f"header (line {header_at + 1})", ", ".join(names)[:200], f"holds both {TORQUE_COLUMN} and "
                             f"one column per motor ({', '.join(found.values())}): keep the motors' own columns (their mean "
                             f"is the torque per motor), or only {TORQUE_COLUMN}")
    if sorted(found) != list(range(1, len(found) + 1)):
        raise PressDataError(source, f"header (line {header_at + 1})", ", ".join(found.values()), f"must number the motors "
                             f"1 to {len(found)} ({TORQUE_COLUMN}_1, {TORQUE_COLUMN}_2, ...), one column each")
    return [found[k] for k in sorted(found)]


def _digest(data: bytes) -> str:
    return "sha256:" + hashlib.sha256(data).hexdigest()


def _lines_txt(lines: np.ndarray) -> str:
    shown = ", ".join(str(int(x)) for x in lines[:_LISTED])
    return shown + (f" and {lines.size - _LISTED} more" if lines.size > _LISTED else "")


def _ranges_txt(deg: np.ndarray, step: float) -> str:
    """Contiguous runs of grid angles (deg) as 'a-b' text."""
    runs, start = [], deg[0]
    for prev, cur in zip(deg[:-1], deg[1:]):
        if cur - prev > 1.5 * step:
            runs.append((start, prev))
            start = cur
    runs.append((start, deg[-1]))
    txt = ", ".join(f"{a:g}" if a == b else f"{a:g}-{b:g}" for a, b in runs[:_LISTED])
    return txt + (f" and {len(runs) - _LISTED} more ranges" if len(runs) > _LISTED else "")


def _check_positive(source: str, field: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not math.isfinite(value) or value <= 0:
        raise PressDataError(source, field, value, "must be a positive finite number")
    return float(value)


def read_drive_log(path: str | Path, gear_ratio: float, rated_torque_Nm: float, step_deg: float = 1.0,
                   torque_unit: str = "N*m", settings=None, peak_torque_Nm: float | None = None,
                   correction: tuple[float, float] = (0.0, 0.0)) -> DriveLog:
    """Read a drive log and bring it onto the crank-angle grid; returns a :class:`DriveLog`
    (:func:`read_log_rows`, then :func:`grid_rows`).

    ``gear_ratio``: motor speed / crank speed (the press file's ``drive.gear_ratio``).
    ``rated_torque_Nm``: rated torque per motor, to recognise torque logged in kN m.
    ``torque_unit``: 'N*m' or 'kN*m' (the column is then multiplied by 1000).
    ``settings``: a :class:`DriveLogSettings`, the parsed drive_log.toml, or ``None`` for the shipped one.
    ``peak_torque_Nm``: the motor's peak torque T_max per motor; given, samples beyond it are named in a warning,
    and samples beyond ``glitch_torque_ratio_of_peak`` x T_max (no torque the motor made) are dropped with one.
    ``correction``: (channel delay in s, encoder offset in deg), a correction for a torque channel that lags the angle
    channel by that time (each torque sample moves to the crank angle of its time t - delay; samples before the log's start are dropped) and an encoder zero
    that reads that much high (subtracted from every angle); see :mod:`calibration.identification.recording`.
    Raises :class:`PressDataError` for input that cannot be repaired safely.
    """
    source = str(path)
    grid = _grid_args(source, gear_ratio, rated_torque_Nm, step_deg, settings, peak_torque_Nm)  # bad arguments before the file
    _check_unit(source, torque_unit)
    return _grid(read_log_rows(path, torque_unit), grid, correction)


def read_log_rows(path: str | Path, torque_unit: str = "N*m") -> LogRows:
    """The rows of the drive-log CSV ``path`` as read (:class:`LogRows`), the header and cells checked, nothing else;
    ``torque_unit`` ('N*m' or 'kN*m') is the unit of its torque column. :func:`grid_rows` brings them onto the grid."""
    source = str(path)
    _check_unit(source, torque_unit)
    p = Path(path)
    if not is_file(p):
        raise PressDataError(source, "<file>", source, "must be an existing drive-log CSV file")
    text, sha = read_text_with_digest(p, "<file>")
    return dataclasses.replace(_parse(text, source, torque_unit), file_sha256=sha)


def grid_rows(rows: LogRows, gear_ratio: float, rated_torque_Nm: float, step_deg: float = 1.0, settings=None,
              peak_torque_Nm: float | None = None, correction: tuple = (0.0, 0.0), force_steps_deg=()) -> DriveLog:
    """The drive log of ``rows`` (read once by :func:`read_log_rows` or :mod:`calibration.trace_log`) on the
    crank-angle grid, checked and repaired as :func:`read_drive_log` says; ``correction``: (channel delay in s,
    encoder offset in deg) the samples are corrected for, as there, and optionally third the lost motion in the gear
    (motor deg; the gear torque's curve on the grid, N m) they are corrected for (:func:`_lost_motion_corrected`);
    ``force_steps_deg``: crank angles (deg, the model's) where the process force steps, die contact first and BDC after
    it (:func:`press_model.kinematics.force_step_angles`'s order): a grid point whose two neighbouring samples lie on
    either side of a step takes the sample on its own side, one on the step the loaded side (:func:`_on_grid`)."""
    return _grid(rows, _grid_args(rows.source, gear_ratio, rated_torque_Nm, step_deg, settings, peak_torque_Nm),
                 correction[:2], force_steps_deg, correction[2] if len(correction) > 2 else None)


def columns_rows(source: str, comments: Sequence[str], data: np.ndarray, lines: np.ndarray, notes: Sequence[str],
                 file_sha256: str = "", channel_map=None, motors: tuple | None = None) -> LogRows:
    """:class:`LogRows` of columns another reader made (torque in N m), for :func:`grid_rows`; their
    ``data_key`` is the digest of the columns' values, ``file_sha256`` that of the file they were read from, and
    ``channel_map`` the map that made them; ``motors``: (rows, M) each motor's own torque (N m) and the M channels'
    names, where the torque column is their mean (None: one torque channel)."""
    arr = np.array(data, dtype=float)
    arr = arr.reshape(-1, arr.shape[-1] if arr.ndim == 2 and arr.shape[-1] == len(COLUMNS) + 1 else len(COLUMNS))
    force = arr[:, len(COLUMNS)].copy() if arr.shape[1] > len(COLUMNS) else None  # a mapped process force
    return LogRows(source, tuple(comments), np.ascontiguousarray(arr[:, :len(COLUMNS)]), np.array(lines, dtype=int), (),
                   tuple(notes), "N*m", _digest(np.ascontiguousarray(arr).tobytes()), file_sha256, channel_map, force,
                   *((np.array(motors[0], dtype=float), tuple(motors[1])) if motors is not None else ()))


def _check_unit(source: str, torque_unit) -> None:
    if not isinstance(torque_unit, str) or torque_unit not in TORQUE_UNITS:
        raise PressDataError(source, "torque_unit", torque_unit,
                             f"must be one of {', '.join(map(repr, TORQUE_UNITS))} (CLI --torque-unit)")


@dataclass(frozen=True)
class _GridSpec:
    """What a log's rows are gridded against, checked: drive_log.toml's settings, the gear ratio (motor / crank
    speed), the rated and peak torque per motor (N m; peak None: not checked) and the crank grid (rad)."""

    cfg: DriveLogSettings
    gear_ratio: float
    rated: float
    theta: np.ndarray
    peak: float | None


def _grid_args(source: str, gear_ratio, rated_torque_Nm, step_deg, settings, peak_torque_Nm) -> _GridSpec:
    """The :class:`_GridSpec` of the arguments, each checked (a bad one refused naming it)."""
    cfg = _settings(settings)
    gear_ratio = _check_positive(source, "gear_ratio", gear_ratio)
    rated = _check_positive(source, "rated_torque_Nm", rated_torque_Nm)
    peak = None if peak_torque_Nm is None else _check_positive(source, "peak_torque_Nm", peak_torque_Nm)
    return _GridSpec(cfg, gear_ratio, rated, crank_grid(step_deg), peak)


def _grid(rows: LogRows, grid: _GridSpec, correction, force_steps_deg=(), lost_motion=None) -> DriveLog:
    with np.errstate(all="ignore"):  # every non-finite intermediate is checked explicitly below
        return _grid_log(rows, grid, (float(correction[0]), float(correction[1])), tuple(force_steps_deg), lost_motion)


def check_against_model(log: DriveLog, predicted_Nm: np.ndarray, torque_unit: str = "N*m", settings=None) -> float:
    """Refuse a log whose torque does not fit the model's prediction in sign and scale, before any fitting.

    ``predicted_Nm``: the motor torque per motor of the theoretical parameters on the log's grid and crank motion.
    Returns the least-squares factor k of measured ~ k predicted; refused when k < 0 (the sign convention is the
    other way round) or outside ``[model]`` min/max_torque_scale of drive_log.toml (another unit, motor count or press):
    a fit would otherwise pull the parameters to their bounds and call it a calibration.
    """
    cfg = _settings(settings)
    pred = np.asarray(predicted_Nm, dtype=float)
    meas = log.torque
    ok = np.isfinite(pred) & np.isfinite(meas)
    denom = float(np.dot(pred[ok], pred[ok]))
    k = float(np.dot(pred[ok], meas[ok]) / denom) if denom > 0.0 else math.nan
    if not math.isfinite(k):
        return k
    shown = f"measured / predicted torque = {k:.3g}"
    if log.channel_map is not None and not cfg.min_torque_scale <= k <= cfg.max_torque_scale:
        raise log.channel_map.torque_refusal(log.source, k, cfg.min_torque_scale, cfg.max_torque_scale, log.rated_torque_Nm,
                                             lambda f: f"measured / predicted torque = {f:.3g}",
                                             f"it must lie in [{cfg.min_torque_scale:g}, {cfg.max_torque_scale:g}], drive_log.toml "
                                             "[model], against the model with the theoretical parameters")
    if k < 0.0:
        raise PressDataError(log.source, "motor_torque_Nm", shown, "is negative: the log's torque has the opposite sign to "
                             "the model's (positive = driving the crank forward); multiply the torque column by -1 (drives "
                             "differ in their sign convention) and run again")
    if not cfg.min_torque_scale <= k <= cfg.max_torque_scale:
        unit = (" If the log is in N m, drop --torque-unit kN*m." if torque_unit == "kN*m" and k > 100.0 else
                " If the log is in kN m, pass --torque-unit kN*m." if torque_unit == "N*m" and k < 0.01 else "")
        raise PressDataError(log.source, "motor_torque_Nm", shown,
                             f"must lie in [{cfg.min_torque_scale:g}, {cfg.max_torque_scale:g}] (drive_log.toml [model]): the "
                             "parameter ranges cannot move the torque that far, so the unit, the torque per motor (not "
                             f"summed over the motors) or the press file does not fit this log.{unit}")
    return k


def _need_rows(source: str, cfg: DriveLogSettings, rows: int, why: str) -> None:
    if rows < cfg.min_rows:
        raise PressDataError(source, "rows", rows, f"a drive log needs at least {cfg.min_rows} data rows{why}")


def _grid_log(table: LogRows, grid: _GridSpec, correction: tuple[float, float] = (0.0, 0.0), force_steps_deg=(),
              lost_motion=None) -> DriveLog:
    source, torque_unit, channel_map = table.source, table.torque_unit, table.channel_map
    cfg, gear_ratio, rated, theta, peak = grid.cfg, grid.gear_ratio, grid.rated, grid.theta, grid.peak
    warnings: list[str] = list(table.notes)
    if table.ignored:
        forces = [c for c in table.ignored if "force" in c.lower()]
        warnings.append(f"Ignored {len(table.ignored)} extra column{'s' if len(table.ignored) > 1 else ''} "
                        f"({', '.join(map(repr, table.ignored))}); calibration reads {HEADER}"
                        + (f", and a logged process force only as {FORCE_COLUMN} (in N): rename {', '.join(map(repr, forces))} "
                           f"to {FORCE_COLUMN}, converted to N, to calibrate with the logged force instead of the job's"
                           if forces and table.force_N is None else "") + ".")
    data, lines, descents = _clean_rows(table, source, cfg, rated, torque_unit, warnings, peak, channel_map)
    samples = data.copy()
    samples.flags.writeable = False
    t, angle, speed, torque = data.T
    angle = angle - correction[1]  # an encoder reading high by the offset
    u, missing, median_dt = _unwrap(table, grid, (t, angle, speed), lines, descents, warnings)
    u_speed, missing_speed = u, missing  # the speed channel is the angle's: a torque-channel delay leaves it where it is
    rates = np.maximum(speed[[0, -1]], 0.0) / gear_ratio * _RPM_TO_DEG_S  # deg/s at the log's ends
    rates = (float(rates[0]), float(rates[1]))
    u_force = u_speed  # the force read against the torque channel where its lag is known: moved with the torque, and by it
    if table.force_lag_s is not None and correction[0] + table.force_lag_s:
        u_force = _delayed(t, u_speed, torque, missing_speed, correction[0] + table.force_lag_s, rates)[0]
    if correction[0]:
        u, torque, missing = _delayed(t, u, torque, missing, correction[0], rates)
    if lost_motion is not None and lost_motion[0]:
        u, torque, missing = _lost_motion_corrected(u, torque, missing, lost_motion[0] / gear_ratio, lost_motion[1])

    covered = float(u[-1] - u[0])
    if covered < 360.0:
        raise PressDataError(source, "crank_angle_deg", f"{covered:.4g} deg of rotation",
                             f"the log covers only {covered:.4g} deg (from {np.mod(u[0], 360.0):.4g} to "
                             f"{np.mod(u[-1], 360.0):.4g} deg): calibration needs at least one full turn (360 deg); "
                             "log at least one whole stroke")

    grid_deg = np.arange(theta.size) * (360.0 / theta.size)  # exact in deg, where the samples are
    # Every interval between samples spans less than a turn (regular steps < 180 deg, bridged gaps less than
    # max_interpolated_gap_deg), so only the turns that hold a sample, or the reach beyond an end sample, can hold data:
    # a long gap adds no rows.
    turns = np.unique(np.floor(np.concatenate((u, _reach(u, missing), _reach(u_speed, missing_speed))) / 360.0))
    x = (360.0 * turns[:, None] + grid_deg[None, :]).ravel()
    stroke_torque = _on_grid(u, torque, x, missing, force_steps_deg).reshape(turns.size, -1)
    stroke_speed = _on_grid(u_speed, speed, x, missing_speed).reshape(turns.size, -1) / gear_ratio * _RPM_TO_RAD_S
    has_data = ~np.all(np.isnan(stroke_torque), axis=1)  # a turn inside one long gap holds nothing
    stroke_torque, stroke_speed = stroke_torque[has_data], stroke_speed[has_data]

    count = np.sum(~np.isnan(stroke_torque), axis=0)
    if np.any(count == 0):
        step_deg = float(grid_deg[1] - grid_deg[0])
        raise PressDataError(source, "crank_angle_deg", f"no data at {_ranges_txt(grid_deg[count == 0], step_deg)} deg",
                             "every crank angle of the turn needs data from at least one turn, but these fall inside "
                             "gaps in time in every turn: log more strokes or a log without these gaps")

    stroke_force, force_binned, force_turns = _force_on_grid(table, lines, u_force, missing_speed, x, turns.size, force_steps_deg)
    if stroke_force is not None:
        stroke_force = stroke_force[has_data]
    mean, spread = _mean_spread(stroke_torque, count)
    # the speed over its own strokes: a delay correction moves the torque samples along the angle, not the speed's
    speed_mean, speed_spread = _mean_spread(stroke_speed, np.sum(~np.isnan(stroke_speed), axis=0))
    synthetic_notes = [c for c in table.comments if "synthetic" in c.lower()]
    out = dict(theta=theta, torque=mean, torque_spread=spread, stroke_torque=stroke_torque, crank_speed=speed_mean,
               crank_speed_spread=speed_spread,
               speed_samples=np.column_stack([t, np.radians(u_speed), speed / gear_ratio * _RPM_TO_RAD_S]),
               torque_angles=np.radians(u), stroke_torque_binned=_binned_turns(u, torque, grid_deg.size)[0],
               **dict(zip(("torque_binned", "angle_binned_offset"), _binned(u, torque, grid_deg.size))))
    for arr in (*out.values(), *(() if stroke_force is None else (stroke_force, force_binned, *force_turns))):
        arr.flags.writeable = False
    return DriveLog(
        source=source,
        synthetic=bool(synthetic_notes),
        label=synthetic_notes[0] if synthetic_notes else "",
        comments=table.comments,
        # every crank angle seen this often: a log that starts mid-turn holds its strokes across the turns' boundaries
        strokes=int(np.min(count)),
        sample_rate_hz=1.0 / median_dt,
        rotation_deg=covered,
        gear_ratio=gear_ratio,
        torque_unit=torque_unit,
        warnings=tuple(warnings),
        channel_map=channel_map,
        rated_torque_Nm=rated,
        samples=samples,
        stroke_force=stroke_force,
        force_binned=force_binned,
        stroke_force_binned=None if force_turns is None else force_turns[0],
        stroke_force_counts=None if force_turns is None else force_turns[1],
        **out,
    )


def _force_on_grid(table: LogRows, lines: np.ndarray, u: np.ndarray, missing: np.ndarray, x: np.ndarray,
                   turns: int, steps_deg=()) -> tuple[np.ndarray | None, np.ndarray | None, tuple | None]:
    """The process force column of the rows kept (``lines``, unwrapped angles ``u`` deg), from its finite samples:
    (turns, n) N on the grid angles ``x``, (n,) N its bin means (:attr:`DriveLog.force_binned`) and each turn's bin
    means and counts (:func:`_binned_turns`); (None, None, None) when the log has no force column. A grid point beside
    or on a force step (``steps_deg``) takes the side the torque's takes (:func:`_on_grid`): read across the step, die
    contact 0.03 deg before a grid point of a 40-spm SYNTHETIC run left that point a quarter of the force, the model's
    force snapped it unloaded while the torque was loaded, and eta_gear came out 2.5 % low (linearised, noise-free log)."""
    if table.force_N is None:
        return None, None, None
    n = x.size // max(turns, 1)
    pos = np.searchsorted(table.lines, lines)  # the rows' line numbers rise through the file
    force = table.force_N[np.clip(pos, 0, table.lines.size - 1)]
    ok = np.isfinite(force)
    bound = run_limits().max_process_force_N
    beyond = np.flatnonzero(ok & (np.abs(force) > bound))
    if beyond.size:  # a glitch or another unit: 1e308 overflowed the force's noise estimate and was blamed on its timing
        i = int(beyond[0])
        raise PressDataError(table.source, f"line {int(lines[i])}, column {FORCE_COLUMN}", float(force[i]),
                             f"must be at most {bound:g} N in magnitude (max_process_force_N in {LIMITS_FILE}, far above any "
                             f"press's force; {beyond.size} row{'s' if beyond.size > 1 else ''} beyond it): fix the cell, or "
                             "leave it empty (a missing value)")
    if ok.sum() < 2:
        return np.full((turns, n), np.nan), np.full(n, np.nan), (np.full((1, n), np.nan), np.zeros((1, n), np.int64))
    idx = np.flatnonzero(ok)
    gaps = np.concatenate(([0], np.cumsum(missing)))  # an interval between kept samples is a gap if any step inside was
    on_grid = _on_grid(u[idx], force[idx], x, np.append(gaps[idx[1:]] - gaps[idx[:-1]] > 0, False), steps_deg).reshape(turns, -1)
    return on_grid, _binned(u[idx], force[idx], n)[0], _binned_turns(u[idx], force[idx], n)


def _binned_turns(u: np.ndarray, values: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(T, n) the mean of ``values`` over the samples of each turn whose angle ``u`` (unwrapped deg) rounds to each of
    the n grid points (NaN where none), and (T, n) their counts; the bins of :func:`_binned`, split by turn (a sample
    rounding to 360 deg opens the next turn's bin 0)."""
    k = np.rint(u / (360.0 / n)).astype(np.int64)
    turn = k // n
    row = turn - turn.min()
    T = int(row.max()) + 1
    flat = row * n + np.mod(k, n)
    count = np.bincount(flat, minlength=T * n).reshape(T, n)
    total = np.bincount(flat, values, minlength=T * n).reshape(T, n)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan), count


def _delayed(t: np.ndarray, u: np.ndarray, torque: np.ndarray, missing: np.ndarray, delay_s: float,
             rates: tuple[float, float]):
    """The torque samples (time-sorted, ``u`` unwrapped deg) corrected for a torque channel ``delay_s`` behind the
    angle: each keeps its value and moves to the angle of its own time, t - delay, by linear interpolation in the
    smooth angle channel; a sample whose t - delay lies before the log's first row (or, for a negative delay, after
    its last) takes the first (last) angle moved on at ``rates`` (deg/s, the crank rates of the first and the last
    row's speed column) for the time it lies beyond. Returns (u, torque, missing) as :func:`_unwrap` gives them.

    The angle axis moves, not the torque: reading the torque between two samples (at t + delay) averages their noise,
    by up to half its variance at half a sample, so a corrected log would fit better for its smoothing alone and
    its statistics would see other noise than the log's (calibration/identification/recording.py). Moved, the samples are put on the
    grid as an uncorrected log's are, with the same noise. None is dropped: dropping the samples before the log's first
    angle shortened the torque's coverage by the delay's rotation, and a log of three turns then read as two strokes;
    held at the last angle, the samples of a negative delay past the log's end piled up there."""
    ts = t - delay_s
    moved = np.where(ts < t[0], u[0] + rates[0] * (ts - t[0]), np.where(ts > t[-1], u[-1] + rates[1] * (ts - t[-1]), 0.0))
    return np.where((ts >= t[0]) & (ts <= t[-1]), np.interp(ts, t, u), moved), torque, missing


def _lost_motion_corrected(u: np.ndarray, torque: np.ndarray, missing: np.ndarray, gap_deg: float, curve: np.ndarray):
    """The torque samples (``u`` unwrapped deg, the motor's angle over the gear ratio) moved to the crank angle they
    were made at with a lost motion of ``gap_deg`` (crank deg) in the gear: the crank lags the motor by half the gap
    while the gear torque drives and leads it by as much while it brakes, so each sample moves by -sgn(T) gap / 2, T
    the gear torque's curve ``curve`` (N m on the uniform grid of a turn, the model's) read at the sample's angle.
    Where the torque goes from braking to driving the moved samples overlap (the torque of a few hundredths of a
    degree logged twice while the motor crossed the gap), so they are sorted by angle, each keeping its value: the
    angle axis moves, not the torque, as with the delay (:func:`_delayed`). Returns (u, torque, missing);
    ``missing`` (one shorter: the intervals) follows the sample that opens each interval."""
    n = len(curve)
    k = np.mod(np.rint(u / (360.0 / n)).astype(np.int64), n)
    moved = u - 0.5 * gap_deg * np.sign(np.asarray(curve, float))[k]
    order = np.argsort(moved, kind="stable")
    return moved[order], torque[order], np.append(missing, False)[order][:-1]


def _binned(u: np.ndarray, torque: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(n,) the mean torque (N m) of all samples whose angle ``u`` (unwrapped deg) rounds to each of the n grid points
    of a turn, over every turn, NaN where no sample falls (:attr:`DriveLog.torque_binned`); and (n,) the mean of
    their angle less the grid point (rad, 0 where none; :attr:`DriveLog.angle_binned_offset`)."""
    step = 360.0 / n
    k = np.rint(u / step)
    idx = np.mod(k.astype(np.int64), n)
    count = np.bincount(idx, minlength=n)
    total = np.bincount(idx, torque, minlength=n)
    off = np.bincount(idx, np.radians(u - k * step), minlength=n)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan), off / np.maximum(count, 1)


def _clean_rows(table: LogRows, source: str, cfg: DriveLogSettings, rated: float, torque_unit: str,
                warnings: list[str], t_max: float | None = None, channel_map=None) -> tuple[np.ndarray, np.ndarray, int]:
    """Rows in time order, with torque in N m: drops non-finite and duplicated rows, and (given the motor's peak
    torque ``t_max``) rows whose torque no motor of this press made (with a warning each).

    Returns the data (rows, 4), their line numbers, and how many rows were out of time order (sorted here;
    :func:`_unwrap` refuses the sort if it does not give a forward-turning crank).
    """
    data, lines = table.data, table.lines
    _need_rows(source, cfg, len(data), "")
    finite = np.all(np.isfinite(data), axis=1)
    if not finite.all():
        bad = lines[~finite]
        warnings.append(f"Dropped {bad.size} row{'s' if bad.size > 1 else ''} with an empty, NaN or infinite cell "
                        f"(line {_lines_txt(bad)}); the crank angles they held are treated as gaps.")
        data, lines = data[finite], lines[finite]
        _need_rows(source, cfg, len(data), f" with four finite values ({bad.size} rows had an empty, NaN or infinite cell)")

    far = np.abs(data[:, 1]) > cfg.max_crank_angle_deg
    if far.any():
        i = int(np.argmax(far))
        raise PressDataError(source, f"line {lines[i]}, crank_angle_deg", float(data[i, 1]),
                             f"must lie within +-{cfg.max_crank_angle_deg:g} deg (drive_log.toml [check] max_crank_angle_deg): "
                             "no log turns the crank that far, so the cell is corrupt; remove or fix the row")
    data = data.copy()
    data[:, 3] *= TORQUE_UNITS[torque_unit]
    if t_max is not None:
        data, lines = _torque_beyond_peak(data, lines, source, cfg, t_max, warnings)
    peak = float(np.max(np.abs(data[:, 3])))
    if not math.isfinite(peak):
        raise PressDataError(source, "motor_torque_Nm", peak, "must be finite in N m after unit conversion")
    if peak == 0.0:
        raise PressDataError(source, "motor_torque_Nm", 0.0, "is 0 in every row: the column holds no torque (a drive "
                             "channel not logged, or the wrong column exported); log the motor torque per motor in N m")
    if peak < cfg.min_torque_fraction_of_rated * rated:
        limit = f"{cfg.min_torque_fraction_of_rated:g} x the rated torque {rated:g} N m"
        if channel_map is not None:  # the map's unit, not the log, is the suspect (and --torque-unit is refused beside a map)
            top = cfg.glitch_torque_ratio_of_peak * (t_max if t_max is not None else rated)
            raise channel_map.torque_refusal(source, peak / rated, cfg.min_torque_fraction_of_rated, top / rated, rated,
                                             lambda k: f"max |torque| {k * rated:.4g} N m", f"it must reach {limit}")
        hint = ("looks like kN m; multiply by 1000 or pass torque_unit='kN*m' (CLI --torque-unit kN*m)"
                if torque_unit == "N*m" else "is too small even in kN m: check the column holds motor torque per motor")
        raise PressDataError(source, "motor_torque_Nm", f"max |torque| {peak:.4g} N m", f"must reach {limit}; {hint}")

    t = data[:, 0]
    descents = int(np.count_nonzero(np.diff(t) < 0))
    if descents:
        order = np.argsort(t, kind="stable")
        data, lines, t = data[order], lines[order], t[order]

    same = np.diff(t) == 0
    if same.any():
        identical = same & np.all(data[1:] == data[:-1], axis=1)
        clash = same & ~identical
        if clash.any():
            i = int(np.argmax(clash))
            raise PressDataError(source, f"lines {lines[i]} and {lines[i + 1]}", f"time_s = {float(t[i])!r} twice",
                                 "two rows with the same time must be identical (then one is dropped); with "
                                 "different values it is unknown which one the drive logged: remove the wrong row")
        keep = np.concatenate(([True], ~identical))
        warnings.append(f"Dropped {int(identical.sum())} duplicated row{'s' if identical.sum() > 1 else ''} "
                        f"(line {_lines_txt(lines[1:][identical])}) identical to the row before.")
        data, lines, t = data[keep], lines[keep], data[keep, 0]
        _need_rows(source, cfg, len(data), " after dropping duplicated rows")

    return data, lines, descents


def _torque_beyond_peak(data: np.ndarray, lines: np.ndarray, source: str, cfg: DriveLogSettings, t_max: float,
                        warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Drop rows whose |torque| exceeds glitch_torque_ratio_of_peak x T_max (a logging glitch: the drive's current
    limit keeps the motor near T_max, and one such sample would otherwise pass between the grid points unseen or
    pull the stroke average by orders of magnitude), and name the rows above T_max that stay."""
    mag = np.abs(data[:, 3])
    glitch = mag > cfg.glitch_torque_ratio_of_peak * t_max
    # glitches are single samples; a log beyond the peak throughout is in another unit or of another press, which
    # the sign and scale check against the model (check_against_model) names as such
    if glitch.any() and glitch.sum() <= _GLITCH_SHARE * len(data):
        worst = int(np.argmax(mag))
        warnings.append(f"Dropped {int(glitch.sum())} row{'s' if glitch.sum() > 1 else ''} whose torque is beyond "
                        f"{cfg.glitch_torque_ratio_of_peak:g} x the motor's peak torque T_max = {t_max:g} N m (line "
                        f"{_lines_txt(lines[glitch])}, up to {data[worst, 3]:.4g} N m): a logging glitch, no torque the "
                        "motor made; the crank angles they held are treated as gaps.")
        data, lines, mag = data[~glitch], lines[~glitch], mag[~glitch]
        _need_rows(source, cfg, len(data), f" with a plausible torque ({int(glitch.sum())} rows were beyond the motor's peak)")
    above = mag > t_max
    if above.any():
        warnings.append(f"The torque exceeds the motor's peak torque T_max = {t_max:g} N m (press file [motor]) in "
                        f"{int(above.sum())} row{'s' if above.sum() > 1 else ''} (line {_lines_txt(lines[above])}, up to "
                        f"{float(mag.max()):.5g} N m): the drive limits the motor to T_max, so check the log's unit and "
                        "that the press file is this press's.")
    return data, lines


def _unwrap(table: LogRows, grid: _GridSpec, columns: tuple[np.ndarray, np.ndarray, np.ndarray], lines: np.ndarray,
            descents: int, warnings: list[str]):
    """The unwrapped crank angle (deg, non-decreasing) of every row, after checking it against time and speed;
    ``columns``: (time s, crank angle deg, motor speed rpm) of the rows of ``table`` kept.

    Returns ``(u, missing, median_dt)``: ``missing[i]`` flags the step from row i to i + 1 as a gap in time
    too wide to bridge, and ``median_dt`` (s) is the regular sampling interval.
    """
    source, channel_map, cfg, gear_ratio = table.source, table.channel_map, grid.cfg, grid.gear_ratio
    t, angle, speed = columns
    dt = np.diff(t)
    d = np.diff(angle)
    if not (np.all(np.isfinite(dt)) and np.all(np.isfinite(d))):
        field = "time_s" if not np.all(np.isfinite(dt)) else "crank_angle_deg"
        raise PressDataError(source, field, "differences overflow", "must hold values of a realistic size (s, deg)")
    median_dt = float(np.median(dt))
    gap = dt > cfg.gap_factor * median_dt
    step = (d + 180.0) % 360.0 - 180.0  # between regular samples the crank turns far less than half a turn

    # A crank that falls back (reverse running, encoder trouble, or shuffled rows) cannot be put on one grid.
    implied = 0.5 * (speed[1:] + speed[:-1]) / gear_ratio * _RPM_TO_DEG_S  # crank rate the speed column gives, deg/s
    if channel_map is not None:  # a wrong unit of the map's angle scrambles the wraps: the speed check names the map's key
        _check_speed(source, cfg, gear_ratio, step / dt, implied, gap, channel_map)
    pre = np.concatenate(([0.0], np.cumsum(np.where(gap, 0.0, step))))
    _refuse_backward(source, cfg, pre, angle, t, lines, descents)
    if descents:
        warnings.append(f"Sorted the rows by time_s ({descents} were out of order); sorted, the crank angle turns forward.")
    if channel_map is None:
        _check_speed(source, cfg, gear_ratio, step / dt, implied, gap)

    # Across a gap the crank may have turned by more than half a turn: the motor speed gives the whole turns.
    expected = implied * dt
    across = np.mod(d, 360.0)
    across = across + 360.0 * np.round((expected - across) / 360.0)
    rotation = np.where(gap, across, step)
    jump = np.abs(rotation - expected) > cfg.angle_jump_relative * np.abs(expected) + cfg.angle_jump_floor_deg
    if jump.any():
        i = int(np.argmax(jump))
        pair = f"{lines[i]}-{lines[i + 1]}" if lines[i + 1] == lines[i] + 1 else f"{lines[i]} and {lines[i + 1]}"  # sorted rows
        raise PressDataError(source, f"lines {pair}, crank_angle_deg",
                             f"{angle[i]:g} -> {angle[i + 1]:g}",
                             f"the crank turns {rotation[i]:.4g} deg in {dt[i]:.4g} s where the motor speed implies "
                             f"{expected[i]:.4g} deg: an encoder jump, a mis-wrapped angle or a wrong motor_speed_rpm "
                             "in these rows; remove or fix them")

    far = gap & (np.abs(rotation) > 360.0 * cfg.max_gap_turns)
    if far.any():
        i = int(np.argmax(far))
        raise PressDataError(source, f"lines {lines[i]} and {lines[i + 1]}, time_s", f"{t[i]:.6g} -> {t[i + 1]:.6g} s",
                             f"jumps by {dt[i]:.4g} s (the log's step is {median_dt:.4g} s), in which the motor speed implies "
                             f"{rotation[i] / 360.0:.4g} crank turns, more than the {cfg.max_gap_turns:g} a log may skip "
                             "(drive_log.toml [check] max_gap_turns): a corrupt time stamp, or two recordings in one file; "
                             "fix the time or split the log")
    u = np.mod(angle[0], 360.0) + np.concatenate(([0.0], np.cumsum(rotation)))
    _refuse_backward(source, cfg, u, angle, t, lines, descents)
    held = np.maximum.accumulate(u) - u
    if held.max() > 0.0:
        k = int(np.count_nonzero(held > 0.0))
        warnings.append(f"Held {k} sample{'s' if k > 1 else ''} whose crank angle fell back by at most "
                        f"{held.max():.3g} deg (encoder jitter) at the highest angle reached before "
                        f"{'them' if k > 1 else 'it'}.")
        u = u + held

    bridged = gap & (rotation <= cfg.max_interpolated_gap_deg)
    missing = gap & ~bridged
    if bridged.any():
        i = int(np.argmax(np.where(bridged, dt, -1.0)))
        warnings.append(f"Bridged {int(bridged.sum())} gap{'s' if bridged.sum() > 1 else ''} in time (time step "
                        f"> {cfg.gap_factor:g} x the median {median_dt:.4g} s; longest {dt[i]:.4g} s after line "
                        f"{lines[i]}) by linear interpolation: each spans at most {cfg.max_interpolated_gap_deg:g} "
                        f"deg of crank rotation.")
    if missing.any():
        idx = np.flatnonzero(missing)
        spans = "; ".join(f"t = {t[i]:.6g}-{t[i + 1]:.6g} s, crank {np.mod(u[i], 360.0):.4g}-"
                          f"{np.mod(u[i + 1], 360.0):.4g} deg" for i in idx[:_LISTED])
        more = f" and {idx.size - _LISTED} more" if idx.size > _LISTED else ""
        warnings.append(f"{idx.size} gap{'s' if idx.size > 1 else ''} in time span{'' if idx.size > 1 else 's'} more "
                        f"than {cfg.max_interpolated_gap_deg:g} deg of crank rotation ({spans}{more}): the grid points "
                        f"inside have no data (NaN) in that turn; the rotation across each comes from the motor speed.")

    return u, missing, median_dt


def _refuse_backward(source: str, cfg: DriveLogSettings, u: np.ndarray, angle: np.ndarray, t: np.ndarray,
                     lines: np.ndarray, descents: int) -> None:
    """Refuse a crank angle ``u`` (unwrapped, deg) that falls further than the tolerance below its running maximum."""
    back = np.maximum.accumulate(u) - u
    if back.max() <= cfg.backward_tolerance_deg:
        return
    i = int(np.argmax(back > cfg.backward_tolerance_deg))
    where = f"line {lines[i]}, crank_angle_deg"
    if descents:
        raise PressDataError(source, where, float(angle[i]),
                             f"{descents} rows are out of time order, and sorted by time_s the crank angle falls back "
                             f"by {back[i]:.4g} deg here: the time stamps do not fit the angles; fix the time_s column")
    raise PressDataError(source, where, float(angle[i]),
                         f"falls {back[i]:.4g} deg below the angle reached before (t = {t[i]:.6g} s); the crank must "
                         "turn forward (reverse running, an encoder jump or a mis-wired encoder cannot be calibrated)")


def _check_speed(source: str, cfg: DriveLogSettings, gear_ratio: float, measured: np.ndarray,
                 implied: np.ndarray, gap: np.ndarray, channel_map=None) -> None:
    """Refuse a speed column that disagrees with the crank angle's time derivative (both in deg/s)."""
    # the top speed of the run, robust to a single absurd sample (1e300 rpm in one row once made every other row
    # "too slow to compare" and the check blamed the whole column's unit); such a row is named by the jump check
    top = float(np.quantile(np.abs(implied), 0.99)) or float(np.max(np.abs(implied)))
    if top == 0.0:
        raise PressDataError(source, "motor_speed_rpm", 0.0, "is 0 in every row while the log must cover a turning "
                             "crank; the column must hold the motor speed in rpm")
    use = ~gap & (np.abs(implied) >= cfg.speed_floor_fraction_of_max * top)
    if not use.any():
        raise PressDataError(source, "motor_speed_rpm", "no usable rows",
                             "too few regular samples with the motor turning to check the speed against the crank angle")
    ratio = float(np.median(measured[use] / implied[use]))
    if not (math.isfinite(ratio) and abs(ratio - 1.0) <= cfg.speed_mismatch_tolerance):
        if channel_map is not None:
            raise channel_map.speed_refusal(source, ratio, gear_ratio, cfg.speed_mismatch_tolerance)
        fit = f"; this log fits a gear ratio of {gear_ratio / ratio:.4g}" if math.isfinite(ratio) and ratio > 0 else ""
        raise PressDataError(
            source, "motor_speed_rpm", f"crank angle rate / (speed / gear_ratio) = {ratio:.4g}",
            f"must be 1 within {cfg.speed_mismatch_tolerance:g}. Near {gear_ratio:.4g} (the gear ratio) the column holds "
            f"crank rpm instead of motor rpm; near {60.0 / (2.0 * math.pi):.4g} it holds rad/s instead of rpm; near -1 the "
            f"speed sign is flipped (or the crank runs in reverse); otherwise check gear_ratio = {gear_ratio:g}{fit}")


def _on_grid(u: np.ndarray, values: np.ndarray, x: np.ndarray, missing: np.ndarray, steps_deg=()) -> np.ndarray:
    """Linear interpolation of samples ``values`` at non-decreasing angles ``u`` to the angles ``x`` (deg).

    NaN outside :func:`_reach` (the samples' span and half a sample step beyond each end) and strictly inside an interval
    flagged in ``missing`` (a gap too long to bridge). Within half a step beyond an end sample the line through the two
    end samples is extended: the samples stand for their own steps, so N samples cover N steps of rotation, not N - 1,
    and a log of exactly three turns of samples covers every crank angle three times whatever angle it starts at
    (within the samples' span alone, the grid point a hair before the first sample went missing, and the log read as two
    strokes whenever the recording correction moved its first sample past a grid point).
    Where a process-force step (``steps_deg``, deg, every turn) lies strictly between the two samples around a grid
    point, interpolating would mix the torque of both sides of the step, which the model at that point never has (at
    die contact it put 1.7 kN m into the grid point before contact and pulled J_gear 2 % low on a noise-free SYNTHETIC
    log): the point takes the sample on its own side of the step instead, at most one sample step away; beyond an end
    sample with a step between them the point has no sample on its side and stays NaN. A grid point on the step's own
    angle takes the loaded side, as Eq. 14 counts that angle loaded (H <= H_p, the slide moving down or standing) and so
    the model has it: after the first step (die contact, the force comes on), before the others (BDC, it goes off),
    extrapolated to the step from the two samples there. (The crank-slider's BDC lies on the 180-deg grid point; taking
    the side after it, or either side by the rounding of the unwrapped angle, left out the cushion's bearing friction
    there, 99 N m, and pulled eta_gear 1.6 % and mu_s 46 % low on a noise-free SYNTHETIC log.)
    """
    j = np.clip(np.searchsorted(u, x, side="right") - 1, 0, u.size - 2)
    du = u[j + 1] - u[j]
    lo, hi = _reach(u, missing)
    inside = (x >= u[0]) & (x <= u[-1])
    frac = np.where(du > 0.0, (x - u[j]) / np.where(du > 0.0, du, 1.0), 0.0)
    frac = np.where(inside, np.clip(frac, 0.0, 1.0), frac)  # beyond an end: the end pair's line extended
    edge = []  # (points on a step, the sample on its loaded side, the next one away from the step)
    for i, s in enumerate(steps_deg):
        first = u[j] + np.mod(s - u[j], 360.0)  # the step's first angle after the left sample
        across = inside & (first > u[j]) & (first < u[j + 1])
        on = across & (np.abs(x - first) <= _SAME_ANGLE_DEG)
        frac = np.where(across, np.where(on, 1.0 if i == 0 else 0.0, np.where(x < first, 0.0, 1.0)), frac)
        near, far = (j + 1, j + 2) if i == 0 else (j, j - 1)
        ok = on & (far >= 0) & (far < u.size)
        ok[ok] &= ~missing[np.minimum(near, far)[ok]] & (u[near[ok]] != u[far[ok]])
        edge.append((ok, near, far))
    out = values[j] + frac * (values[j + 1] - values[j])
    for ok, near, far in edge:
        # on the step, the loaded side's own limit: the line through its two nearest samples (the nearest alone sits up to
        # a sample step away, 0.14 deg on the crank-slider's BDC, where the cushion's work moves the torque 44 N m per deg)
        a, b = near[ok], far[ok]
        out[ok] = values[a] + (x[ok] - u[a]) * (values[a] - values[b]) / (u[a] - u[b])
    inside_gap = missing[j] & (x > u[j]) & (x < u[j + 1])
    stepped = np.zeros(x.shape, dtype=bool)
    for s in steps_deg:  # a step between an end sample and the point beyond it: the sample is of the other side
        ahead = x + np.mod(s - x, 360.0)  # the step's first angle at or after the point
        behind = u[-1] + np.mod(s - u[-1], 360.0)  # ... after the last sample
        stepped |= ((x < u[0]) & (ahead > x) & (ahead < u[0])) | ((x > u[-1]) & (behind > u[-1]) & (behind <= x))
    out[(x < lo) | (x > hi) | inside_gap | stepped] = np.nan
    return out


def _reach(u: np.ndarray, missing: np.ndarray) -> tuple[float, float]:
    """(deg, deg) the crank angles the samples at non-decreasing angles ``u`` stand for: their span and half the end
    step beyond each end (the nearest sample's half-way point to the one that was not logged), none beyond an end
    whose step is a gap too long to bridge (``missing``)."""
    before = 0.0 if missing[0] else 0.5 * float(u[1] - u[0])
    after = 0.0 if missing[u.size - 2] else 0.5 * float(u[-1] - u[-2])
    return float(u[0]) - before, float(u[-1]) + after


def _mean_spread(curves: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean over rows ignoring NaN, and the sample standard deviation (NaN where fewer than two values)."""
    valid = ~np.isnan(curves)
    top = float(np.max(np.abs(curves[valid]), initial=0.0))
    # computed on the values divided by a power of two at or below the largest (2**e of 2**1024 itself would
    # overflow): exact, and the sums and squares of finite values of any size cannot overflow
    scale = math.ldexp(1.0, math.frexp(top)[1] - 1) if 0.0 < top < math.inf else 1.0
    c = curves / scale
    mean = np.where(valid, c, 0.0).sum(axis=0) / count
    dev2 = np.where(valid, (c - mean) ** 2, 0.0).sum(axis=0)
    spread = np.where(count > 1, np.sqrt(dev2 / np.maximum(count - 1, 1)), np.nan)
    return mean * scale, spread * scale
