"""The console text of a calibration: the summary lines the 'calibrate' command prints, and its warnings."""
from __future__ import annotations

import math
from pathlib import Path

from calibration.identification.force_accuracy import ACCURACY_WARNING
from calibration.identification.process_force import FORCE_WARNING
from calibration.identification.run import Calibration


def warning_lines(warnings) -> list[str]:
    """The warnings of a calibration as stderr lines: 'WARNING:' for a model that is not adequate for the log (its
    intervals do not cover the model error), for a process force neither logged nor known well enough for
    eta_gear (:data:`calibration.identification.process_force.FORCE_WARNING`), for a logged force whose accuracy
    moves the estimate too far or whose scale the log shows off (:data:`calibration.identification.force_accuracy.
    ACCURACY_WARNING`) and for a held parameter the log disagrees with (:mod:`calibration.identification.held`),
    'warning:' for the rest."""
    return [f"{'WARNING' if w.startswith(('MODEL NOT ADEQUATE', FORCE_WARNING, ACCURACY_WARNING, 'HELD PARAMETER')) else 'warning'}: {w}"
            for w in warnings]


def signed(x: float) -> str:
    """A whole number with its sign, never '-0' (a value that rounds to zero)."""
    return f"{int(round(x)) + 0:+d}" if math.isfinite(x) else str(x)


def calibrate_lines(cal: Calibration, rec: dict, logs: list[str], out: str, seconds: float) -> list[str]:
    """The summary of a calibration for the terminal: errors before and after, the methods compared, the values
    with their intervals, identifiability notes, the validation, and the files written in ``seconds`` s."""
    m = rec["metrics"]
    lines = [f"{'SYNTHETIC ' if cal.log.synthetic else ''}log {', '.join(map(str, logs))}: "
             f"{'+'.join(str(lg.strokes) for lg in cal.logs)} strokes; method {rec['method']}: "
             f"RMSE {m['rmse_before_Nm']:.1f} -> {m['rmse_after_Nm']:.1f} N m, peak error {signed(m['peak_error_before_Nm'])} -> "
             f"{signed(m['peak_error_after_Nm'])} N m, "
             f"thermal error {100 * m['thermal_error_before']:+.2f} % -> {100 * m['thermal_error_after']:+.2f} %"]
    if len(cal.runs) > 1:
        low = rec["objective_eq28_minimum_of_methods"]
        for r in cal.runs:
            lines.append(f"  {r.method:<24} Eq. 28 {r.objective:.6f} ({100 * (r.objective - low) / low:+.3f} % above the minimum)  "
                         f"{r.cycles:>6} model cycles  {r.time_s:.1f} s")
        lines.append(f"  minimum of all methods: Eq. 28 = {low:.6f}")
    jr = rec["joint_region"]
    for n, x in rec["parameters"].items():
        lo, hi = rec["intervals"][n]
        jlo, jhi = jr["box"][n]
        lines.append(f"  {n:>9} = {x:.6g}  ({100 * jr['level']:g} % interval {lo:.6g} .. {hi:.6g}; joint region {jlo:.6g} .. {jhi:.6g})")
    lines.append(f"  {100 * jr['level']:g} % interval: this parameter alone (one at a time); joint region: every parameter at once "
                 f"({jr['method_short']})")
    if cal.bootstrap is not None:
        lines.append(f"  intervals: parametric bootstrap, {cal.bootstrap.refits} refits, {cal.bootstrap.cycles} model cycles, "
                     f"{cal.bootstrap_time_s:.1f} s")
    lines += [f"  - {s}" for s in rec["identifiability"][1:]]
    lines += [f"  {line}" for line in verdict_lines(cal)]
    if cal.motor_shares is not None:
        lines.append(f"  {cal.motor_shares.line()}")
    lines += [f"  note: {n}" for n in cal.notes]
    v = rec.get("validation")
    if v:
        fitted = (f"{100 * v['shared_samples_with_fit']:.3g} % of its samples fitted" if v.get("shared_samples_with_fit")
                  else "not fitted")
        lines.append(f"validation on {'SYNTHETIC ' if v['synthetic'] else ''}log {v['log']} ({fitted}): RMSE {v['rmse_before_Nm']:.1f} -> "
                     f"{v['rmse_after_Nm']:.1f} N m, peak error {v['peak_error_before_Nm']:+.0f} -> {v['peak_error_after_Nm']:+.0f} N m, "
                     f"thermal error {100 * v['thermal_error_before']:+.2f} % -> {100 * v['thermal_error_after']:+.2f} %")
    lines.append(f"-> {Path(out)}/calibrated.json, table4.csv/.md, figure5.png{', solvers.csv' if len(cal.runs) > 1 else ''} ({seconds:.1f} s)")
    return lines


def verdict_lines(cal: Calibration) -> list[str]:
    """The recording correction and the adequacy verdict in one line each, for the console."""
    out = [f"recording: {cal.recording.statement()}"] if cal.recording is not None else []
    if cal.process_force_line:
        out.append(cal.process_force_line)
    a = cal.adequacy
    if a is not None:
        out.append(f"adequacy: {'adequate' if a.adequate else 'NOT ADEQUATE'} (lack-of-fit F = {a.lack_of_fit_ratio:.2f}, "
                   f"p = {a.p_value:.2g}; residual lag-1 {a.residual_lag1:.2f}, noise {a.pure_error_lag1:.2f}; suspects: "
                   + (", ".join(f"{t.name} (t = {t.t:.1f}, {t.size:.3g} {t.unit})" for t in a.suspects) or "none") + ")")
    return out
