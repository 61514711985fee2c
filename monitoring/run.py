"""``servo-press strokes``: every stroke of a press's drive logs into the per-stroke store, then the drift chart.

Each log is one task (:func:`log_strokes`, on local worker processes or a Dask cluster through
:func:`calibration.fleet.cluster.run_tasks`, as ``monitor``'s calibrations): the worker reads the press, the job, the
calibration and the log, and returns the log's stroke records; this process writes them to the store (one Parquet file
per log and day, named by the log's content: a log given again replaces its own file). Then the press's efficiency
ratio, stroke by stroke in time order from the whole store, runs through the CUSUM (:mod:`monitoring.drift`), its
baseline the press's first ``baseline_strokes`` strokes: ``STORE/_reports/<press>/drift.json`` and ``trend.png``.
"""
from __future__ import annotations

import math
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from press_io.errors import PressDataError, ServoPressError
from press_io.outputs import claim, versions, write_json
from press_model.jobs import load_job
from press_model.params import read_joint_box
from press_model.press_data import load_press

from calibration.fleet.cluster import Workers, find_logs, run_tasks
from monitoring.drift import Cusum
from monitoring.rules import load_rules
from monitoring.store import MARKER, query, write_records
from monitoring.strokes import (SCHEMA_VERSION, check_motor_columns, log_records, log_tonnage, motor_strokes, motor_turns, peak_seen,
                               peak_zone)
from monitoring.swings import is_pendulum, swing_tonnage
from monitoring.tonnage import not_observable_text



@dataclass(frozen=True)
class StrokeTask:
    """One log of a ``strokes`` run, as paths a worker opens itself (built-in names as they are)."""

    path: Path
    press: str | None
    job: str
    params: str
    rules: str | None
    press_id: str
    single_thread: bool


def log_strokes(task: StrokeTask, loaded: tuple | None = None) -> dict:
    """The stroke records of one log (runs on a worker): ``{"status": "ok", "records", "log_sha256"}`` or ``{"status":
    "failed", "error"}``; never raises, so one bad log cannot stop the others. ``loaded``: (press, job, parameters, box,
    rules) as this process read them."""
    from calibration.fleet.cluster import one_thread, file_sha256
    from calibration.traces.drive_log import grid_rows, read_log_rows, recorded_time
    from press_model.model import PressModel

    if task.single_thread:
        one_thread()
    try:
        press, job, params, box, rules = loaded if loaded is not None else _load(task)
        rows = read_log_rows(task.path)
        check_motor_columns(rows, press)
        rec = recorded_time(rows.comments, str(task.path))
        pm = PressModel(press)
        if is_pendulum(rows):  # the crank swings back: cut at its turning points, one record per working swing
            lt, log = swing_tonnage(press, job, params, box, rows, rules, pm=pm)
            motors = motor_strokes(rows, log.swing_of_row, lt.turns)
        else:
            log = grid_rows(rows, press.drive.gear_ratio, press.motor.rated_torque)
            lt = log_tonnage(press, job, params, box, log, rules, pm=pm)
            motors = motor_turns(rows, lt.turns)
        records = log_records(lt, pm, log, rules, task.press_id, rec[1] if rec else None, motors, job)
        zone = peak_zone(lt.fmap, job, rules)
        return {"status": "ok", "records": records, "log_sha256": file_sha256(Path(task.path)),
                "not_observable": not_observable_text(lt.fmap.theta, lt.est.observable),
                "peak_unseen": None if peak_seen(zone, lt.est.observable, rules) else not_observable_text(lt.fmap.theta, ~zone)}
    except ServoPressError as exc:
        return {"status": "failed", "error": str(exc)}
    except Exception as exc:  # noqa: BLE001 (reported per log so that the others go on)
        return {"status": "failed", "error": f"unexpected {type(exc).__name__}: {exc}"}


def _load(task: StrokeTask) -> tuple:
    press = load_press(task.press)
    params, box, _ = read_joint_box(task.params, press)
    return press, load_job(task.job), params, box, load_rules(task.rules)


