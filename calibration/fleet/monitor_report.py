"""The files of ``servo-press monitor``: trend.csv, alarms.json, trend.png and report.md.

All are made from the per-log results and the rules' verdict (:func:`calibration.fleet.monitor.assess`), with no
wall times and no count of this run's work in them, so that a rerun (or a resumed run) gives the same bytes.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

from press_model.jobs import load_job
from press_io.outputs import atomic_write_text, check_output_folder, claim, refuse_overwrite_input, versions, write_json, write_table
from press_model.plots import save, subplots, tight_layout
from press_model.press_data import load_press

from calibration.traces.drive_log import parse_recorded
from calibration.fleet.cluster import Workers, is_monitor_folder, run_fleet
from calibration.fleet.monitor import Baseline, MonitorRules, assess, calibrated_values, load_rules, primary_intervals, read_baseline
from calibration.identification.inputs import FitChoice, LogFormat
from calibration.identification.settings import CalibrationSettings

FILES = ("trend.csv", "alarms.json", "trend.png", "report.md")


def monitor_fleet(press: str, job: str, logs: str, baseline: str | None, out: str, fit: FitChoice, fmt: LogFormat,
                  workers: Workers) -> list[str]:
    """The 'monitor' command: calibrate every log of ``logs`` with ``fit``'s method and seed on ``workers``
    (:func:`calibration.fleet.cluster.run_fleet`, an earlier monitor folder ``out`` is resumed), assess the trends
    against ``baseline`` and write the monitor outputs into ``out``.

    ``fmt``: how the logs are read (their torque unit, or the channel map they are read through). The output folder,
    the inputs, the map and the baseline are checked before any log is calibrated. Returns the lines to print
    (:func:`monitor_lines`).
    """
    out_ = Path(out)
    inputs = [press, job, baseline, fmt.channel_map] + ([logs] if Path(logs).is_dir() else [])
    if not is_monitor_folder(out_):  # a folder of an earlier (or interrupted) monitor run is resumed, not replaced
        check_output_folder(out, inputs, "monitor")
    for name in FILES:
        refuse_overwrite_input(out_ / name, inputs)
    rules = load_rules()
    press_, job_ = load_press(press), load_job(job)  # read once, for the baseline and every calibration in this process
    base = None
    if baseline is not None:  # checked before any log is calibrated
        base = read_baseline(baseline, press_, CalibrationSettings.from_job(job_).parameters)
    if workers.scheduler is not None and workers.count is not None:
        print("servo-press: note: --workers is for local runs; a cluster's workers are set where they are started", file=sys.stderr)
    t0 = time.perf_counter()
    with claim(out_, str(out)):  # a second monitor on the same --out is refused while this one runs
        fleet = run_fleet(logs, press, job, out_, fit, fmt, workers, loaded=(press_, job_))
        verdict = assess(fleet["entries"], rules, base)
        rec = write_monitor_outputs(out_, fleet, verdict, rules, baseline)
    return monitor_lines(fleet, rec, out_, time.perf_counter() - t0)


def monitor_lines(fleet: dict, rec: dict, out: Path, seconds: float) -> list[str]:
    """The summary of a monitor run for the terminal: logs calibrated in ``seconds`` s, the first alarm of each
    parameter, the poor fits and the failures."""
    changes = [a for a in rec["alarms"] if a["kind"] == "parameter_change"]
    poor = [a for a in rec["alarms"] if a["kind"] == "poor_fit"]
    first = {}
    for a in changes:
        first.setdefault(a["parameter"], a)
    # an alarm is one parameter of one log: the count says over how many parameters, whose first alarms are listed
    over = (f" on {len(first)} parameter{'s' if len(first) != 1 else ''} (the first of each below, every one in alarms.json)"
            if len(changes) > len(first) else "")
    lines = [f"{'SYNTHETIC ' if rec['synthetic_logs'] else ''}fleet of {rec['logs']} logs of {rec['press']}: {rec['calibrated']} calibrated "
             f"({fleet['calibrated']} now, {fleet['reused']} reused) in {seconds:.1f} s, {len(rec['failed'])} failed; "
             f"{len(changes)} parameter alarm{'s' if len(changes) != 1 else ''}{over}, {len(poor)} poor fit{'s' if len(poor) != 1 else ''} -> {out}"]
    lines += [f"  alarm from {a['log']}{' (' + a['recorded'] + ')' if a['recorded'] else ''}: {a['reason']}" for a in first.values()]
    lines += [f"  poor fit {a['log']}: RMSE {a['value']:.1f} N m > {a['threshold_Nm']:.1f} N m" for a in poor]
    lines += [f"  failed {f['log']}: {f['error']}" for f in rec["failed"]]
    return lines


def _synthetic(entries: list[dict]) -> list[str]:
    return [e["log"] for e in entries if e["status"] == "ok" and e["record"]["log"]["synthetic"]]


def trend_rows(entries: list[dict], names: list[str], poor: set[str]) -> tuple[list[str], list[dict]]:
    """Columns and rows of trend.csv: ``log, recorded``, each parameter with its 95 % interval, the RMSEs, and
    ``poor_fit`` (yes / no) and ``status`` (ok / failed: the message is in alarms.json and report.md)."""
    cols = ["log", "recorded"]
    for n in names:
        cols += [n, f"{n}_low", f"{n}_high"]
    cols += ["rmse_before_Nm", "rmse_after_Nm", "poor_fit", "status"]
    rows = []
    for e in entries:
        r = dict.fromkeys(cols, "")
        r.update(log=e["log"], recorded=e["recorded"] or "", status=e["status"])
        if e["status"] == "ok":
            rec = e["record"]
            v, iv = calibrated_values(rec), primary_intervals(rec)
            for n in names:
                if n in v:
                    r[n], (r[f"{n}_low"], r[f"{n}_high"]) = v[n], iv[n]
            r["rmse_before_Nm"] = float(rec["metrics"]["rmse_before_Nm"])
            r["rmse_after_Nm"] = float(rec["metrics"]["rmse_after_Nm"])
            r["poor_fit"] = "yes" if e["log"] in poor else "no"
        rows.append(r)
    return cols, rows


def write_monitor_outputs(out: Path, fleet: dict, verdict: dict, rules: MonitorRules, baseline_arg: str | None) -> dict:
    """Write the four files into ``out``; returns the alarms.json record."""
    out = Path(out)
    entries, press, job, st = fleet["entries"], fleet["press"], fleet["job"], fleet["settings"]
    names = list(st["parameters"])
    base: Baseline | None = verdict["baseline"]
    cols, rows = trend_rows(entries, names, verdict["poor"])
    write_table(out / "trend.csv", cols, rows, digits=10)
    synthetic = _synthetic(entries)
    failed = [{"log": e["log"], "recorded": e["recorded"], "error": e["error"]} for e in entries if e["status"] != "ok"]
    rec = {
        "alarms": verdict["alarms"],
        "failed": failed,
        "synthetic_logs": synthetic,
        "label": "SYNTHETIC drive logs (not measured data)" if synthetic else "",
        **press.identity(),
        "job": job.name, "job_source": job.source,
        "logs": len(entries), "calibrated": sum(e["status"] == "ok" for e in entries),
        "baseline": base.record() if base is not None else None,
        "baseline_argument": baseline_arg,
        "rules": {
            "parameter_change": "alarm when a parameter's 95 % interval on a log no longer overlaps the baseline's 95 % interval, both "
                                "without the uncertainty every log of the press shares (the job force tolerance's share: change_interval); "
                                "logs up to and including a fleet baseline, failed logs and poorly fitting logs are not judged",
            "poor_fit": verdict["poor_fit"].record(rules),
        },
        "settings": st,
        "versions": versions(),
    }
    save(trend_figure(entries, names, base, verdict, synthetic, press.name), out / "trend.png")
    atomic_write_text(out / "report.md", report_markdown(entries, names, rec, verdict))
    write_json(out / "alarms.json", rec)  # last: a folder with alarms.json holds a finished run
    return rec


def _times(entries: list[dict]):
    """x positions of the logs: recording dates when every log has one, else the log's position in the order."""
    if entries and all(e["recorded"] for e in entries):
        return [parse_recorded(e["recorded"], e["log"]) for e in entries], True
    return list(range(len(entries))), False


