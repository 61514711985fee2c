"""The [calibration] table of a job file: what to calibrate, Eq. 28's weight, and the optimisers' settings."""
from __future__ import annotations

import difflib
from dataclasses import dataclass

from press_model.errors import PressDataError
from press_model.jobs import JOB_FORMAT, Job
from press_model.readers import FieldReader

from calibration.identification.aco import AcoSettings

METHODS = ("aco", "least-squares", "differential-evolution")


@dataclass(frozen=True)
class CalibrationSettings:
    parameters: tuple[str, ...]
    weight: float
    default_method: str
    peak_window: float  # s after die contact
    speed_harmonics: int
    interval_level: float
    correlation_limit: float
    interval_width_limit: float
    ls_starts: int
    de_population: int
    de_generations: int
    de_tolerance: float
    aco: AcoSettings
    peak_filter_window_deg: float
    peak_filter_order: int
    peak_noise_ratio_warning: float
    bootstrap_refits: int
    bootstrap_block_deg: float
    bootstrap_step_guard_deg: float
    bootstrap_iterations: int
    bootstrap_block_noise_lengths: float  # under coloured noise a block holds at least this many correlation lengths
    bootstrap_allowance: dict  # parameter name -> widening of its interval on each side, fraction of its range (0 if absent)
    adequacy_level: float = 0.01  # false-alarm probability of the adequacy verdict (calibration/identification/adequacy.py)
    ripple_orders: tuple[float, ...] = (6.0,)  # candidate torque-ripple orders per motor turn
    recording_estimate: bool = True  # estimate and correct the channel delay and encoder offset (calibration/identification/recording.py)
    recording_iterations: int = 4  # at most this many corrections of the log
    recording_stop_standard_errors: float = 0.25  # corrections stop once the shift still seen is below this many standard errors

    @classmethod
    def from_job(cls, job: Job) -> "CalibrationSettings":
        table = job.raw.get("calibration")
        if table is None:
            raise PressDataError(job.source, "calibration", None, "is missing: a job needs a [calibration] table to calibrate against its log (see cushion_test.toml)")
        aco_table = table.get("aco") if isinstance(table, dict) else None
        rest = {k: v for k, v in table.items() if k != "aco"} if isinstance(table, dict) else table
        rd = FieldReader(job.source, {"calibration": rest})
        c = ("calibration",)
        names = rd.node((*c, "parameters"))
        if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
            rd.fail((*c, "parameters"), names, 'must be a list of parameter names, e.g. ["eta_gear", "psi"]')
        s = cls(
            parameters=tuple(names),
            weight=rd.number((*c, "weight"), ge=0.0, le=1.0),
            default_method=rd.string((*c, "default_method"), choices=METHODS),
            peak_window=rd.number((*c, "peak_window_after_contact_s"), ge=0.0, unit="s"),
            speed_harmonics=rd.integer((*c, "speed_harmonics"), ge=1),
            interval_level=rd.number((*c, "interval_level"), gt=0.0, lt=1.0),
            correlation_limit=rd.number((*c, "correlation_limit"), gt=0.0, lt=1.0),
            interval_width_limit=rd.number((*c, "interval_width_limit"), gt=0.0),
            ls_starts=rd.integer((*c, "least_squares", "starts"), ge=1),
            de_population=rd.integer((*c, "differential_evolution", "population"), ge=5),
            de_generations=rd.integer((*c, "differential_evolution", "max_generations"), ge=1),
            de_tolerance=rd.number((*c, "differential_evolution", "tolerance"), gt=0.0),
            peak_filter_window_deg=rd.number((*c, "peak_filter_window_deg"), gt=0.0, lt=180.0, unit="deg"),
            peak_filter_order=rd.integer((*c, "peak_filter_order"), ge=0),
            peak_noise_ratio_warning=rd.number((*c, "peak_noise_ratio_warning"), ge=0.0),
            bootstrap_refits=rd.integer((*c, "bootstrap", "refits"), ge=0),
            bootstrap_block_deg=rd.number((*c, "bootstrap", "block_deg"), ge=1.0, lt=360.0, unit="deg"),
            bootstrap_step_guard_deg=rd.number((*c, "bootstrap", "step_guard_deg"), ge=0.0, lt=90.0, unit="deg"),
            bootstrap_iterations=rd.integer((*c, "bootstrap", "iterations"), ge=1),
            bootstrap_block_noise_lengths=rd.number((*c, "bootstrap", "block_noise_lengths"), ge=1.0, unit="correlation lengths"),
            bootstrap_allowance=cls._allowance(rd, (*c, "bootstrap", "allowance"), names),
            aco=AcoSettings.from_mapping(aco_table if aco_table is not None else {}, f"{job.source} [calibration.aco]"),
            adequacy_level=rd.number((*c, "adequacy", "level"), gt=0.0, lt=0.5),
            ripple_orders=cls._orders(rd, (*c, "adequacy", "ripple_orders_per_motor_turn")),
            recording_estimate=cls._flag(rd, (*c, "recording", "estimate")),
            recording_iterations=rd.integer((*c, "recording", "iterations"), ge=1),
            recording_stop_standard_errors=rd.number((*c, "recording", "stop_standard_errors"), gt=0.0, lt=1.0,
                                                     unit="standard errors"),
        )
        rd.reject_unread(JOB_FORMAT)
        return s

    @staticmethod
    def _flag(rd: FieldReader, path: tuple) -> bool:
        val = rd.node(path)
        if not isinstance(val, bool):
            rd.fail(path, val, "must be true or false")
        return val

    @staticmethod
    def _orders(rd: FieldReader, path: tuple) -> tuple[float, ...]:
        orders = rd.node(path)
        if not isinstance(orders, list) or not all(isinstance(q, (int, float)) and not isinstance(q, bool) and q > 0 for q in orders):
            rd.fail(path, orders, "must be a list of positive numbers (ripple periods per motor revolution), e.g. [6]; [] tests none")
        return tuple(float(q) for q in orders)

    @staticmethod
    def _allowance(rd: FieldReader, path: tuple, names: list[str]) -> dict:
        """The optional [calibration.bootstrap.allowance] table: parameter name -> fraction of its range (>= 0).

        A name the job does not calibrate is kept and unused (a copied job may calibrate fewer parameters, and
        --parameters may choose others); one that looks like a misspelling of a calibrated name is refused."""
        table = rd.table(path, required=False)
        out = {}
        for key in table:
            close = difflib.get_close_matches(key, names, n=1, cutoff=0.8)
            if key not in names and close:
                rd.fail((*path, key), table[key], f"names no key parameter (misspelled? did you mean '{close[0]}'?)")
            out[key] = rd.number((*path, key), ge=0.0, lt=1.0, unit="fraction of the parameter's range")
        return out


