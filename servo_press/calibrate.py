"""The 'calibrate' command: its inputs read once (:mod:`calibration.identification.inputs`), the fit
(:func:`calibration.identification.run.calibrate`), and its folder: calibrated.json (:mod:`calibration.identification.record`),
table4.csv / table4.md / solvers.csv (:mod:`calibration.identification.report`) and figure5.png
(:mod:`calibration.identification.figure`), with the lines it prints (:mod:`calibration.identification.console`).
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from press_io.errors import ServoPressError
from press_model.jobs import Job, load_job
from press_io.outputs import output_folder, write_json
from press_model.plots import save
from press_model.press_data import PressData, load_press

from calibration.identification.console import calibrate_lines, warning_lines
from calibration.identification.figure import figure5
from calibration.identification.inputs import (FitChoice, LogFormat, calibration_parameters, read_log,
                                              refuse_fitted_log_as_validation)
from calibration.identification.record import result_record
from calibration.identification.report import write_report
from calibration.identification.run import Calibration, calibrate
from calibration.identification.settings import METHODS, CalibrationSettings


def calibrate_job(press: str | None, job, log, validate: str | None, fmt: LogFormat, fit: FitChoice,
                  out: str) -> tuple[list[str], list[str]]:
    """The 'calibrate' command: every input read and checked once (the press, each distinct job, the parameters and the
    channel map before the output folder's path is checked, then each log and ``validate``), then
    :func:`calibration.identification.run.calibrate` on the rows read and :func:`write_outputs` into the folder ``out``
    (written whole at the end). ``fit.method``: one of :data:`calibration.identification.methods.METHODS`, "all", or
    None for the job's default. ``log`` and ``job`` may be lists (several ``--log`` / ``--job``): the logs are fitted
    jointly, paired with the jobs in order, one job serving all (the first job's [calibration] settings apply; a
    warning names the keys where another job's differ). ``fmt``: how every log and ``validate`` are read.

    Returns (the warning lines for stderr, the summary lines) for the command to print.
    """
    logs = [log] if isinstance(log, str) else list(log)
    jobs = [job] if isinstance(job, str) else list(job)
    if len(jobs) not in (1, len(logs)):
        raise ServoPressError(f"--job given {len(jobs)} times for {len(logs)} --log: give one --job for all logs, or one per "
                              "--log (paired in order)")
    press_ = load_press(press)
    loaded = {j: load_job(j) for j in dict.fromkeys(jobs)}  # a job named for several logs is read once
    jobs_ = [loaded[j] for j in jobs]
    cs = CalibrationSettings.from_job(jobs_[0])
    methods = list(METHODS) if fit.method == "all" else [fit.method or cs.default_method]
    cs = dataclasses.replace(cs, parameters=calibration_parameters(fit.parameters, press_, jobs_[0], cs))
    cmap = fmt.read_map(press_)
    t0 = time.perf_counter()
    # the output folder's path is checked before the logs are read (an --out that holds an input is refused as such);
    # a log refused below leaves no folder behind
    with output_folder(out, [press, *jobs, *logs, fit.parameters, validate, fmt.channel_map], "calibrate") as tmp:
        rows = [read_log(lg, press_, fmt.torque_unit, cmap) for lg in logs]
        vrows = read_log(validate, press_, fmt.torque_unit, cmap) if validate is not None else None
        if vrows is not None:
            for r in rows:
                refuse_fitted_log_as_validation(r, vrows)
        pairs = [(r, jobs_[min(i, len(jobs_) - 1)]) for i, r in enumerate(rows)]
        cal = calibrate(press_, jobs_[0], rows[0], methods, fit.seed, cs, validate=vrows, more_logs=pairs[1:])
        rec = write_outputs(cal, press_, jobs_[0], fit.seed, tmp)
    freed = [cal.held["statement"]] if cal.held and cal.held["statement"] else []  # said, though the freed fit is to trust
    return warning_lines([*cal.log.warnings, *freed, *cal.warnings, *cal.share_warnings]), calibrate_lines(cal, rec, logs, out,
                                                                                                         time.perf_counter() - t0)


def write_outputs(cal: Calibration, press: PressData, job: Job, seed: int, out: Path) -> dict:
    """Write calibrated.json, table4.csv/.md, solvers.csv and figure5.png; returns the calibrated.json record."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rec = result_record(cal, press, job, seed)
    write_report(cal, rec, out)
    save(figure5(cal), out / "figure5.png")
    write_json(out / "calibrated.json", rec)
    return rec
