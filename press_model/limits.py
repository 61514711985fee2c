"""Sensible ranges of command-line settings and plausibility bounds of press data (``data/run_limits.toml``)."""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

from press_io.errors import PressDataError, ServoPressError

LIMITS_FILE = "press_model/data/run_limits.toml"


@dataclass(frozen=True)
class RunLimits:
    """The ranges of run_limits.toml (units as in its key names)."""

    min_step_deg: float
    max_step_deg: float
    warn_playback_drift_deg: float
    min_n: int
    warn_below_n: int
    max_n: int
    max_runs: int
    max_mass_kg: float
    max_inertia_kg_m2: float
    max_length_m: float
    max_com_offset_m: float
    max_gravity_m_s2: float
    max_gear_ratio: float
    max_motors: int
    max_motor_torque_Nm: float
    max_motor_speed_rpm: float
    max_revolute_viscous_Nms_per_rad: float
    max_guide_viscous_Ns_per_m: float
    max_balance_cylinders: int
    max_piston_area_m2: float
    max_tank_volume_m3: float
    max_pressure_offset_MPa: float
    max_balance_pressure_ratio: float
    min_position_tolerance_m: float
    min_friction_tolerance: float
    max_iterations: int
    max_count: int
    max_process_force_N: float
    max_strokes_per_min: float
    max_dwell_s: float
    min_sample_time_s: float
    max_sample_rate_Hz: float
    max_logged_strokes: int
    max_cam_master_step_deg: float


@lru_cache(maxsize=1)
def run_limits() -> RunLimits:
    """The shipped ranges, read once. (The file ships with the package; this reader only checks that every key is
    there as a positive number and none is unknown, without the press reader, which itself uses these bounds.)"""
    text = resources.files("press_model.data").joinpath("run_limits.toml").read_text(encoding="utf-8")
    raw = tomllib.loads(text)
    fields = {"simulate": ("min_step_deg", "max_step_deg", "warn_playback_drift_deg"), "sensitivity": ("min_n", "warn_below_n", "max_n"),
              "design": ("max_runs",),
              "press": ("max_mass_kg", "max_inertia_kg_m2", "max_length_m", "max_com_offset_m", "max_gravity_m_s2", "max_gear_ratio",
                        "max_motors", "max_motor_torque_Nm", "max_motor_speed_rpm", "max_revolute_viscous_Nms_per_rad",
                        "max_guide_viscous_Ns_per_m", "max_balance_cylinders", "max_piston_area_m2", "max_tank_volume_m3",
                        "max_pressure_offset_MPa", "max_balance_pressure_ratio", "min_position_tolerance_m",
                        "min_friction_tolerance", "max_iterations"),
              "job": ("max_count", "max_process_force_N", "max_strokes_per_min", "max_dwell_s", "min_sample_time_s", "max_sample_rate_Hz",
                      "max_logged_strokes", "max_cam_master_step_deg")}
    values = {}
    for section, keys in fields.items():
        table = raw.get(section, {})
        for key in keys:
            v = table.get(key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
                raise PressDataError(LIMITS_FILE, f"{section}.{key}", v, "must be a positive number")
            values[key] = v
        for key in set(table) - set(keys):
            raise PressDataError(LIMITS_FILE, f"{section}.{key}", table[key], f"is not a known key of [{section}]")
    return RunLimits(**values)


def check_spm(spm: float) -> None:
    """Refuse a stroke rate (strokes per minute) that is not a positive number, or beyond max_strokes_per_min."""
    if not (math.isfinite(spm) and spm > 0):
        raise ServoPressError(f"--spm = {spm!r} is not valid: must be a positive number of strokes per minute, e.g. --spm 11.4")
    bound = run_limits().max_strokes_per_min
    if spm > bound:
        raise ServoPressError(f"--spm = {spm!r} is not valid: must be at most {bound:g} strokes per minute, far above any press "
                              f"(max_strokes_per_min in {LIMITS_FILE}); e.g. --spm 11.4")


def check_step_deg(step_deg: float) -> None:
    """Refuse a crank-angle step outside [min_step_deg, max_step_deg] (NaN and non-divisors are left to crank_grid)."""
    lim = run_limits()
    if step_deg == step_deg and 0 < step_deg and not lim.min_step_deg <= step_deg <= lim.max_step_deg:
        raise ServoPressError(f"--step-deg = {step_deg!r} is not valid: must lie in [{lim.min_step_deg:g}, {lim.max_step_deg:g}] deg "
                              f"and divide 360 (e.g. 1, 0.5, 0.25); finer grids take minutes and change nothing that matters, "
                              f"coarser ones miss the die-contact step (ranges in {LIMITS_FILE})")


def check_design_runs(n: int) -> None:
    """Refuse a number of designed calibration runs (``--runs``) outside [1, max_runs]."""
    bound = run_limits().max_runs
    if not 1 <= n <= bound:
        raise PressDataError("--runs", "--runs", n, f"must be a whole number from 1 to {bound}: each run is a press test of its own "
                             f"and takes ~1.5 s to design and play back, and beyond {bound} the intervals narrow only as 1/sqrt(N) "
                             f"(max_runs in {LIMITS_FILE}); e.g. --runs 2")


def check_sobol_n(flag: str, n: int) -> str | None:
    """Refuse a Sobol base sample size outside [min_n, max_n]; returns a warning text below warn_below_n, else None."""
    lim = run_limits()
    if isinstance(n, int) and n >= 2 and not n & (n - 1):  # not a power of two: the sampler says so
        if not lim.min_n <= n <= lim.max_n:
            raise PressDataError("--n" if flag == "--n" else "--convergence", flag, n,
                                 f"must be a power of two from {lim.min_n} to {lim.max_n}: below {lim.min_n} the S_T "
                                 f"intervals are as wide as the indices, above {lim.max_n} the run takes hours "
                                 f"(ranges in {LIMITS_FILE}); e.g. {flag} 2048")
        if n < lim.warn_below_n:
            return (f"{flag} {n} is below {lim.warn_below_n}: the 95 % intervals of S_T are wider than the 0.05 screening "
                    f"threshold at this N, so the key parameters may change with N; use {flag} {lim.warn_below_n} or more "
                    f"(see sobol.csv's ST_conf, and --convergence)")
    return None
