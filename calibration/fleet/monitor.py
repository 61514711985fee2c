"""Fleet monitoring rules: the baseline, the parameter-change alarm and the poor-fit flag.

Plain functions on calibration records (the content of ``calibrated.json``, one per drive log, in the
order the logs were recorded); :mod:`calibration.fleet.cluster` runs the calibrations, :mod:`calibration.fleet.monitor_report`
writes the files.

* **Change.** A parameter has changed on a log when the log's 95 % interval no longer overlaps the baseline's
  95 % interval, each taken without the uncertainty that every log of the press shares (:func:`change_intervals`):
  the job force tolerance's share, on logs without a force column, is the same cushion's same calibration error in
  every log; it moves every estimate alike and cancels in their difference, so it widens no change. The baseline is
  the first log that calibrated with a good fit, or a ``calibrated.json`` given with ``--baseline``. While the
  change stays inside the combined uncertainty the intervals overlap and nothing is raised.
* **Poor fit.** A log whose RMSE after calibration lies far above the press's typical value (median +
  max(k 1.4826 MAD, floor x median), ``press_model/data/monitor.toml``): no parameter values explain it,
  which points to a sensor fault or a changed process rather than wear. A poorly fitting log raises no
  parameter alarms (its parameters are not to be trusted) and is never the baseline.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from press_io.errors import PressDataError
from press_model.params import intervals_of, read_json
from press_model.press_data import PressData
from press_model.readers import FieldReader, read_toml

RULES_FILE = "monitor.toml"


@dataclass(frozen=True)
class MonitorRules:
    """``press_model/data/monitor.toml``: the poor-fit rule (dimensionless factors, a count of logs)."""

    source: str
    mad_factor: float
    relative_floor: float
    min_logs: int


def load_rules(path: str | Path | None = None) -> MonitorRules:
    """Read the monitoring rules; ``None`` reads the shipped ``press_model/data/monitor.toml``."""
    raw, source = read_toml(path, RULES_FILE if path is None else None, "<file>", "must be an existing monitoring-rules TOML file")
    rd = FieldReader(source, raw)
    r = MonitorRules(source, rd.number(("poor_fit", "mad_factor"), gt=0.0), rd.number(("poor_fit", "relative_floor"), ge=0.0),
                     rd.integer(("poor_fit", "min_logs"), ge=2))
    rd.reject_unread("see press_model/data/monitor.toml for the format")
    return r


# --- reading a calibration record: the one place that knows its field names -------------------------------
def primary_intervals(record: dict) -> dict[str, tuple[float, float]]:
    """The 95 % intervals a calibration reports as its primary ones: name -> (low, high), SI units.

    ``record["intervals"]`` of calibrated.json: the parametric bootstrap's (calibration/identification/bootstrap.py), or the
    Jacobian ones when no refits ran. Every interval the monitor takes from a fleet log is read here.
    """
    return {n: (float(lo), float(hi)) for n, (lo, hi) in record["intervals"].items()}


def common_sd(record: dict) -> dict[str, float]:
    """The standard deviation of each estimate that every log of one press and cushion shares (SI units): the job
    force tolerance's share (``interval_widening.process_force_sd``, 0 on a log with the force column). The same
    cushion's calibration error moves every log's estimate by the same amount, so it cancels in a change between logs."""
    widening = record.get("interval_widening") or {}
    return {n: float(v) for n, v in (widening.get("process_force_sd") or {}).items()}


def change_intervals(record: dict) -> dict[str, tuple[float, float]]:
    """The primary 95 % intervals less the shared uncertainty (:func:`common_sd`): name -> (low, high), SI units.

    calibrated.json widens each side of an interval in quadrature, half-width h -> sqrt(h^2 + (q s)^2) for each
    widening s at the level's quantile q (``interval_widening.what``); removing the shared s is the inverse,
    sqrt(max(h^2 - (q s)^2, 0)), side by side about the calibrated value. What is left is the log's own uncertainty.
    """
    values, intervals = calibrated_values(record), primary_intervals(record)
    sd = common_sd(record)
    q = float((record.get("interval_widening") or {}).get("level_quantile", 0.0))
    out = {}
    for n, (lo, hi) in intervals.items():
        shared = (q * sd.get(n, 0.0)) ** 2
        if shared == 0.0:  # nothing shared: the interval itself (the round trip below could move it by a rounding)
            out[n] = (lo, hi)
            continue
        v = values.get(n, 0.5 * (lo + hi))
        out[n] = (v - math.sqrt(max((v - lo) ** 2 - shared, 0.0)), v + math.sqrt(max((hi - v) ** 2 - shared, 0.0)))
    return out


def calibrated_values(record: dict) -> dict[str, float]:
    """The calibrated parameter values of a record: name -> value (SI)."""
    return {n: float(v) for n, v in record["parameters"].items()}


def rmse_after(record: dict) -> float:
    """RMSE of the calibrated torque against the log (N m per motor)."""
    return float(record["metrics"]["rmse_after_Nm"])


# --- the baseline ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Baseline:
    """What every log is compared with: values, intervals and the intervals a change is judged by (without the
    uncertainty every log shares, :func:`change_intervals`), by parameter name (SI)."""

    source: str  # "first good log <id>" or the --baseline path
    log: str | None  # the fleet log it is, or None for a file
    values: dict
    intervals: dict
    change: dict

    def record(self) -> dict:
        return {"source": self.source, "log": self.log, "parameters": self.values,
                "intervals": {n: list(v) for n, v in self.intervals.items()},
                "change_intervals": {n: list(v) for n, v in self.change.items()}}


def baseline_from_record(record: dict, source: str, log: str | None) -> Baseline:
    return Baseline(source, log, calibrated_values(record), primary_intervals(record), change_intervals(record))


def read_baseline(path: str | Path, press: PressData, names) -> Baseline:
    """A ``--baseline calibrated.json``, read by the one reader of calibration intervals (which refuses a file
    made on another press); refused too when it calibrated none of the parameters ``names`` the monitor calibrates."""
    doc = read_json(str(path), press, "--baseline")  # read once: the intervals and the shared uncertainty's record
    values, intervals = intervals_of(doc)
    if not set(names) & set(intervals):
        raise PressDataError(str(path), "intervals", sorted(intervals),
                             f"must include at least one of the monitored parameters ({', '.join(names)}): nothing could be compared")
    values = {n: float(v) for n, v in values.items()}
    change = change_intervals({**doc.value, "parameters": values, "intervals": intervals})
    return Baseline(str(path), None, values, intervals, change)


# --- the rules --------------------------------------------------------------------------------------------
def overlaps(a: tuple[float, float], b: tuple[float, float]) -> bool:
    """True when the closed intervals a and b share a point."""
    return a[0] <= b[1] and b[0] <= a[1]


@dataclass(frozen=True)
class PoorFitRule:
    """The fleet's typical RMSE after calibration and the threshold above which a fit is poor (N m)."""

    logs: int
    median_Nm: float
    mad_Nm: float
    threshold_Nm: float  # inf when there are too few logs to judge

    def record(self, rules: MonitorRules) -> dict:
        return {"logs": self.logs, "median_rmse_after_Nm": self.median_Nm, "mad_rmse_after_Nm": self.mad_Nm,
                "threshold_Nm": self.threshold_Nm if math.isfinite(self.threshold_Nm) else None,
                "rule": f"rmse_after_Nm > median + max({rules.mad_factor:g} x 1.4826 x MAD, {rules.relative_floor:g} x median) "
                        f"over the press's calibrated logs; judged from {rules.min_logs} logs on ({rules.source})"}


