"""``press_model/data/tonnage.toml``: the virtual tonnage's, the per-stroke alarms' and the drift chart's rules, read once.

Every value's unit is in its key and its reason beside it in the file; a user's copy is given with ``--rules``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from press_model.readers import FieldReader, read_toml

RULES_FILE = "tonnage.toml"
SCHEMA = 1


@dataclass(frozen=True)
class TonnageRules:
    """[tonnage]: force levels (fractions of the job's force), the observability rule, the joint region's sampling and
    the peak's running median."""

    levels_of_job_force: tuple[float, ...]
    observable_half_width_of_job_force: float
    region_samples: int
    region_seed: int
    peak_median_points: int
    touch_of_job_force: float


@dataclass(frozen=True)
class AlarmRules:
    """[alarms]: OPC 40503 condition classes per stroke, as fractions of the job's force (EccentricLoad: the press
    file's [motor] load_shares and load_share_tolerance)."""

    overload_of_job_force: float
    process_low_of_job_force: float


@dataclass(frozen=True)
class DriftRules:
    """[drift]: the CUSUM's in-control average run length (strokes), reference value (sd) and Phase-I baseline."""

    in_control_strokes: float
    reference_sd: float
    baseline_strokes: int


@dataclass(frozen=True)
class Rules:
    source: str
    tonnage: TonnageRules
    alarms: AlarmRules
    drift: DriftRules


def _levels(rd: FieldReader) -> tuple[float, ...]:
    path = ("tonnage", "levels_of_job_force")
    raw = rd.node(path)
    ok = (isinstance(raw, list) and len(raw) >= 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in raw)
          and all(b > a for a, b in zip(raw, raw[1:])) and 0.0 in raw and 1.0 <= raw[-1])
    if not ok:
        rd.fail(path, raw, "must be at least three increasing fractions of the job's force holding 0 (the model without process force) "
                           "and reaching >= 1, "
                           "e.g. [-0.5, 0.0, 0.5, 1.0, 1.5, 2.0]")
    return tuple(float(v) for v in raw)


def _odd(rd: FieldReader, path: tuple) -> int:
    n = rd.integer(path, ge=1, le=31)
    if n % 2 == 0:
        rd.fail(path, n, "must be odd (a window centred on its point), e.g. 5")
    return n


def load_rules(path: str | Path | None = None) -> Rules:
    """The rules of ``path`` (a TOML file), or the shipped ``press_model/data/tonnage.toml`` for ``None``; a bad value
    raises PressDataError naming the key."""
    raw, source = read_toml(path, RULES_FILE if path is None else None, "--rules", "must be an existing tonnage-rules TOML file")
    rd = FieldReader(source, raw)
    rd.integer(("schema",), ge=SCHEMA, le=SCHEMA)
    t = TonnageRules(_levels(rd), rd.number(("tonnage", "observable_half_width_of_job_force"), gt=0.0, le=1.0),
                     rd.integer(("tonnage", "region_samples"), ge=0, le=256), rd.integer(("tonnage", "region_seed"), ge=0),
                     _odd(rd, ("tonnage", "peak_median_points")), rd.number(("tonnage", "touch_of_job_force"), gt=0.0, lt=1.0))
    a = AlarmRules(rd.number(("alarms", "overload_of_job_force"), gt=1.0, le=2.0),
                   rd.number(("alarms", "process_low_of_job_force"), gt=0.0, lt=1.0))
    d = DriftRules(rd.number(("drift", "in_control_strokes"), ge=100.0, le=1e9), rd.number(("drift", "reference_sd"), gt=0.0, le=3.0),
                   rd.integer(("drift", "baseline_strokes"), ge=30))
    rd.reject_unread("see press_model/data/tonnage.toml for the format")
    return Rules(source, t, a, d)
