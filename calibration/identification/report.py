"""The tables and the markdown report of a calibration: table4.csv and table4.md (theoretical, calibrated, intervals and
relative error beside the paper's Table 4, the adequacy verdict, the accuracy before and after, the validation) and
solvers.csv when several methods ran.
"""
from __future__ import annotations

from pathlib import Path

from calibration.sensitivity.report import paper_figures
from press_model.press_data import is_reference_press
from press_io.outputs import atomic_write_text, write_table

from calibration.identification.run import Calibration


def write_report(cal: Calibration, rec: dict, out: Path) -> None:
    """Write table4.csv, table4.md and (several methods) solvers.csv of ``cal`` into ``out``; ``rec`` is its
    calibrated.json record (:func:`calibration.identification.record.result_record`). The paper's Table 4 and accuracy
    stand beside ours on the reference press only (on another press they are not the user's figures)."""
    paper = paper_figures()["calibration"] if is_reference_press(rec["press_fingerprint"]) else None
    rows = table4_rows(cal, rec, paper["table4"] if paper is not None else None)
    write_table(out / "table4.csv", list(rows[0]), rows, digits=8)
    atomic_write_text(out / "table4.md", table4_markdown(rec, rows, paper, [r.time_s for r in cal.runs]))
    if len(cal.runs) > 1:
        write_table(out / "solvers.csv", ["method", "objective_eq28", "gap_to_minimum_pct", "model_cycles",
                                          *cal.objective.problem.names], solver_rows(cal))


def table4_rows(cal: Calibration, rec: dict, t4: dict | None) -> list[dict]:
    """One row a parameter: theoretical, calibrated, the interval, the joint region, the Jacobian interval and the
    relative error (theoretical - calibrated) / calibrated in %, beside the paper's Table 4 ``t4`` (NaN where it
    has no such parameter; None: no paper columns, a press other than the reference)."""
    p = cal.objective.problem
    rows = []
    for n, th, x in zip(p.names, p.theoretical, cal.best.x):
        pt = t4.get(n) if t4 is not None else None
        (lo, hi), (jlo, jhi) = rec["intervals"][n], rec["intervals_jacobian"][n]
        slo, shi = rec["joint_region"]["box"][n]
        row = {"parameter": n, "theoretical": float(th), "calibrated": float(x), "interval_low": float(lo), "interval_high": float(hi),
               "joint_region_low": float(slo), "joint_region_high": float(shi),
               "jacobian_interval_low": float(jlo), "jacobian_interval_high": float(jhi),
               "relative_error_pct": float(100 * (th - x) / x)}
        if t4 is not None:
            row.update({"paper_theoretical": float(pt[0]) if pt else float("nan"), "paper_calibrated": float(pt[1]) if pt else float("nan"),
                        "paper_relative_error_pct": float(100 * (pt[0] - pt[1]) / pt[1]) if pt else float("nan")})
        rows.append(row)
    return rows


def solver_rows(cal: Calibration) -> list[dict]:
    """solvers.csv: each method's Eq. 28, its gap to the minimum of all methods (%), its model cycles and estimate,
    then the row of the minimum of all methods."""
    names, low = cal.objective.problem.names, min(r.objective for r in cal.runs)
    srows = [{"method": r.method, "objective_eq28": r.objective, "gap_to_minimum_pct": 100.0 * (r.objective - low) / low,
              "model_cycles": r.cycles, **{n: float(x) for n, x in zip(names, r.x)}} for r in cal.runs]
    srows.append({**min(srows, key=lambda r: r["objective_eq28"]), "method": "minimum of all methods", "model_cycles": sum(r.cycles for r in cal.runs)})
    return srows