def trend_figure(entries: list[dict], names: list[str], base: Baseline | None, verdict: dict, synthetic: list[str], press_name: str):
    """Each parameter against time with its 95 % band and the baseline's band, alarms in red; the RMSE after
    calibration with the poor-fit threshold in the last panel."""
    xs, dated = _times(entries)
    ok = [i for i, e in enumerate(entries) if e["status"] == "ok"]
    alarmed = {(a["log"], a["parameter"]) for a in verdict["alarms"]}
    fig, axes = subplots(len(names) + 1, 1, figsize=(9, 1.9 * (len(names) + 1) + 0.6), sharex=True, squeeze=False)
    axes = axes[:, 0]
    for ax, n in zip(axes, names):
        idx = [i for i in ok if n in entries[i]["record"]["parameters"]]
        x = [xs[i] for i in idx]
        v = np.array([calibrated_values(entries[i]["record"])[n] for i in idx])
        iv = np.array([primary_intervals(entries[i]["record"])[n] for i in idx]).reshape(-1, 2)
        if idx:
            ax.fill_between(x, iv[:, 0], iv[:, 1], color="C0", alpha=0.2, lw=0, label="95 % interval")
            ax.plot(x, v, "o-", color="C0", ms=3, lw=1, label="calibrated")
            red = [k for k, i in enumerate(idx) if (entries[i]["log"], n) in alarmed]
            if red:
                ax.plot([x[k] for k in red], v[red], "o", color="C3", ms=6, label="alarm")
        if base is not None and n in base.values:
            ax.axhline(base.values[n], color="k", lw=0.8, ls="--", label="baseline")
            ax.axhspan(*base.intervals[n], color="k", alpha=0.08, lw=0)
        ax.set_ylabel(n, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="best", ncol=4)
    ax = axes[-1]
    x = [xs[i] for i in ok]
    r = [entries[i]["record"]["metrics"]["rmse_after_Nm"] for i in ok]
    ax.plot(x, r, "o-", color="C2", ms=3, lw=1, label="RMSE after calibration")
    poor = [k for k, i in enumerate(ok) if entries[i]["log"] in verdict["poor"]]
    if poor:
        ax.plot([x[k] for k in poor], [r[k] for k in poor], "o", color="C3", ms=6, label="poor fit")
    thr = verdict["poor_fit"].threshold_Nm
    if math.isfinite(thr):
        ax.axhline(thr, color="C3", lw=0.8, ls=":", label="poor-fit threshold")
    for i, e in enumerate(entries):
        if e["status"] != "ok":
            ax.axvline(xs[i], color="C1", lw=0.8, ls="-.")
    ax.set_ylabel("RMSE after [N m]", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    ax.set_xlabel("recorded" if dated else "log (in file-name order; the logs carry no '# recorded:' date)")
    if dated:
        fig.autofmt_xdate()
    title = f"Fleet monitoring: {press_name}, {len(ok)} of {len(entries)} logs calibrated"
    fig.suptitle(title + (" - SYNTHETIC drive logs" if synthetic else ""), fontsize=10)
    tight_layout(fig)
    return fig


def _fmt_iv(iv) -> str:
    return f"[{iv[0]:.5g}, {iv[1]:.5g}]"


def report_markdown(entries: list[dict], names: list[str], rec: dict, verdict: dict) -> str:
    syn = rec["synthetic_logs"]
    base = rec["baseline"]
    st = rec["settings"]
    lines = [f"# Fleet monitoring: {rec['press']}" + (" (SYNTHETIC drive logs)" if syn else ""), ""]
    if syn:
        lines += [f"**SYNTHETIC:** {len(syn)} of the {rec['calibrated']} calibrated logs are marked synthetic (made by "
                  "`servo-press experiment`, not measured); their truth and seed are in each log's `.truth.json`.", ""]
    lines += [f"Press `{rec['press_source']}` (fingerprint `{rec['press_fingerprint']}`), job `{rec['job_source']}`; method "
              f"{st['method']}, seed {st['seed']}; parameters {', '.join(names)}.",
              f"{rec['logs']} logs, {rec['calibrated']} calibrated, {len(rec['failed'])} failed.", ""]
    lines += ["## Baseline", ""]
    if base is None:
        lines += ["No baseline: no log calibrated with a good fit, so no parameter is judged.", ""]
    else:
        lines += [f"{base['source']}:", "", "| parameter | value | 95 % interval |", "|---|---|---|"]
        lines += [f"| {n} | {base['parameters'][n]:.6g} | {_fmt_iv(base['intervals'][n])} |" for n in names if n in base["parameters"]]
        lines += [""]
    lines += ["## Alarms", "", "Rule: " + rec["rules"]["parameter_change"] + ".", ""]
    changes = [a for a in rec["alarms"] if a["kind"] == "parameter_change"]
    if changes:
        first = {}
        for a in changes:
            first.setdefault(a["parameter"], a)
        lines += ["First alarm of each parameter (every alarm is in `alarms.json`):", "",
                  "| parameter | first log | recorded | value | 95 % interval | baseline | change | logs in alarm |", "|---|---|---|---|---|---|---|---|"]
        for n, a in first.items():
            k = sum(1 for b in changes if b["parameter"] == n)
            ch = f"{a['change_percent']:+.2f} %" if a["change_percent"] is not None else ""
            lines.append(f"| {n} | {a['log']} | {a['recorded'] or ''} | {a['value']:.6g} | {_fmt_iv(a['interval'])} | "
                         f"{a['baseline']:.6g} | {ch} | {k} |")
        quiet = [n for n in names if n not in first]
        if quiet:
            lines += ["", f"No alarm: {', '.join(quiet)} (every change interval overlaps the baseline's)."]
    else:
        lines.append("No parameter alarm: every calibrated log's change intervals overlap the baseline's.")
    pf = rec["rules"]["poor_fit"]
    lines += ["", "## Fit quality", "", f"Rule: {pf['rule']}.",
              (f"Median RMSE after calibration {pf['median_rmse_after_Nm']:.1f} N m, MAD {pf['mad_rmse_after_Nm']:.1f} N m, threshold "
               f"{pf['threshold_Nm']:.1f} N m." if pf["threshold_Nm"] is not None else
               f"Only {pf['logs']} calibrated logs: too few to judge a typical fit; no log is flagged."), ""]
    poor = [a for a in rec["alarms"] if a["kind"] == "poor_fit"]
    lines += [f"* {a['log']}: {a['reason']}" for a in poor] or ["No poor fit."]
    lines += ["", "## Failed logs", ""]
    lines += [f"* {f['log']}: {f['error']}" for f in rec["failed"]] or ["None."]
    lines += ["", "## Trend", "", "![trend](trend.png)", "",
              "| log | recorded | " + " | ".join(names) + " | RMSE before / after [N m] | status |",
              "|---|---|" + "---|" * len(names) + "---|---|"]
    for e in entries:
        if e["status"] == "ok":
            v = calibrated_values(e["record"])
            m = e["record"]["metrics"]
            cells = [f"{v[n]:.5g}" if n in v else "" for n in names]
            status = "poor fit" if e["log"] in verdict["poor"] else "ok"
            lines.append(f"| {e['log']} | {e['recorded'] or ''} | " + " | ".join(cells) +
                         f" | {m['rmse_before_Nm']:.1f} / {m['rmse_after_Nm']:.1f} | {status} |")
        else:
            lines.append(f"| {e['log']} | {e['recorded'] or ''} | " + " | ".join("" for _ in names) + " | | failed |")
    v = rec["versions"]
    lines += ["", "Versions: " + ", ".join(f"{k} {x}" for k, x in v.items()) + "."]
    return "\n".join(lines) + "\n"