def _check_store(store: Path) -> None:
    """A store folder is new, empty, or one this command made (its store.json): nothing else is written into."""
    if store.exists() and (not store.is_dir() or (any(store.iterdir()) and not (store / MARKER).is_file())):
        raise PressDataError(str(store), "--out", str(store), "holds files that are not a stroke store (no store.json): give a "
                             "new folder or one `servo-press strokes` wrote; nothing of yours is written into")


CHARTED = {  # the per-stroke statistics charted, and what a shift of each says
    "efficiency_ratio": "the motoring torque against the calibrated model's: up when eta_gear falls (wear), down when it rises",
    "residual_rms_Nm": "the model's misfit outside the process: up when something the model has not (a fault, a sensor) appears",
}


def drift_report(store: Path, press_id: str, rules) -> dict:
    """The press's CUSUM of each :data:`CHARTED` statistic over the store's strokes in time order: baseline (the first
    ``baseline_strokes``), limit, alarms (stroke, time, log). Each chart alone holds the stated in-control run length."""
    cols = ", ".join(CHARTED)
    rows = query(store, f"SELECT tdc_time, stroke_index, source, peak_force_N, {cols} FROM strokes WHERE press = ? "
                        "ORDER BY tdc_time, source, stroke_index", [press_id])  # none yet: no rows (the table exists)
    d = rules.drift
    out = {"press": press_id, "strokes": len(rows), "in_control_strokes_per_chart": d.in_control_strokes,
           "reference_sd": d.reference_sd, "baseline_strokes": d.baseline_strokes, "charts": {}, "alarms": []}
    series = {}
    for j, (name, meaning) in enumerate(CHARTED.items()):
        values = np.array([r[4 + j] for r in rows], dtype=float)
        finite = int(np.sum(np.isfinite(values[:d.baseline_strokes])))
        if len(values) < d.baseline_strokes or finite < 30:
            out["note"] = (f"{len(rows)} strokes, fewer than the baseline's {d.baseline_strokes} ([drift] baseline_strokes): "
                           "no drift chart yet")
            series[name] = (values, None)
            continue
        chart = Cusum.from_baseline(values[:d.baseline_strokes], d.in_control_strokes, d.reference_sd)
        after = chart.run(values[d.baseline_strokes:]) + d.baseline_strokes
        out["charts"][name] = {"meaning": meaning, "mean": chart.mean, "sd": chart.sd, "decision_limit_sd": chart.h,
                               "delay_of_one_sd_step": chart.detection_delay(1.0), "alarms": len(after)}
        out["alarms"] += [{"statistic": name, "stroke": int(i), "time": str(rows[i][0]), "source": rows[i][2],
                           "stroke_index": int(rows[i][1]), "value": float(values[i])} for i in after]
        series[name] = (values, after)
    return {**out, "_series": (rows, series)}


