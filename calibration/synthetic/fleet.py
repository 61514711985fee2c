"""A SYNTHETIC fleet: one press, N servo-cushion drive logs whose truth drifts from log to log.

``servo-press experiment --fleet N --out DIR`` writes ``DIR/log_000.csv`` ... (each made by
:func:`calibration.synthetic.experiment.write_experiment`, dated by a ``# recorded: <ISO-8601>`` comment line, with
its own ``.truth.json`` sidecar) and ``DIR/fleet.json``: the drift schedule, the seeds and every log's
truth, labelled SYNTHETIC. The schedule (``press_model/data/synthetic_fleet.toml`` or ``--drift FILE``)
moves the truth as wear would (gear efficiency falling, joint friction rising), so that
``servo-press monitor`` has a known drift to find. Nothing in calibration reads the truths.
"""
from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path

from press_io.errors import PressDataError, ServoPressError
from press_model.jobs import Job, load_job
from press_io.outputs import claim, file_out, output_folder, refuse_overwrite_input, versions, write_json
from press_model.params import apply_overrides
from press_model.press_data import PressData, load_press
from press_model.readers import FieldReader, read_toml

from calibration.traces.drive_log import RECORDED
from calibration.synthetic.experiment import (ExperimentSettings, experiment_truth, reference_truth_note, refuse_foreign_log, truth_path,
                                              write_experiment)

SCHEDULE_FILE = "synthetic_fleet.toml"
_FORMAT = "see press_model/data/synthetic_fleet.toml for the format"


@dataclass(frozen=True)
class DriftSchedule:
    """When the logs are dated and how the truth moves. ``drift``: name -> ("per_log", step) or ("values", [...])."""

    source: str
    start: datetime  # UTC
    start_text: str
    interval_days: float
    seed_step: int
    drift: dict

    def truth(self, base: dict, i: int, n: int) -> dict:
        """The truth of log ``i`` of ``n`` (SI units): ``base`` moved by the schedule."""
        out = dict(base)
        for name, (kind, value) in self.drift.items():
            if kind == "values":
                if len(value) != n:
                    raise PressDataError(self.source, f"drift.{name}.values", f"{len(value)} values",
                                         f"must give one value per log: --fleet asks for {n} logs")
                out[name] = value[i]
            else:
                if name not in base:
                    raise PressDataError(self.source, f"drift.{name}", name, "drifts a parameter that has no starting truth: "
                                         "name it in the job's [experiment.truth] or in --truth")
                out[name] = base[name] + i * value
        return out

    def record(self) -> dict:
        return {"source": self.source, "start": self.start_text, "interval_days": self.interval_days, "seed_step": self.seed_step,
                "drift": {n: {k: v} for n, (k, v) in self.drift.items()}}


def load_schedule(path: str | Path | None = None) -> DriftSchedule:
    """Read a drift schedule TOML; ``None`` reads the shipped ``press_model/data/synthetic_fleet.toml``."""
    raw, source = read_toml(path, SCHEDULE_FILE if path is None else None, "--drift", f"must be an existing drift-schedule TOML file ({_FORMAT})")
    rd = FieldReader(source, raw)
    start_text = rd.string(("fleet", "start"))
    try:
        start = datetime.fromisoformat(start_text)
    except ValueError:
        rd.fail(("fleet", "start"), start_text, "must be an ISO-8601 date-time, e.g. '2025-01-06T08:00:00+00:00'")
    start = start.replace(tzinfo=timezone.utc) if start.tzinfo is None else start.astimezone(timezone.utc)
    drift = {}
    for name in rd.table(("drift",), required=False):
        spec = rd.table(("drift", name))
        if set(spec) == {"per_log"}:
            drift[name] = ("per_log", rd.number(("drift", name, "per_log")))
        elif set(spec) == {"values"}:
            vals = rd.node(("drift", name, "values"))
            if not isinstance(vals, list) or not vals:
                rd.fail(("drift", name, "values"), vals, "must be a list of numbers, one truth per log")
            drift[name] = ("values", [rd.number(("drift", name, "values", k)) for k in range(len(vals))])
        else:
            rd.fail(("drift", name), dict(spec), "must be {per_log = <change per log>} or {values = [<truth of each log>, ...]}")
    s = DriftSchedule(source, start, start_text, rd.number(("fleet", "interval_days"), gt=0.0, unit="days"),
                      rd.integer(("fleet", "seed_step"), ge=0, limit=None), drift)
    rd.reject_unread(_FORMAT)
    return s


def log_name(i: int) -> str:
    return f"log_{i:03d}.csv"