def table4_markdown(rec: dict, rows: list[dict], paper: dict | None, times_s: list[float]) -> str:
    """table4.md: the Table 4 analogue of ``rows`` (:func:`table4_rows`), the adequacy verdict, the accuracy before and
    after beside the ``paper``'s (None: without the paper's columns, a press other than the reference), what the
    experiment can tell apart, the validation and the solvers (``times_s``)."""
    m = rec["metrics"]
    syn = rec["log"]["synthetic"]
    lines = [f"# Calibration against {'a SYNTHETIC' if syn else 'a measured'} drive log",
             "", f"Log: `{rec['log']['source']}`" + (f" ({rec['log']['label']})" if syn else "") + f"; method {rec['method']}, seed {rec['seed']}.", "",
             "## Table 4 analogue (relative error = (theoretical - calibrated) / calibrated, as in the paper)", "",
             "| parameter | theoretical | calibrated | 95 % interval (this parameter alone) | joint 95 % region (all at once) | Jacobian interval (second opinion) | rel. error |"
             + (" the paper's press: theoretical | the paper's press: calibrated | the paper's press: rel. error |" if paper else ""),
             "|---|---|---|---|---|---|---|" + ("---|---|---|" if paper else "")]
    for r in rows:
        lines.append(f"| {r['parameter']} | {r['theoretical']:.5g} | {r['calibrated']:.5g} | [{r['interval_low']:.5g}, {r['interval_high']:.5g}] | "
                     f"[{r['joint_region_low']:.5g}, {r['joint_region_high']:.5g}] | "
                     f"[{r['jacobian_interval_low']:.5g}, {r['jacobian_interval_high']:.5g}] | {r['relative_error_pct']:+.1f} % |"
                     + (f" {r['paper_theoretical']:.5g} | {r['paper_calibrated']:.5g} | {r['paper_relative_error_pct']:+.1f} % |" if paper else ""))
    lines += ["", f"Intervals: {rec['interval_method']}.", f"They answer: {rec['intervals_question']}.",
              f"Joint region: {rec['joint_region']['question']}; {rec['joint_region']['method']}."]
    if rec.get("measured_peak"):
        lines += [f"Measured peak of Eq. 23: {rec['measured_peak']['method']}."]
    lines += [f"**Warning:** {w}" for w in rec.get("warnings", [])]
    a = rec.get("adequacy")
    if a:
        lines += ["", "## Model adequacy (calibration/identification/adequacy.py)", "",
                  f"{'Adequate' if a['adequate'] else '**Not adequate**'}: lack-of-fit F = {a['lack_of_fit_ratio']:.2f} (p = {a['p_value']:.2g}), "
                  f"residual lag-1 {a['residual_lag1']:.2f} against the noise's {a['pure_error_lag1']:.2f}; suspects: "
                  + (", ".join(a["suspects"]) or "none") + f". {rec['intervals_note']}.", "",
                  "| candidate effect | t | implied size |", "|---|---|---|"]
        lines += [f"| {n} | {t['t']:.1f} | {t['size']:.3g} +/- {t['size_std']:.2g} {t['unit']} |" for n, t in a["score_tests"].items()]
    nz = rec.get("nuisance") or {}
    if "channel_delay_s" in nz:
        lines += ["", f"Recording: channel delay {1e3 * nz['channel_delay_s']:.2f} ms, encoder offset {nz['angle_offset_deg']:+.3f} deg "
                  f"(corrected in the log; {'separable' if nz['separable'] else 'not separable on this motion'}, correlation {nz['correlation']:+.2f})."]
    lines += accuracy_lines(m, paper) + ["", "## What this experiment can tell apart", ""] + [f"* {s}" for s in rec["identifiability"]]
    v = rec.get("validation")
    if v:
        lines += ["", f"## Out-of-sample validation: `{v['log']}`" + (" (SYNTHETIC)" if v["synthetic"] else ""), "",
                  "Predicted with the theoretical and the calibrated parameters; " + (
                      f"{100 * v['shared_samples_with_fit']:.3g} % of this log's samples are fitted ones (part of a fitted "
                      "recording): not wholly out of sample." if v.get("shared_samples_with_fit") else
                      "nothing was fitted to this log."), "",
                  "| figure | theoretical | calibrated |", "|---|---|---|"] + validation_rows(v)
    if len(rec["solver_runs"]) > 1:
        lines += ["", "## Solvers on the same objective", "", "| method | Eq. 28 | above the minimum of all methods | model cycles | time [s] |", "|---|---|---|---|---|"]
        lines += [f"| {r['method']} | {r['objective_eq28']:.6f} | {r['gap_to_minimum_pct']:.3f} % | {r['model_cycles']} | {t:.2f} |"
                  for r, t in zip(rec["solver_runs"], times_s)]
        lines += [f"| minimum of all methods | {rec['objective_eq28_minimum_of_methods']:.6f} | | | |"]
    return "\n".join(lines) + "\n"


def accuracy_lines(m: dict, paper: dict | None) -> list[str]:
    """table4.md's prediction accuracy before and after (``m``: calibrated.json's metrics), beside the paper's press's
    figures when ``paper`` is given (the reference press only)."""
    rows = [("RMSE [N m]", f"{m['rmse_before_Nm']:.1f}", f"{m['rmse_after_Nm']:.1f}", "rmse_before_Nm", "rmse_after_Nm"),
            ("peak error [N m]", f"{m['peak_error_before_Nm']:+.1f}", f"{m['peak_error_after_Nm']:+.1f}", "peak_error_before_Nm", "peak_error_after_Nm"),
            ("peak error incl. die-contact spike [N m]", f"{m['peak_error_with_impact_before_Nm']:+.1f}",
             f"{m['peak_error_with_impact_after_Nm']:+.1f}", None, None),
            ("thermal error (Eq. 24)", f"{100 * m['thermal_error_before']:+.2f} %", f"{100 * m['thermal_error_after']:+.2f} %",
             "thermal_error_before", "thermal_error_after")]
    if paper is None:
        return ["", "## Prediction accuracy", "", "| figure | before | after |", "|---|---|---|"] + [f"| {r[0]} | {r[1]} | {r[2]} |" for r in rows]

    def theirs(key):
        if key is None:
            return ""
        return f"{100 * paper[key]:.1f} %" if key.startswith("thermal") else f"{paper[key]}"

    return (["", "## Prediction accuracy, ours beside the paper's press's", "",
             "| figure | ours: before | ours: after | the paper's press: before | the paper's press: after |", "|---|---|---|---|---|"]
            + [f"| {r[0]} | {r[1]} | {r[2]} | {theirs(r[3])} | {theirs(r[4])} |" for r in rows])


def validation_rows(v: dict) -> list[str]:
    """Markdown table rows of a validation record (theoretical | calibrated)."""
    return [f"| RMSE [N m] | {v['rmse_before_Nm']:.1f} | {v['rmse_after_Nm']:.1f} |",
            f"| peak error [N m] | {v['peak_error_before_Nm']:+.1f} | {v['peak_error_after_Nm']:+.1f} |",
            f"| thermal error (Eq. 24) | {100 * v['thermal_error_before']:+.2f} % | {100 * v['thermal_error_after']:+.2f} % |"]
