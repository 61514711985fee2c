"""The channel map of a drive trace (``--log-format MAP.toml``): which channel of the file is which, in which unit.

A map belongs to one press (its PLC's channel names, its motors), and says so::

    press = "25,000 kN servo press, eight-bar linkage (reference)"   # the press file's name

    [channels]
    crank_angle_deg = { name = "fCrankAngle", unit = "deg" }
    motor_speed_rpm = { name = "Drive1_ActVelo", unit = "rpm", side = "motor" }
    motor_torque_Nm = [{ name = "Drive1_ActTorque", unit = "%" }, { name = "Drive2_ActTorque", unit = "%", sign = -1 }]
    time_s = { name = "Time", unit = "s" }    # only where the channels have no time of their own (plain CSV)
    process_force_N = { name = "Cushion_ActForce", unit = "kN" }   # optional: the force on the slide (cushion or part)

Units (:data:`UNITS`): the crank angle in deg or rad (crank side, wrapping or not); the speed in rpm, rad/s or
deg/s with ``side`` "motor" or "crank" (a drive logs its shaft, a PLC often the crank); the torque per channel in
N*m, kN*m or % of the press file's rated motor torque; several torque channels (one per motor, at most the
press's motor count) are averaged to the torque per motor. The time in s or ms. The optional process force (the
force on the slide from the cushion or the part, up positive as the job's ``[process]`` forces) in N, kN or % of
``rated_N`` (the force that 100 % stands for, given in the channel's entry); it replaces the job's nominal force curve
in the model for that log (:mod:`calibration.identification.process_force`). ``sign = -1`` on a speed or
torque channel turns its sign (a drive whose positive direction is the other way, a mirrored motor); default 1, the
value as the drive logs it. An unknown unit, a missing ``side`` or a channel the trace does not hold is refused
naming the channel.

When a log read through a map fails a check that a unit, side or sign of the map explains (the speed against the
crank angle, the torque's size, the torque against the model), the refusal names the map's key and the value that
fits (:meth:`ChannelMap.speed_refusal`, :meth:`ChannelMap.torque_refusal`), not the log.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

from press_io.errors import PressDataError
from press_model.readers import FieldReader, read_toml

ROLES = ("crank_angle_deg", "motor_speed_rpm", "motor_torque_Nm", "time_s", "process_force_N")
_RPM = 2.0 * math.pi / 60.0
UNITS = {  # role -> unit -> factor to SI (rad, rad/s, N m, s); '%' is resolved with the rated torque
    "crank_angle_deg": {"deg": math.pi / 180.0, "rad": 1.0},
    "motor_speed_rpm": {"rpm": _RPM, "rad/s": 1.0, "deg/s": math.pi / 180.0},
    "motor_torque_Nm": {"N*m": 1.0, "kN*m": 1000.0, "%": math.nan},
    "time_s": {"s": 1.0, "ms": 1e-3},
    "process_force_N": {"N": 1.0, "kN": 1000.0, "%": math.nan},  # '%' of the channel's rated_N
}
SIDES = ("motor", "crank")
_HINT = "see 'Drive traces' in calibration/README.md for the channel map's format"


@dataclass(frozen=True)
class ChannelSpec:
    """One mapped channel: its role, its name in the trace, its unit and (speed only) the shaft it is measured at;
    ``field`` is where it stands in the map, for messages (e.g. ``channels.motor_torque_Nm.1``)."""

    role: str
    name: str
    unit: str
    field: str
    side: str = ""
    sign: float = 1.0  # -1 turns the channel's sign (speed, torque and force only)
    rated_N: float = math.nan  # the force 100 % stands for (a process force channel in '%')

    def factor(self, rated_torque_Nm: float) -> float:
        """Factor from the file's unit to SI (rad, rad/s at the named side, N m per motor, s, N), with the channel's sign."""
        f = UNITS[self.role][self.unit]
        if self.unit == "%":
            f = (self.rated_N if self.role == "process_force_N" else rated_torque_Nm) / 100.0
        return self.sign * f


@dataclass(frozen=True)
class ChannelMap:
    """A parsed channel map (see the module docstring); ``source`` is the map file."""

    source: str
    press: str
    angle: ChannelSpec
    speed: ChannelSpec
    torque: tuple[ChannelSpec, ...]
    time: ChannelSpec | None
    force: ChannelSpec | None = None  # the optional process force channel

    @property
    def specs(self) -> tuple[ChannelSpec, ...]:
        return (self.angle, self.speed, *self.torque) + ((self.time,) if self.time else ()) + ((self.force,) if self.force else ())

    def check_press(self, press_name: str, motors: int) -> None:
        """Refuse a map written for another press: another press name, or more torque channels than the press has motors."""
        if self.press != press_name:
            raise PressDataError(self.source, "press", self.press, f"must be the name of the press calibrated ('{press_name}'): "
                                 "a channel map names one press's PLC channels; use the map of this press, or write one")
        if len(self.torque) > motors:
            extra = self.torque[motors]
            raise PressDataError(self.source, f"{extra.field}.name", extra.name, f"is torque channel {len(self.torque)} of a press "
                                 f"with {motors} motor{'s' if motors != 1 else ''} (one channel per motor at most): the map is for "
                                 "another press, or a channel is listed twice")

    # --- refusals of a log read through this map that a key of the map explains ---------------------------------
    def speed_refusal(self, log: str, ratio: float, gear_ratio: float, tolerance: float) -> PressDataError:
        """The refusal of a speed channel that disagrees with the crank angle by ``ratio`` (crank angle rate / the rate
        the speed gives, must be 1 within ``tolerance``): on the map's key when changing one unit, side or sign of the
        map brings the ratio within tolerance, else on ``log`` naming the map's keys to check."""
        a, v = self.angle, self.speed
        fixes = []  # (field, value now, value that fits, ratio it gives)
        for unit, f in UNITS[a.role].items():
            if unit != a.unit:
                fixes.append((f"{a.field}.unit", a.unit, unit, ratio * f / UNITS[a.role][a.unit]))
        if self.time is not None:
            for unit, f in UNITS["time_s"].items():
                if unit != self.time.unit:
                    fixes.append((f"{self.time.field}.unit", self.time.unit, unit, ratio * UNITS["time_s"][self.time.unit] / f))
        shaft = {"motor": 1.0, "crank": gear_ratio}
        now = UNITS[v.role][v.unit] * shaft[v.side]
        for unit, f in UNITS[v.role].items():
            for side in SIDES:
                if (unit, side) != (v.unit, v.side):
                    field, old, new = ((f"{v.field}.side", v.side, side) if unit == v.unit else
                                       (f"{v.field}.unit", v.unit, unit) if side == v.side else
                                       (f"{v.field}.unit, side", f"{v.unit}, {v.side}", f"{unit}, {side}"))
                    fixes.append((field, old, new, ratio * now / (f * shaft[side])))
        fixes.append((f"{v.field}.sign", int(v.sign), int(-v.sign), -ratio))
        fit = [fx for fx in fixes if abs(fx[3] - 1.0) <= tolerance]
        shown = f"crank angle rate / the rate of the speed channel = {ratio:.4g}"
        if fit:
            field, old, new, r = fit[0]
            others = "".join(f"; or {f} = {n!r} ({q:.4g})" for f, _, n, q in fit[1:])
            return PressDataError(self.source, field, old, f"does not fit {log}: read with it, the speed channel '{v.name}' and "
                                  f"the crank angle channel '{a.name}' disagree ({shown}, must be 1 within {tolerance:g}); "
                                  f"{field} = {new!r} fits ({r:.4g}){others}: set it in the map")
        keys = [f"{a.field}.unit = {a.unit!r}", f"{v.field}.unit = {v.unit!r}, side = {v.side!r}, sign = {int(v.sign)}"]
        if self.time is not None:
            keys.append(f"{self.time.field}.unit = {self.time.unit!r}")
        return PressDataError(log, f"channel '{v.name}'", shown, f"must be 1 within {tolerance:g}: no single unit, side or sign "
                              f"of the channel map {self.source} explains it; check there {'; '.join(keys)}, and the press's "
                              f"gear_ratio = {gear_ratio:g} (this log fits {gear_ratio / ratio:.4g})" if math.isfinite(ratio)
                              and ratio > 0 else f"must be 1 within {tolerance:g}: check the channel map {self.source}: "
                              f"{'; '.join(keys)}")

    def torque_refusal(self, log: str, scale: float, low: float, high: float, rated_torque_Nm: float, show,
                       problem: str) -> PressDataError:
        """The refusal of torque channels whose size or sign is off: ``scale`` (what the log gives with the map as it is;
        negative: the sign is the other way) must lie in [``low``, ``high``]; ``show(scale)`` words a scale for the
        message, ``problem`` says what is wrong. On the map's torque sign when the other sign fits, on its unit when
        another unit (the same on every torque channel) fits, else on its unit with what each unit would give."""
        first = self.torque[0]
        every = f" on every torque channel ({len(self.torque)})" if len(self.torque) > 1 else ""
        units = {t.unit for t in self.torque}
        if len(units) > 1:
            return PressDataError(self.source, f"{first.field}.unit", sorted(units), f"reads {log} with {show(scale)} "
                                  f"({problem}): check the unit and sign of each torque channel")
        flip = -1.0 if scale < 0.0 else 1.0  # the other sign on every channel turns the scale's sign
        now = abs(first.factor(rated_torque_Nm))
        each = {u: abs(scale) * (rated_torque_Nm / 100.0 if u == "%" else f) / now for u, f in UNITS[first.role].items()}
        fit = [u for u, k in each.items() if low <= k <= high]
        turned = f"sign = {int(-first.sign)}" if flip < 0 else ""
        if flip < 0 and first.unit in fit:
            return PressDataError(self.source, f"{first.field}.sign", int(first.sign), f"does not fit {log}: read with it, "
                                  f"{show(scale)} ({problem}); {turned}{every} fits ({show(each[first.unit])}): the drive "
                                  "counts torque the other way round (positive must drive the crank forward)")
        if fit:
            both = f" with {turned}" if turned else ""
            return PressDataError(self.source, f"{first.field}.unit", first.unit, f"does not fit {log}: read with it, "
                                  f"{show(scale)} ({problem}); unit = {fit[0]!r}{both}{every} fits ({show(each[fit[0]])}): "
                                  "set the unit the drive logs in")
        listed = ", ".join(f"{u!r}: {show(flip * k)}" for u, k in each.items() if u != first.unit)
        return PressDataError(self.source, f"{first.field}.unit", first.unit, f"does not fit {log}: read with it, {show(scale)} "
                              f"({problem}); no unit{' or sign' if turned else ''} of the map fits (other units give {listed}): "
                              "check that the channels are each motor's torque, and the press file")