def write_fleet(press: PressData, job: Job, truth: dict, seed: int, n: int, out: Path, schedule: DriftSchedule,
                progress=None) -> dict:
    """Write ``n`` SYNTHETIC logs (``log_000.csv`` ...) and ``fleet.json`` into folder ``out``; returns fleet.json's record.

    Log i is dated ``start + i * interval_days``, made with noise seed ``seed + i * seed_step`` and the truth
    ``schedule.truth(truth, i, n)``. A truth outside a parameter's sensitivity range is refused (by the
    press data's overrides) before any file is written.
    """
    if n < 1:
        raise PressDataError("--fleet", "--fleet", n, "must be a whole number of logs >= 1")
    out = Path(out)
    settings = ExperimentSettings.from_job(job)
    truths = [schedule.truth(truth, i, n) for i in range(n)]
    for i, t in enumerate(truths):  # refuse a drift that leaves a parameter's range before writing anything
        apply_overrides(press, t, f"{schedule.source}: the drifted truth of {log_name(i)} (log {i + 1} of {n})")
    logs = []
    for i, t in enumerate(truths):
        when = (schedule.start + timedelta(days=i * schedule.interval_days)).isoformat()
        s = seed + i * schedule.seed_step
        path = out / log_name(i)
        fleet_info = {"fleet": {"synthetic": True, "index": i, "logs": n, "recorded": when, "schedule": schedule.record(),
                                "manifest": "fleet.json"}}
        write_experiment(press, job, t, s, path,
                         extra_comments=(f"{RECORDED} {when}", f"SYNTHETIC fleet log {i + 1} of {n}; drift schedule in fleet.json"),
                         extra_provenance=fleet_info, settings=settings)
        logs.append({"log": path.name, "truth_file": truth_path(path).name, "recorded": when, "seed": s, "truth": t})
        if progress:
            progress(i + 1, n, path)
    rec = {
        "synthetic": True,
        "what": "SYNTHETIC fleet: one press, drive logs made by the model with a drifting truth (NOT measured data)",
        "press": press.name, "press_source": press.source, "job": job.name, "job_source": job.source,
        "seed": seed, "logs": n, "schedule": schedule.record(), "starting_truth": dict(truth),
        "effects": {"noise_sigma_Nm": settings.noise_sigma, "contact_oscillation_Nm": settings.oscillation,
                    "sample_rate_Hz": settings.sample_rate, "strokes": settings.strokes},
        "log_files": logs,
        "versions": versions(),
    }
    write_json(out / "fleet.json", rec)
    return rec


def experiment_job(press: str | None, job: str, truth: str | None, seed: int, out: str,
                   fleet: tuple[int | None, str | None] = (None, None), progress=None, effects=None) -> list[str]:
    """The 'experiment' command: a SYNTHETIC drive log at ``out`` with its truth beside it, or with ``fleet`` = (N, drift
    schedule file or None: the shipped one; ``--fleet``, ``--drift``) a SYNTHETIC fleet of N logs drifting by the
    schedule in the folder ``out`` (written whole at the end; ``progress(i, n, path)`` after each log). ``effects``: the SYNTHETIC recording and model-form effects of
    ``experiment --effect NAME=VALUE`` (:mod:`calibration.synthetic.effects`). Returns the lines to print.
    """
    fleet, drift = fleet
    out_ = file_out(out)
    press_ = load_press(press)
    job_ = load_job(job)
    truth_ = experiment_truth(press_, job_, truth)
    note = reference_truth_note(press_, job_, truth, truth_)
    notes = [note] if note else []
    if fleet is not None:
        schedule = load_schedule(drift)
        with output_folder(out, [press, job, truth, drift], "experiment --fleet") as tmp:
            rec = write_fleet(press_, job_, truth_, seed, fleet, tmp, schedule, progress=progress)
        drifts = ", ".join(f"{n} {next(iter(d))} {next(iter(d.values()))}" for n, d in rec["schedule"]["drift"].items()) or "none"
        seeds = f"{rec['log_files'][0]['seed']}..{rec['log_files'][-1]['seed']}"
        return notes + [f"wrote a SYNTHETIC fleet of {fleet} drive logs in {out} (noise seeds {seeds}; drift per log: {drifts}); "
                        f"schedule, seeds and truths in {Path(out) / 'fleet.json'}"]
    if drift is not None:
        raise ServoPressError("--drift applies to a synthetic fleet: add --fleet N (the number of logs)")
    refuse_overwrite_input(out_, [press, job, truth])
    with claim(out_, out):  # the log and its truth file come from one run
        refuse_foreign_log(out_)
        prov = write_experiment(press_, job_, truth_, seed, out_, effects=effects)
    return notes + [f"wrote SYNTHETIC drive log {out_} ({prov['effects']['strokes']} strokes at {prov['effects']['sample_rate_Hz']:g} Hz, "
                    f"seed {seed}); truth in {truth_path(out_)}"]
