"""A drive trace read through its channel map: the four columns of a drive log, then the same checks and grid.

:func:`read_trace_log` reads the trace (:func:`calibration.traces.trace_formats.read_trace`), finds the mapped channels
(:mod:`calibration.traces.channel_map`), brings them onto one time base and into the drive log's units, and hands the
columns (:func:`calibration.traces.drive_log.columns_rows`) to :func:`calibration.traces.drive_log.grid_rows`, which
checks and grids them exactly as it does a plain drive-log CSV. So a trace and the CSV of the same samples give the same :class:`DriveLog`.

The time base is the crank angle channel's own samples: the angle wraps, and interpolating across a wrap would
invent angles; the speed and torque channels are interpolated linearly in time onto it where their sample times
differ (a note says so). Samples of the angle channel outside another channel's time span are dropped.
Torque channels (one per motor) are averaged to the torque per motor, and kept each as it is for the motors' shares
(:mod:`calibration.traces.motor_shares`); how far they disagree is reported.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from press_io.errors import PressDataError
from press_model.press_data import PressData

from calibration.traces.channel_map import ChannelMap, ChannelSpec, load_channel_map
from calibration.traces.drive_log import DriveLog, LogRows, _settings, columns_rows, grid_rows
from calibration.traces.trace_formats import Channel, Trace, read_trace

_RAD_S_TO_RPM = 60.0 / (2.0 * math.pi)
_LISTED = 8


def read_trace_log(path: str | Path, channel_map: ChannelMap | str | Path, press: PressData, step_deg: float = 1.0,
                   settings=None, correction: tuple[float, float] = (0.0, 0.0)) -> DriveLog:
    """Read a drive trace through ``channel_map`` (a :class:`ChannelMap` or its file) for ``press``; returns a
    :class:`DriveLog` as :func:`calibration.traces.drive_log.read_drive_log` does. Raises :class:`PressDataError` for a map
    that does not fit the press or the trace (naming the channel) and for every refusal of the drive-log checks.
    ``correction``: (channel delay in s, encoder offset in deg) as in :func:`calibration.traces.drive_log.read_drive_log`."""
    cmap = channel_map if isinstance(channel_map, ChannelMap) else load_channel_map(channel_map)
    cmap.check_press(press.name, press.drive.motors)
    return grid_rows(read_trace_rows(path, cmap, press, settings), press.drive.gear_ratio, press.motor.rated_torque, step_deg,
                     settings, peak_torque_Nm=press.motor.peak_torque, correction=correction)


def read_trace_rows(path: str | Path, cmap: ChannelMap, press: PressData, settings=None) -> LogRows:
    """The drive log's rows of a trace read once through ``cmap`` (already checked against ``press``), before the
    drive-log checks and grid (:func:`calibration.traces.drive_log.grid_rows`, once per recording correction);
    ``settings`` as for :func:`read_trace_log`."""
    trace = read_trace(path)
    cfg = _settings(settings)
    comments, data, lines, notes, motors = map_columns(trace, cmap, press.drive.gear_ratio, press.motor.rated_torque,
                                                       cfg.torque_channels_cancel_ratio)
    return columns_rows(trace.source, comments, data, lines, notes, trace.sha256, channel_map=cmap, motors=motors)


def map_columns(trace: Trace, cmap: ChannelMap, gear_ratio: float, rated_torque_Nm: float, cancel_ratio: float):
    """The drive log's columns from a trace: ``(comments, data (rows, 4, or 5 with a mapped process force in N), lines, notes,
    motors)`` with time in s, crank angle in deg, motor speed in rpm at the motor shaft and torque per motor in N m (see the
    module docstring); ``motors``: ((rows, M) each torque channel in N m, their M names) for several torque channels, else None.

    Refused, on the map's key: a mapped channel with a time of its own whose samples cover a shorter time than the
    crank angle channel's (beyond the sampling of either; the columns of one table with a mapped time column keep the
    drive-log CSV's handling: rows with an empty cell are dropped, naming their lines), and torque channels whose mean has an RMS below ``cancel_ratio`` (drive_log.toml
    [check] torque_channels_cancel_ratio) times theirs (they cancel: one counted the other way)."""
    found = {s.field: trace.channel(s.name, cmap.source, f"{s.field}.name") for s in cmap.specs}
    angle_ch = found[cmap.angle.field]
    binary = "; 'line' in the messages below is the sample number" if angle_ch.lines is None else ""
    notes = [f"Read {trace.source} as {trace.how} through the channel map {cmap.source}{binary}.", *trace.notes]
    time_of = _time_source(trace, cmap, found)

    base_t = time_of(cmap.angle, angle_ch)
    for spec in cmap.specs[1:] if cmap.time is None else ():
        _refuse_short(trace, cmap, spec, found[spec.field], time_of(spec, found[spec.field]), angle_ch, base_t)
    keep = np.ones(base_t.shape, dtype=bool)  # rows inside every channel's time span (a NaN time is the drive-log checks' to drop)
    resampled = []

    def on_base(spec: ChannelSpec) -> np.ndarray:
        ch = found[spec.field]
        t = time_of(spec, ch)
        if t is base_t or (t.shape == base_t.shape and np.array_equal(t, base_t, equal_nan=True)):
            return ch.values
        ok = np.isfinite(t) & np.isfinite(ch.values)
        if ok.sum() < 2:
            raise PressDataError(cmap.source, f"{spec.field}.name", spec.name, f"holds fewer than two samples in {trace.source}")
        tt, vv = t[ok], ch.values[ok]
        if np.any(np.diff(tt) <= 0):
            order = np.argsort(tt, kind="stable")
            tt, vv = tt[order], vv[order]
            first = np.concatenate(([True], np.diff(tt) > 0))
            tt, vv = tt[first], vv[first]
        keep[:] &= ~((base_t < tt[0]) | (base_t > tt[-1]))
        resampled.append(f"'{spec.name}' (every {_step_ms(tt)} ms)")
        return np.interp(base_t, tt, vv)

    angle = angle_ch.values * cmap.angle.factor(rated_torque_Nm) * 180.0 / math.pi
    speed = on_base(cmap.speed) * cmap.speed.factor(rated_torque_Nm) * _RAD_S_TO_RPM
    if cmap.speed.side == "crank":
        speed = speed * gear_ratio
    torques = np.array([on_base(s) * s.factor(rated_torque_Nm) for s in cmap.torque])
    torque = torques.mean(axis=0)
    force = [on_base(cmap.force) * cmap.force.factor(rated_torque_Nm)] if cmap.force is not None else []
    if len(cmap.torque) > 1:
        _refuse_cancelling(trace, cmap, torques, torque, cancel_ratio)
    if resampled:
        notes.append(f"Brought {', '.join(resampled)} onto the time base of the crank angle channel '{cmap.angle.name}' (every "
                     f"{_step_ms(base_t[np.isfinite(base_t)])} ms) by linear interpolation in time"
                     + (f"; dropped {int((~keep).sum())} angle samples outside their time span." if (~keep).any() else "."))
    if len(cmap.torque) > 1:
        both = np.all(np.isfinite(torques), axis=0) & keep
        spread = float(np.sqrt(np.mean((torques[:, both] - torque[both]) ** 2))) if both.any() else math.nan
        level = float(np.sqrt(np.mean(torque[both] ** 2))) if both.any() else math.nan
        names = ", ".join(f"'{s.name}'" for s in cmap.torque)
        notes.append(f"Averaged {len(cmap.torque)} torque channels ({names}) to the torque per motor; they differ from their mean "
                     f"by {spread:.4g} N m RMS ({100.0 * spread / level:.3g} % of the mean's RMS {level:.4g} N m).")
    used = {id(ch) for ch in found.values()}
    ignored = [n for n, ch in trace.channels.items() if id(ch) not in used]
    if ignored:
        listed = ", ".join(map(repr, ignored[:_LISTED])) + (f" and {len(ignored) - _LISTED} more" if len(ignored) > _LISTED else "")
        notes.append(f"Ignored {len(ignored)} channel{'s' if len(ignored) > 1 else ''} the map does not name ({listed}).")
    data = np.column_stack([base_t, angle, speed, torque, *force])[keep]  # a fifth column: the process force in N
    lines = angle_ch.lines[keep] if angle_ch.lines is not None else np.flatnonzero(keep) + 1
    motors = (torques.T[keep], tuple(s.name for s in cmap.torque)) if len(cmap.torque) > 1 else None
    return trace.comments, data, lines, notes, motors


def _span(t: np.ndarray, values: np.ndarray) -> tuple[int, float, float, float]:
    """(finite samples, first time, last time, median step) of a channel, times in s (NaN for no samples)."""
    ok = np.isfinite(t) & np.isfinite(values)
    tt = t[ok]
    if tt.size == 0:
        return 0, math.nan, math.nan, math.nan
    return int(tt.size), float(tt.min()), float(tt.max()), float(np.median(np.abs(np.diff(tt)))) if tt.size > 1 else 0.0


def _refuse_short(trace: Trace, cmap: ChannelMap, spec: ChannelSpec, ch: Channel, t: np.ndarray, angle_ch: Channel,
                  base_t: np.ndarray) -> None:
    """Refuse a mapped channel whose samples start later or end earlier than the crank angle channel's by more than
    two sample steps of the slower of the two (channels of other sample times end up to one step apart)."""
    n, lo, hi, step = _span(t, ch.values)
    na, alo, ahi, astep = _span(base_t, angle_ch.values)
    if na == 0 or (n >= 2 and lo <= alo + 2.0 * max(step, astep) and hi >= ahi - 2.0 * max(step, astep)):
        return
    cut = f"; {'; '.join(trace.notes)}" if trace.notes else ""
    held = f"{n} samples over {lo:.6g}-{hi:.6g} s" if n else "no samples"
    raise PressDataError(cmap.source, f"{spec.field}.name", spec.name, f"is short in {trace.source}: the channel holds {held}, "
                         f"the crank angle channel '{cmap.angle.name}' {na} over {alo:.6g}-{ahi:.6g} s{cut}; export the "
                         "channels over the same time (a channel added later, or cut off), or map another channel")


def _refuse_cancelling(trace: Trace, cmap: ChannelMap, torques: np.ndarray, mean: np.ndarray, ratio: float) -> None:
    """Refuse torque channels (N m, one row each) whose mean's RMS is below ``ratio`` times their own RMS."""
    both = np.all(np.isfinite(torques), axis=0)
    if not both.any():
        return
    own = float(np.mean(np.sqrt(np.mean(torques[:, both] ** 2, axis=1))))
    level = float(np.sqrt(np.mean(mean[both] ** 2)))
    if own > 0.0 and level < ratio * own:
        names = [s.name for s in cmap.torque]
        signs = ", ".join(f"'{s.name}' {int(s.sign):+d}" for s in cmap.torque)
        raise PressDataError(cmap.source, "channels.motor_torque_Nm", names, f"cancel in {trace.source}: their mean has an RMS of "
                             f"{level:.4g} N m, {100.0 * level / own:.3g} % of theirs ({own:.4g} N m; under "
                             f"{100.0 * ratio:g} %, drive_log.toml [check] torque_channels_cancel_ratio), while motors "
                             f"driving one crank share its load: one motor's torque is counted the other way; check each "
                             f"motor's sign in the map (now {signs}) and set sign = -1 on the one its drive counts the "
                             "other way")


def _time_source(trace: Trace, cmap: ChannelMap, found: dict[str, Channel]):
    """A function giving each mapped channel's time (s): the map's time channel if it names one, else the channel's own."""
    if cmap.time is not None:
        tch = found[cmap.time.field]
        t = tch.values * cmap.time.factor(0.0)

        def mapped(spec: ChannelSpec, ch: Channel) -> np.ndarray:
            if ch.values.shape != t.shape:
                raise PressDataError(cmap.source, f"{spec.field}.name", spec.name, f"has {ch.values.size} samples, the time channel "
                                     f"'{cmap.time.name}' {t.size}: they must be columns of one table; leave time_s out where "
                                     "the channels have times of their own")
            return t

        return mapped

    def own(spec: ChannelSpec, ch: Channel) -> np.ndarray:
        if ch.time_s is None:
            raise PressDataError(cmap.source, f"{spec.field}.name", spec.name, f"has no time of its own in {trace.source} "
                                 f"({trace.format}): name the time column in the map, e.g. time_s = {{ name = \"Time\", unit = \"s\" }}")
        return ch.time_s

    return own


def _step_ms(t: np.ndarray) -> str:
    return f"{1000.0 * float(np.median(np.diff(t))):.4g}" if t.size > 1 else "?"