def joint_settings_warning(jobs) -> str | None:
    """For logs fitted jointly with several jobs: one warning naming the [calibration] keys (dotted) that a later job
    sets to another value than the first, whose settings the joint fit uses; None when none does (a job without a
    [calibration] table, or one job serving all)."""
    def flat(node, prefix=""):
        if isinstance(node, dict):
            out = {}
            for k, v in node.items():
                out.update(flat(v, f"{prefix}{k}."))
            return out
        return {prefix[:-1]: node}

    first = flat(jobs[0].raw.get("calibration") or {}, "calibration.")
    differ = {}
    for jb in jobs[1:]:
        other = flat(jb.raw.get("calibration") or {}, "calibration.")
        keys = sorted(k for k in other if first.get(k, "<absent>") != other[k])  # a key the job leaves out ignores nothing
        if keys and jb.source not in differ:
            differ[jb.source] = keys
    if not differ:
        return None
    listed = "; ".join(f"{src}: {', '.join(keys[:8])}{f' and {len(keys) - 8} more' if len(keys) > 8 else ''}"
                       for src, keys in differ.items())
    return (f"the jobs' [calibration] settings differ ({listed}): a joint fit has one set of settings, the first job's "
            f"({jobs[0].source}); the others' [calibration] tables are not used (their [process] is). Give the jobs the "
            "same [calibration] table to silence this")
