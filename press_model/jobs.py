"""Job files: what the press does in a cycle (process force of Eq. 14, prescribed crank motion).

A job file is TOML like the press file. The shipped ones are named: 'cushion-test' (the calibration
experiment of Section 4.1), 'door-panel' (the door outer panel of Section 4.3) and 'no-load' (the
cushion test's motion without process force, a sensitivity load case).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from press_io.errors import PressDataError
from .forces import NO_PROCESS, ProcessForce
from .motion import ConstantSpeed, ModulatedSpeed
from .readers import FieldReader, read_toml
from .schema import migrate

BUILTIN_JOBS = {"cushion-test": "cushion_test.toml", "cushion-validation": "cushion_validation.toml", "door-panel": "door_panel.toml",
                "no-load": "no_load_test.toml", "crank-slider-cushion": "crank_slider_cushion.toml"}
# sections another reader validates in full, unknown keys included, when the job is used for that purpose:
# [motion] make_motion, [experiment] and [calibration] calibration.synthetic.experiment / calibration.identification.settings,
# [planning] and [playback] planning.settings.read_planning, [design] calibration.design.runs
DELEGATED_SECTIONS = ("motion", "experiment", "calibration", "planning", "playback", "design")
JOB_FORMAT = "see the shipped job files (press_model/data/cushion_test.toml, door_panel.toml) and press_model/README.md for the format"


@dataclass(frozen=True)
class Job:
    name: str
    source: str
    process: ProcessForce
    motion: Mapping | None  # the [motion] table, read by :func:`make_motion`
    raw: Mapping


def load_job(name_or_path: str | Path) -> Job:
    """Read and validate a job file, by built-in name or path. A file of an older schema (none given: 1) is read as the
    current one, with a note (:mod:`press_model.schema`); ``Job.raw`` holds the current form without ``schema``."""
    key = str(name_or_path)
    raw, source = read_toml(key, BUILTIN_JOBS.get(key), "--job", f"must be an existing TOML job file or one of {', '.join(BUILTIN_JOBS)}")
    if "job" not in raw and ("press" in raw or "bodies" in raw):
        raise PressDataError(source, "--job", source, "is a press file (it has [press], no [job]): pass it as --press, and give "
                             f"--job a job file or one of {', '.join(BUILTIN_JOBS)}")
    raw = migrate(raw, "job", source)
    rd = FieldReader(source, raw)
    name = rd.string(("job", "name"))
    process = read_process(rd) if "process" in raw else NO_PROCESS
    motion = rd.table(("motion",), required=False) or None
    if motion is not None:
        make_motion(motion, source)  # validate now, not halfway through a run
    for section in DELEGATED_SECTIONS:
        if section in raw:
            rd.delegate((section,))
    rd.reject_unread(JOB_FORMAT)
    return Job(name, source, process, motion, raw)


def read_process(rd: FieldReader) -> ProcessForce:
    p = ("process",)
    hp = rd.number((*p, "contact_height_m"), gt=0.0, unit="m", limit="max_length_m")
    heights = rd.node((*p, "heights_m"))
    forces = rd.node((*p, "forces_N"))
    for key, val in (("heights_m", heights), ("forces_N", forces)):
        if not isinstance(val, list) or len(val) < 2:
            rd.fail((*p, key), val, "must be a list of at least two numbers (a piecewise-linear F(H))")
    if len(heights) != len(forces):
        rd.fail((*p, "forces_N"), forces, f"must have as many entries as heights_m ({len(heights)})")
    hs = tuple(rd.number((*p, "heights_m", i), ge=0.0, unit="m", limit="max_length_m") for i in range(len(heights)))
    fs = tuple(rd.number((*p, "forces_N", i), ge=0.0, unit="N, acting up on the slide", limit="max_process_force_N") for i in range(len(forces)))
    if len(set(hs)) != len(hs):
        rd.fail((*p, "heights_m"), list(hs), "must not repeat a height")
    return ProcessForce(hp, hs, fs, rd.source)


def make_motion(table: Mapping, source: str, strokes_per_min: float | None = None):
    """Crank motion from a job's [motion] table; ``strokes_per_min`` overrides the table's rate."""
    rd = FieldReader(source, {"motion": table})
    kind = rd.string(("motion", "kind"), choices=("constant", "modulated"))
    spm = rd.number(("motion", "strokes_per_min"), gt=0.0, unit="1/min", default=strokes_per_min, limit="max_strokes_per_min")
    if strokes_per_min is not None:
        spm = strokes_per_min
    if not (isinstance(spm, (int, float)) and math.isfinite(spm) and spm > 0):
        raise PressDataError(source, "--spm", spm, "must be a positive number of strokes per minute")
    if kind == "constant":
        rd.reject_unread(JOB_FORMAT)
        return ConstantSpeed.from_spm(spm)
    depth = rd.number(("motion", "speed_depth"), ge=0.0, lt=1.0)
    slow = rd.angle(("motion", "slow_angle_deg"))
    rd.reject_unread(JOB_FORMAT)
    return ModulatedSpeed.from_spm(spm, depth, slow)
