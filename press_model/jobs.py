"""Job files: what the press does in a cycle (process force of Eq. 14, prescribed crank motion).

A job file is TOML like the press file. The shipped ones are named: 'cushion-test' (the calibration
experiment of Section 4.1) and 'door-panel' (the door outer panel of Section 4.3).
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Mapping

from .errors import PressDataError
from .forces import NO_PROCESS, ProcessForce
from .motion import ConstantSpeed, ModulatedSpeed
from .press_data import FieldReader, read_text_file

BUILTIN_JOBS = {"cushion-test": "cushion_test.toml", "door-panel": "door_panel.toml"}


@dataclass(frozen=True)
class Job:
    name: str
    source: str
    process: ProcessForce
    motion: Mapping | None  # the [motion] table, read by :func:`make_motion`
    raw: Mapping


def load_job(name_or_path: str | Path) -> Job:
    """Read and validate a job file, by built-in name or path."""
    key = str(name_or_path)
    if key in BUILTIN_JOBS:
        text = resources.files("press_model.data").joinpath(BUILTIN_JOBS[key]).read_text(encoding="utf-8")
        source = f"<built-in {BUILTIN_JOBS[key]}>"
    else:
        path = Path(key)
        if not path.is_file():
            raise PressDataError(key, "--job", key, f"must be an existing TOML job file or one of {', '.join(BUILTIN_JOBS)}")
        text, source = read_text_file(path, "--job"), str(path)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise PressDataError(source, "<file>", "TOML", f"is not valid TOML ({exc}); fix the syntax at that line") from None
    rd = FieldReader(source, raw)
    name = rd.string(("job", "name"))
    process = read_process(rd) if "process" in raw else NO_PROCESS
    motion = rd.table(("motion",), required=False) or None
    if motion is not None:
        make_motion(motion, source)  # validate now, not halfway through a run
    return Job(name, source, process, motion, raw)


def read_process(rd: FieldReader) -> ProcessForce:
    p = ("process",)
    hp = rd.number((*p, "contact_height_m"), gt=0.0, unit="m")
    heights = rd.node((*p, "heights_m"))
    forces = rd.node((*p, "forces_N"))
    for key, val in (("heights_m", heights), ("forces_N", forces)):
        if not isinstance(val, list) or len(val) < 2:
            rd.fail((*p, key), val, "must be a list of at least two numbers (a piecewise-linear F(H))")
    if len(heights) != len(forces):
        rd.fail((*p, "forces_N"), forces, f"must have as many entries as heights_m ({len(heights)})")
    hs = tuple(rd.number((*p, "heights_m", i), ge=0.0, unit="m") for i in range(len(heights)))
    fs = tuple(rd.number((*p, "forces_N", i), ge=0.0, unit="N, acting up on the slide") for i in range(len(forces)))
    if len(set(hs)) != len(hs):
        rd.fail((*p, "heights_m"), list(hs), "must not repeat a height")
    return ProcessForce(hp, hs, fs)


def make_motion(table: Mapping, source: str, strokes_per_min: float | None = None):
    """Crank motion from a job's [motion] table; ``strokes_per_min`` overrides the table's rate."""
    rd = FieldReader(source, {"motion": table})
    kind = rd.string(("motion", "kind"), choices=("constant", "modulated"))
    spm = strokes_per_min if strokes_per_min is not None else rd.number(("motion", "strokes_per_min"), gt=0.0, unit="1/min")
    if not (isinstance(spm, (int, float)) and math.isfinite(spm) and spm > 0):
        raise PressDataError(source, "--spm", spm, "must be a positive number of strokes per minute")
    if kind == "constant":
        return ConstantSpeed.from_spm(spm)
    depth = rd.number(("motion", "speed_depth"), ge=0.0, lt=1.0)
    slow = math.radians(rd.number(("motion", "slow_angle_deg"), unit="deg"))
    return ModulatedSpeed.from_spm(spm, depth, slow)