def parse_channel_map(raw: Mapping, source: str) -> ChannelMap:
    """Validate the parsed TOML of a channel map; misspelled or unknown keys are refused."""
    rd = FieldReader(source, raw)
    press = rd.string(("press",))
    rd.table(("channels",))

    def spec(path, role, field):
        rd.table(path)
        name = rd.string((*path, "name"))
        unit = rd.node((*path, "unit"))
        if not isinstance(unit, str) or unit not in UNITS[role]:
            rd.fail((*path, "unit"), unit, f"is not a unit of {role} (channel '{name}'): use one of "
                    f"{', '.join(map(repr, UNITS[role]))}{' (% of the rated motor torque)' if role == 'motor_torque_Nm' else ''}")
        side, sign, rated = "", 1.0, math.nan
        if role == "process_force_N" and unit == "%":
            rated = rd.number((*path, "rated_N"), gt=0.0, unit="N")
        if role in ("motor_speed_rpm", "motor_torque_Nm", "process_force_N"):
            sign = rd.node((*path, "sign"), required=False)
            if sign is None:
                sign = 1
            if isinstance(sign, bool) or sign not in (1, -1):
                rd.fail((*path, "sign"), sign, f"must be 1 or -1 (channel '{name}'): -1 turns the channel's sign")
        if role == "motor_speed_rpm":
            side = rd.string((*path, "side"), choices=SIDES, default="")
            if not side:
                rd.fail((*path, "side"), "<missing>", f"required for the speed channel '{name}': say whether it is measured at "
                        "the motor shaft ('motor') or the crank ('crank'); they differ by the gear ratio")
        return ChannelSpec(role, name, unit, field, side, float(sign), rated)

    angle = spec(("channels", "crank_angle_deg"), "crank_angle_deg", "channels.crank_angle_deg")
    speed = spec(("channels", "motor_speed_rpm"), "motor_speed_rpm", "channels.motor_speed_rpm")
    tq = rd.node(("channels", "motor_torque_Nm"))
    if isinstance(tq, Mapping):
        torque = (spec(("channels", "motor_torque_Nm"), "motor_torque_Nm", "channels.motor_torque_Nm"),)
    elif isinstance(tq, list) and tq:
        torque = tuple(spec(("channels", "motor_torque_Nm", i), "motor_torque_Nm", f"channels.motor_torque_Nm.{i}")
                       for i in range(len(tq)))
    else:
        rd.fail(("channels", "motor_torque_Nm"), tq, "must be a channel { name = ..., unit = ... } or a list of them (one per motor)")
    time = (spec(("channels", "time_s"), "time_s", "channels.time_s")
            if rd.node(("channels", "time_s"), required=False) is not None else None)
    force = (spec(("channels", "process_force_N"), "process_force_N", "channels.process_force_N")
             if rd.node(("channels", "process_force_N"), required=False) is not None else None)
    cmap = ChannelMap(source, press, angle, speed, torque, time, force)
    seen: dict[str, str] = {}
    for s in cmap.specs:
        if s.name in seen:
            raise PressDataError(source, f"{s.field}.name", s.name, f"is also {seen[s.name]}: each channel has one role")
        seen[s.name] = s.field
    rd.reject_unread(_HINT)
    return cmap


def load_channel_map(path: str | Path) -> ChannelMap:
    """Read and validate a channel map file (``--log-format``)."""
    raw, source = read_toml(path, None, "--log-format", "must be an existing channel-map TOML file")
    if not raw:
        raise PressDataError(source, "<file>", "<empty>", "holds no keys: a channel map names the press (press = \"...\", the "
                             "press file's name) and a [channels] table with crank_angle_deg, motor_speed_rpm and "
                             "motor_torque_Nm, each { name = ..., unit = ... }; " + _HINT)
    return parse_channel_map(raw, source)