def poor_fit_rule(rmses_Nm, rules: MonitorRules) -> PoorFitRule:
    """The poor-fit threshold from the RMSEs after calibration of the logs that calibrated (N m)."""
    x = np.asarray(list(rmses_Nm), dtype=float)
    if x.size == 0:
        return PoorFitRule(0, math.nan, math.nan, math.inf)
    med = float(np.median(x))
    mad = float(np.median(np.abs(x - med)))
    if x.size < rules.min_logs:
        return PoorFitRule(int(x.size), med, mad, math.inf)
    return PoorFitRule(int(x.size), med, mad, med + max(rules.mad_factor * 1.4826 * mad, rules.relative_floor * med))


def choose_baseline(entries: list[dict], poor: set[str]) -> Baseline | None:
    """The first log (in recorded order) that calibrated and does not fit poorly; None if there is none."""
    for e in entries:
        if e["status"] == "ok" and e["log"] not in poor:
            return baseline_from_record(e["record"], f"first good log {e['log']}", e["log"])
    return None


def parameter_alarms(entries: list[dict], baseline: Baseline, poor: set[str]) -> list[dict]:
    """One alarm per (log, parameter) whose change interval no longer overlaps the baseline's, in log order.

    Logs up to and including a fleet baseline are not judged; failed and poorly fitting logs raise none.
    """
    alarms = []
    start = 0
    if baseline.log is not None:
        start = next(i for i, e in enumerate(entries) if e["log"] == baseline.log) + 1
    for e in entries[start:]:
        if e["status"] != "ok" or e["log"] in poor:
            continue
        values, intervals = calibrated_values(e["record"]), primary_intervals(e["record"])
        change = change_intervals(e["record"])
        for name, cv in change.items():
            if name not in baseline.change or overlaps(cv, baseline.change[name]):
                continue
            b, bc, v = baseline.values[name], baseline.change[name], values[name]
            direction = "fell" if v < b else "rose"
            shared = "" if cv == intervals[name] and bc == baseline.intervals[name] else \
                " (without the job force tolerance's share, which every log of this press and cushion carries alike)"
            alarms.append({
                "kind": "parameter_change", "parameter": name, "log": e["log"], "recorded": e["recorded"],
                "value": v, "baseline": b, "interval": list(intervals[name]), "baseline_interval": list(baseline.intervals[name]),
                "change_interval": list(cv), "baseline_change_interval": list(bc),
                "change_percent": 100.0 * (v - b) / b if b else None,
                "reason": f"{name} {direction} from {b:.6g} to {v:.6g}: its 95 % interval{shared} [{cv[0]:.6g}, {cv[1]:.6g}] no "
                          f"longer overlaps the baseline's [{bc[0]:.6g}, {bc[1]:.6g}] ({baseline.source})",
            })
    return alarms


