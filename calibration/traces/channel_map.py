"""The channel map of a drive trace (``--log-format MAP.toml``): which channel of the file is which, in which unit.

A map belongs to one press (its PLC's channel names, its motors), and says so::

    press = "25,000 kN servo press, eight-bar linkage (reference)"   # the press file's name

    [channels]
    crank_angle_deg = { name = "fCrankAngle", unit = "deg" }
    motor_speed_rpm = { name = "Drive1_ActVelo", unit = "rpm", side = "motor" }
    motor_torque_Nm = [{ name = "Drive1_ActTorque", unit = "%" }, { name = "Drive2_ActTorque", unit = "%" }]
    time_s = { name = "Time", unit = "s" }    # only where the channels have no time of their own (plain CSV)

Units (:data:`UNITS`): the crank angle in deg or rad (crank side, wrapping or not); the speed in rpm, rad/s or
deg/s with ``side`` "motor" or "crank" (a drive logs its shaft, a PLC often the crank); the torque per channel in
N*m, kN*m or % of the press file's rated motor torque; several torque channels (one per motor, at most the
press's motor count) are averaged to the torque per motor. The time in s or ms. An unknown unit, a missing
``side`` or a channel the trace does not hold is refused naming the channel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

from press_model.errors import PressDataError
from press_model.readers import FieldReader, read_toml

ROLES = ("crank_angle_deg", "motor_speed_rpm", "motor_torque_Nm", "time_s")
_RPM = 2.0 * math.pi / 60.0
UNITS = {  # role -> unit -> factor to SI (rad, rad/s, N m, s); '%' is resolved with the rated torque
    "crank_angle_deg": {"deg": math.pi / 180.0, "rad": 1.0},
    "motor_speed_rpm": {"rpm": _RPM, "rad/s": 1.0, "deg/s": math.pi / 180.0},
    "motor_torque_Nm": {"N*m": 1.0, "kN*m": 1000.0, "%": math.nan},
    "time_s": {"s": 1.0, "ms": 1e-3},
}
SIDES = ("motor", "crank")
_HINT = "see 'Drive traces' in the README for the channel map's format"


@dataclass(frozen=True)
class ChannelSpec:
    """One mapped channel: its role, its name in the trace, its unit and (speed only) the shaft it is measured at;
    ``field`` is where it stands in the map, for messages (e.g. ``channels.motor_torque_Nm.1``)."""

    role: str
    name: str
    unit: str
    field: str
    side: str = ""

    def factor(self, rated_torque_Nm: float) -> float:
        """Factor from the file's unit to SI (rad, rad/s at the named side, N m per motor, s)."""
        f = UNITS[self.role][self.unit]
        return rated_torque_Nm / 100.0 if self.unit == "%" else f


@dataclass(frozen=True)
class ChannelMap:
    """A parsed channel map (see the module docstring); ``source`` is the map file."""

    source: str
    press: str
    angle: ChannelSpec
    speed: ChannelSpec
    torque: tuple[ChannelSpec, ...]
    time: ChannelSpec | None

    @property
    def specs(self) -> tuple[ChannelSpec, ...]:
        return (self.angle, self.speed, *self.torque) + ((self.time,) if self.time else ())

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
        side = ""
        if role == "motor_speed_rpm":
            side = rd.string((*path, "side"), choices=SIDES, default="")
            if not side:
                rd.fail((*path, "side"), "<missing>", f"required for the speed channel '{name}': say whether it is measured at "
                        "the motor shaft ('motor') or the crank ('crank'); they differ by the gear ratio")
        return ChannelSpec(role, name, unit, field, side)

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
    cmap = ChannelMap(source, press, angle, speed, torque, time)
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
    return parse_channel_map(raw, source)