def trend_figure(report: dict, job_force: float, rules, title: str):
    """Peak force per stroke against the job's band, and each charted statistic with its CUSUM's alarms."""
    from press_model.plots import pyplot

    plt = pyplot()
    rows, series = report["_series"]
    x = np.arange(len(rows))
    peak = np.array([r[3] for r in rows], dtype=float)
    fig, axes = plt.subplots(1 + len(series), 1, figsize=(9, 2.4 * (1 + len(series))), sharex=True)
    a = axes[0]
    a.plot(x, peak / 1e3, ".", ms=2, color="C0", label="peak force (virtual tonnage)")
    for frac, name in ((rules.alarms.overload_of_job_force, "Overload"), (1.0, "job's force"),
                       (rules.alarms.process_low_of_job_force, "ProcessForce low")):
        a.axhline(frac * job_force / 1e3, color="k" if frac == 1.0 else "C3", lw=0.8, ls="-" if frac == 1.0 else "--",
                  label=f"{name} {frac:.0%}")
    a.set_ylabel("peak force (kN)")
    for b, (name, (values, alarms)) in zip(axes[1:], series.items()):
        b.plot(x, values, ".", ms=2, color="C1", label=name)
        if alarms is not None and len(alarms):
            b.plot(alarms, values[alarms], "x", color="C3", label="CUSUM alarm")
        b.set_ylabel(name)
    axes[-1].set_xlabel("stroke (time order)")
    for ax in axes:  # legends beside the axes, off the points
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def run_strokes(logs: str, press: str | None, job: str, params: str, press_id: str, store: str, rules_path: str | None,
                workers: Workers) -> list[str]:
    """The ``strokes`` command: every log of ``logs`` into ``store`` under ``press_id``, then its drift report; returns
    the lines to print."""
    from press_model.plots import save

    if not press_id or any(c in press_id for c in "/\\='\""):
        raise PressDataError("--press-id", "--press-id", press_id, "must be a non-empty name without / \\ = or quotes (a folder name of the store)")
    out = Path(store)
    _check_store(out)
    loaded = _load(StrokeTask(Path(logs), press, job, params, rules_path, press_id, False))
    rules = loaded[-1]
    found = find_logs(logs, exclude=out)
    tasks = [StrokeTask(f.path.resolve(), press, job, str(Path(params).resolve()), rules_path, press_id, workers.single_thread)
             for f in found if f.error is None]
    lines, written, blind, unseen = [], 0, set(), set()
    failed = [f"{f.path.name}: {f.error}" for f in found if f.error is not None]  # its date line unreadable: no stroke of it
    t0 = time.perf_counter()
    made = not out.exists()
    with claim(out, str(out)):
        out.mkdir(parents=True, exist_ok=True)
        write_json(out / MARKER, {"what": "servo-press strokes: one Parquet record per stroke, partitioned press=/day=",
                                  "schema": SCHEMA_VERSION, "versions": versions()})

        def on_result(task: StrokeTask, res: dict) -> None:
            nonlocal written
            if res["status"] != "ok":
                failed.append(f"{task.path.name}: {res['error']}")
                return
            written += write_records(res["records"], out, res["log_sha256"].removeprefix("sha256:")[:16])
            blind.add(res["not_observable"])
            if res["peak_unseen"]:
                unseen.add(res["peak_unseen"])

        run_tasks(tasks, workers.count or 1, workers.scheduler, on_result, loaded if (workers.count or 1) == 1 else None,
                  fn=log_strokes)
        if failed and not written:  # nothing the run was asked for was made: an error, each log's reason in its one line
            if made:  # the store this run began holds only its store.json: gone again
                shutil.rmtree(out)
            raise ServoPressError(f"no stroke recorded: {len(failed)} of {len(found)} log(s) failed: " + "; ".join(failed))
        report = drift_report(out, press_id, rules)
        folder = out / "_reports" / press_id
        folder.mkdir(parents=True, exist_ok=True)
        force = max(abs(f) for f in loaded[1].process.forces)
        save(trend_figure(report, force, rules, f"{press_id}: {report['strokes']} strokes"), folder / "trend.png")
        write_json(folder / "drift.json", {k: v for k, v in report.items() if not k.startswith("_")} |
                   {"rules": rules.source, "versions": versions()})
    seconds = time.perf_counter() - t0
    lines.append(f"{written} strokes of {len(found) - len(failed)} logs into {out} in {seconds:.1f} s "
                 f"({written / seconds if seconds > 0 else math.inf:.3g} strokes/s)")
    lines += [f"force not observable at {b} (dead centres, the die-contact transient): no force estimate, no alarm there"
              for b in sorted(blind)]
    lines += [f"the job's peak zone ({z}) is not observable on this press: peak force not recorded (NaN, peak_observable "
              "false), no ProcessForce alarm; Overload from the largest observable force" for z in sorted(unseen)]
    if report.get("note"):
        lines.append(f"drift: {report['note']}")
    for name, c in report["charts"].items():
        lines.append(f"drift of {name}: {c['alarms']} CUSUM alarm(s) over {report['strokes']} strokes (limit "
                     f"{c['decision_limit_sd']:.2f} sd: one false alarm in {rules.drift.in_control_strokes:,.0f} strokes)")
    lines += [f"FAILED {f}" for f in failed]
    lines.append(f"-> {folder / 'drift.json'}, {folder / 'trend.png'}")
    return lines