def poor_fit_alarms(entries: list[dict], rule: PoorFitRule) -> list[dict]:
    """One alarm per log whose RMSE after calibration exceeds the rule's threshold."""
    out = []
    for e in entries:
        if e["status"] != "ok":
            continue
        r = rmse_after(e["record"])
        if r > rule.threshold_Nm:
            out.append({
                "kind": "poor_fit", "parameter": "rmse_after_Nm", "log": e["log"], "recorded": e["recorded"],
                "value": r, "baseline": rule.median_Nm, "interval": None, "threshold_Nm": rule.threshold_Nm,
                "reason": f"poor fit: RMSE after calibration {r:.1f} N m is above the threshold {rule.threshold_Nm:.1f} N m "
                          f"(fleet median {rule.median_Nm:.1f} N m): no parameter values explain this log; check the sensor "
                          "and the process (die, cushion) before reading its parameters as wear",
            })
    return out


def assess(entries: list[dict], rules: MonitorRules, baseline: Baseline | None = None) -> dict:
    """Apply the rules to the ordered log entries (``log, recorded, status, record | error``).

    Returns ``baseline`` (a :class:`Baseline` or None), ``poor_fit`` (a :class:`PoorFitRule`), ``poor`` (the
    set of poorly fitting logs) and ``alarms`` (in log order; within a log the poor fit first, then parameter changes).
    """
    rule = poor_fit_rule([rmse_after(e["record"]) for e in entries if e["status"] == "ok"], rules)
    pf = poor_fit_alarms(entries, rule)
    poor = {a["log"] for a in pf}
    base = baseline if baseline is not None else choose_baseline(entries, poor)
    changes = parameter_alarms(entries, base, poor) if base is not None else []
    order = {e["log"]: i for i, e in enumerate(entries)}
    alarms = sorted(pf + changes, key=lambda a: order[a["log"]])  # stable: a log's poor fit before its changes
    return {"baseline": base, "poor_fit": rule, "poor": poor, "alarms": alarms}
