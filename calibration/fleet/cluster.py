"""Calibrating every drive log of a press: finding and ordering the logs, one calibration per log on
local processes or a Dask cluster, and one result file per log so that an interrupted run resumes.

``servo-press monitor`` calls :func:`run_fleet`. Each log is one task, :func:`calibrate_log`, which gets
only file paths and small settings (a :class:`LogTask`): the worker loads the press and job files itself
and runs :func:`calibration.identification.run.calibrate` in its own process. Tasks run

* in this process, one after the other, with ``workers = 1``;
* on a ``dask.distributed.LocalCluster`` of ``workers`` processes on this machine (one thread each,
  bound to 127.0.0.1, no dashboard), the default;
* on a running Dask cluster with ``scheduler = "tcp://host:port"`` (``dask scheduler`` and ``dask worker``;
  the project installed on every worker, and the logs, press and job files at the same paths there).

Dask reschedules the task of a worker that dies on another worker. Each result comes back to this
process and is written, atomically, to ``<out>/logs/<log>.json``: the calibration record (the content of
``calibrated.json``) with a ``monitor`` entry holding the hashes of its inputs. A rerun reuses a result
whose input hashes (log bytes, press fingerprint, job, method, seed, parameters, torque unit, package
version) all match, so an interrupted run finishes only what is missing, and an unchanged rerun
calibrates nothing. A log that fails (refused input) is recorded with its message; only refusals of the
input are reused, a crash or a lost worker is retried on the next run.
"""
from __future__ import annotations

import copy
import dataclasses
import glob
import hashlib
import json
import logging
import os
import signal
import sys
import threading
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from press_io.errors import PressDataError, ServoPressError
from press_io.interrupts import deferred
from press_model.jobs import Job, load_job
from press_io.outputs import read_marker, versions, write_json, write_marker
from press_model.press_data import BUILTIN_PRESSES, PressData, load_press

if TYPE_CHECKING:
    from calibration.identification.inputs import FitChoice, LogFormat
from press_model.readers import data_fingerprint, is_file

from calibration.traces.drive_log import leading_comments, recorded_time
from calibration.traces.trace_formats import read_trace

TRACE_SUFFIXES = ("*.csv", "*.tdms")  # what a folder of traces read through a channel map holds (--log-format)

RESULTS = "logs"  # subfolder of --out with one result JSON per log
_CONNECT_TIMEOUT_S = 10  # how long to wait for a --scheduler to answer
# Dask's housekeeping on the command's own LocalCluster (scheduler, nannies and workers alike, read when each starts):
# by default every process checks its event loop every 20 ms, a worker samples its task's stack for the dashboard's
# profile every 10 ms, a nanny and a worker poll the worker's memory every 100 ms and the system every 500 ms. Without a
# dashboard nobody reads the profile or those histories; an idle cluster of two workers spent ~0.12 s of CPU a second
# on them, ~0.015 s with these settings (and the profile's sampling is off the calibrations' CPU too). Results do not
# depend on them; a --scheduler cluster keeps its own settings.
_LOCAL_CLUSTER_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.admin.tick.interval": "1s",
                         "distributed.worker.memory.monitor-interval": "1s", "distributed.admin.system-monitor.interval": "2s"}


# --- the logs -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FleetLog:
    """One drive log of the fleet: its id (path relative to the fleet's folder), path, and recording date."""

    log: str
    path: Path
    recorded: str | None  # the `# recorded:` text as written in the log
    sort_key: tuple
    error: str | None  # a log whose header cannot be read is reported, not calibrated


def find_logs(spec: str, exclude: Path | None = None, traces: bool = False) -> list[FleetLog]:
    """The logs of ``--logs DIR|GLOB`` (a folder: its ``*.csv``; with ``traces``, read through a channel map, also its
    ``*.tdms``), ordered by their ``# recorded:`` date (a trace's own start time), then (undated logs, after the dated
    ones) by id. Files under ``exclude`` (the output folder) are skipped."""
    p = Path(spec)
    if p.is_dir():
        paths, base = sorted(x for pat in (TRACE_SUFFIXES if traces else ("*.csv",)) for x in p.glob(pat) if x.is_file()), p
    else:
        paths = sorted(Path(x) for x in glob.glob(spec, recursive=True) if is_file(x))
        base = Path(os.path.commonpath([str(x.parent.resolve()) for x in paths])) if paths else None
    if exclude is not None:
        ex = exclude.resolve()
        paths = [x for x in paths if ex not in x.resolve().parents]
    if not paths:
        raise PressDataError(spec, "--logs", spec, "must be a folder holding drive-log *.csv files or a glob matching them "
                             "(quote the glob so that the shell passes it on, e.g. --logs 'press7/*.csv')")
    logs = []
    for x in paths:
        log_id = x.resolve().relative_to(base.resolve()).as_posix()
        try:
            rec = recorded_time(read_trace(x).comments if traces else leading_comments(x), str(x))
        except ServoPressError as exc:
            logs.append(FleetLog(log_id, x, None, (1, "", log_id), str(exc)))
            continue
        key = (0, rec[1].isoformat(), log_id) if rec else (1, "", log_id)
        logs.append(FleetLog(log_id, x, rec[0] if rec else None, key, None))
    return sorted(logs, key=lambda f: f.sort_key)


MARKER = "monitor_run.json"  # in <out>/logs: written before the first calibration, marks a monitor folder


def is_monitor_folder(out: Path) -> bool:
    """True for a folder holding a monitor run, finished or interrupted (its ``logs/monitor_run.json``)."""
    try:
        if (Path(out) / RESULTS / MARKER).is_file():
            return True
    except (OSError, ValueError):
        return False
    marker = read_marker(Path(out))
    return marker is not None and marker["command"] == "monitor"


def result_path(out: Path, log: str) -> Path:
    """Where the result of log ``log`` goes: ``<out>/logs/<log with / as __>.json``."""
    return Path(out) / RESULTS / (log.replace("/", "__") + ".json")


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return "sha256:" + h.hexdigest()




# --- one task -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LogTask:
    """What a worker gets: paths and small settings, never model objects (they are built on the worker)."""

    log: str
    path: str  # absolute
    press: str | None  # absolute path or a built-in name; None = the reference press
    job: str  # absolute path or a built-in name
    method: str
    seed: int
    parameters: tuple[str, ...] | None
    torque_unit: str
    single_thread: bool  # one numba and one BLAS thread (several worker processes share the cores)
    log_format: str | None = None  # absolute path of the channel map (--log-format); None: plain drive-log CSVs


_BLAS_LIMIT = None  # threadpoolctl's limiter, kept alive for the worker process's life


def one_thread() -> None:
    """One numba and one BLAS thread in this worker process (several share the cores); None."""
    global _BLAS_LIMIT
    import numba

    numba.set_num_threads(1)  # per calling thread: set at every task
    if _BLAS_LIMIT is None:
        from threadpoolctl import threadpool_limits

        _BLAS_LIMIT = threadpool_limits(1)


def calibrate_log(task: LogTask, loaded: tuple | None = None) -> dict:
    """Calibrate one log (runs on a worker). Returns ``{"status": "ok", "record", "log_sha256", "press_fingerprint"}``
    or ``{"status": "failed", "error", "reusable"}``; it never raises, so one bad log cannot stop the others.
    ``loaded``: (press, job, channel map or None, the job's calibration settings) as this process read them for the run
    (in-process runs); a worker of its own reads them from the task's paths. The log is read once: its digest is of the bytes its rows come from."""
    from calibration.identification.inputs import channel_map_for, read_log
    from calibration.identification.record import result_record
    from calibration.identification.run import calibrate
    from calibration.identification.settings import CalibrationSettings

    if task.single_thread:
        one_thread()
    try:
        if loaded is None:
            press, job = load_press(task.press), load_job(task.job)
            cmap = channel_map_for(Path(task.log_format), task.torque_unit, press) if task.log_format else None
            cs = None
        else:
            press, job, cmap, cs = loaded
        rows = read_log(task.path, press, task.torque_unit, cmap)
        cs = cs if cs is not None else CalibrationSettings.from_job(job)
        if task.parameters:  # a caller's choice of parameters replaces the job's list
            cs = dataclasses.replace(cs, parameters=tuple(task.parameters))
        cal = calibrate(press, job, rows, [task.method], task.seed, cs, progress=False)
        rec = result_record(cal, press, job, task.seed)
        return {"status": "ok", "record": rec, "log_sha256": rows.file_sha256, "press_fingerprint": press.fingerprint}
    except ServoPressError as exc:  # the input was refused: the same input gives the same refusal
        return {"status": "failed", "error": str(exc), "reusable": True}
    except Exception as exc:  # noqa: BLE001 (reported per log so that the others go on; not reused, retried next run)
        return {"status": "failed", "error": f"unexpected {type(exc).__name__} while calibrating: {exc}", "reusable": False}


# --- running the tasks ----------------------------------------------------------------------------------
def _connect(address: str):
    from dask.distributed import Client

    try:
        return Client(address, timeout=f"{_CONNECT_TIMEOUT_S}s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise ServoPressError(f"--scheduler {address}: no Dask scheduler answered within {_CONNECT_TIMEOUT_S} s ({exc}); start one "
                              "with `dask scheduler` and workers with `dask worker tcp://HOST:PORT --nworkers N --nthreads 1`, "
                              "or leave --scheduler out to run on local processes") from None


@contextmanager
def local_cluster(workers: int):
    """A ``dask.distributed.LocalCluster`` of ``workers`` processes with one thread each, bound to 127.0.0.1, without
    the dashboard (its HTTP routes on a free local port), as a context manager that shuts it down.

    Ctrl-C stops the command, not the cluster under it: SIGINT is ignored while the cluster starts (a second or
    two), so that the worker processes started then inherit the ignoring (Python keeps an inherited SIG_IGN) and
    never see the terminal's Ctrl-C (killed from under their nannies, they logged tracebacks); this process then
    takes Ctrl-C again and closes the cluster in order.

    Dask's own log lines stay off the terminal (``silence_logs`` CRITICAL, in this process and the workers): a log
    the cluster cannot calibrate reaches the command through its future and is reported on that log's line, and
    what Dask logs at ERROR is about its connections, mostly a busy worker's heartbeat racing the scheduler's close
    after Ctrl-C (a CI run printed that traceback before "servo-press: interrupted")."""
    import dask
    from dask.distributed import LocalCluster

    main = threading.current_thread() is threading.main_thread()  # only the main thread may set a signal's handler
    with ExitStack() as stack:
        old = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
        try:
            with dask.config.set(_LOCAL_CLUSTER_CONFIG):
                # each nanny starts its worker processes with this config, a replaced one too: a copy of its own (a
                # nanny's merge with the global config is shallow, and the global one is restored on leaving the with)
                config = copy.deepcopy(dask.config.config)
                cluster = stack.enter_context(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                                           dashboard_address="127.0.0.1:0", scheduler_kwargs={"dashboard": False},
                                                           silence_logs=logging.CRITICAL, config=config))
        finally:
            if main:
                signal.signal(signal.SIGINT, old)
        yield cluster


def run_tasks(tasks: list, workers: int, scheduler: str | None, on_result, loaded: tuple | None = None, fn=None) -> None:
    """Run ``fn(task, loaded)`` (default :func:`calibrate_log`; a function that never raises and returns a dict with
    ``status``) for every task and call ``on_result(task, result)`` in this process as each finishes (any order).
    ``loaded``: what this process read (for calibrate_log: press, job, channel map, calibration settings), which a run in
    this process uses (workers read their own)."""
    fn = fn if fn is not None else calibrate_log
    if not tasks:
        return
    if scheduler is None and workers == 1:
        for t in tasks:
            on_result(t, fn(t, loaded))
        return
    from dask.distributed import Client, as_completed

    stack = ExitStack()
    try:
        if scheduler is not None:
            client = stack.enter_context(_connect(scheduler))
        else:
            cluster = stack.enter_context(local_cluster(workers))
            client = stack.enter_context(Client(cluster))
        futures = client.map(fn, tasks, pure=False)
        task_of = {f.key: t for f, t in zip(futures, tasks)}
        for fut in as_completed(futures):
            task = task_of[fut.key]
            if fut.status == "finished":
                res = fut.result()
            else:  # the task itself never raises: this is the cluster (a worker lost too often, an import failing there)
                exc = fut.exception()
                res = {"status": "failed", "reusable": False,
                       "error": f"the cluster could not run this log ({type(exc).__name__}: {exc}); the project must be installed "
                                "on every worker, and the log, press and job files readable at the same paths there"}
            on_result(task, res)
            fut.release()
    finally:
        # the client's and the cluster's close, in order and whole: a Ctrl-C or SIGTERM then is held until they are
        # closed and raised after (exit 130 / 143); raised inside it, it cut the close short and Python printed
        # 'Exception ignored in ... WeakSet ... KeyboardInterrupt' from a weakref callback it landed in
        with deferred():
            stack.close()


# --- the fleet run --------------------------------------------------------------------------------------
def _resolve(arg: str | None, builtins) -> str | None:
    """An input for a worker: a built-in name as it is, a file as its absolute path."""
    if arg is None or str(arg) in builtins:
        return arg
    return str(Path(arg).resolve())


@dataclass(frozen=True)
class Workers:
    """Where a fleet's logs are calibrated: ``count`` local worker processes (None: one per core), or the Dask cluster
    at ``scheduler`` (its workers are set where they are started); ``single_thread``: one numba and one BLAS thread per worker process
    (several share the cores)."""

    count: int | None = 2
    scheduler: str | None = None
    single_thread: bool = True


def run_fleet(logs_spec: str, press_arg: str | None, job_arg: str, out: Path, fit: FitChoice | None = None,
              fmt: LogFormat | None = None, workers: Workers = Workers(), echo=None,
              loaded: tuple[PressData, Job] | None = None) -> dict:
    """Calibrate every log of ``logs_spec`` that has no valid result in ``<out>/logs`` yet, each with ``fit``'s method
    (None: the job's default) and seed (default :class:`FitChoice`'s), its logs read as ``fmt`` says (default: plain
    drive-log CSVs in N m), on ``workers``.

    Returns ``{"press", "job", "settings", "entries", "calibrated", "reused"}``: ``entries`` in recorded order, each
    ``{"log", "recorded", "status", "record" | "error"}`` as read back from the result files (so a fresh and a
    reused result give the same bytes downstream); ``calibrated`` / ``reused`` count this run's work. ``loaded``:
    (press, job) already read from ``press_arg`` and ``job_arg`` by the caller (default: read here).
    """
    from press_model.jobs import BUILTIN_JOBS

    from calibration.identification.inputs import FitChoice, LogFormat
    from calibration.identification.settings import METHODS, CalibrationSettings

    fit, fmt = fit or FitChoice(), fmt or LogFormat()
    seed, torque_unit, log_format = fit.seed, fmt.torque_unit, fmt.channel_map
    scheduler = workers.scheduler
    echo = echo or (lambda msg: print(msg, file=sys.stderr, flush=True))
    out = Path(out)
    wanted = workers.count if workers.count is not None else os.cpu_count() or 1
    if wanted < 1:
        raise PressDataError("--workers", "--workers", wanted, "must be a whole number of worker processes >= 1")
    press, job = loaded if loaded is not None else (load_press(press_arg), load_job(job_arg))
    cs = CalibrationSettings.from_job(job)
    if not cs.parameters:  # monitor calibrates the job's own list
        raise PressDataError(job.source, "calibration.parameters", "<missing>", "must name the parameters every log is "
                             "calibrated for: give the job's [calibration] parameters = [...] (the paper's six: see cushion_test.toml)")
    method = fit.method or cs.default_method
    if method not in METHODS:
        raise PressDataError("--method", "--method", method, f"must be one of {', '.join(METHODS)}")
    cmap = fmt.read_map(press)  # before any worker starts
    logs = find_logs(logs_spec, exclude=out, traces=log_format is not None)
    settings = {"method": method, "seed": seed, "parameters": list(cs.parameters), "torque_unit": torque_unit,
                **({"log_format_sha256": file_sha256(Path(log_format))} if log_format is not None else {}),
                "press_fingerprint": press.fingerprint, "job_fingerprint": data_fingerprint(job.raw),
                "servo_press_twin": versions()["servo-press-twin"]}

    def inputs(f: FleetLog) -> dict:
        try:
            digest = file_sha256(f.path)
        except OSError:  # unreadable: the calibration reports why
            digest = None
        return {"log_sha256": digest, **settings}

    todo, reused = [], 0
    inputs_of = {f.log: inputs(f) for f in logs}  # hashed once: what a result records and a rerun compares
    for f in logs:
        if f.error is not None:
            write_json(result_path(out, f.log), {"monitor": {"log": f.log, "recorded": None, "status": "failed", "error": f.error,
                                                             "reusable": True, "inputs": inputs_of[f.log]}})
            continue
        cached = _read_result(result_path(out, f.log))
        if cached is not None and cached.get("monitor", {}).get("inputs") == inputs_of[f.log] and cached["monitor"].get("reusable", True):
            reused += 1
            continue
        todo.append(f)
    write_marker(out, "monitor")  # another command refuses this folder (see press_io.outputs.MARKER)
    write_json(out / RESULTS / MARKER, {"what": "servo-press monitor: one result JSON per drive log in this folder, reused by a "
                                        "rerun when the hashes of its inputs match", "settings": settings, "versions": versions()})
    if reused:
        echo(f"monitor: {reused} of {len(logs)} logs already calibrated with the same inputs in {out / RESULTS} (reused)")
    count = min(wanted, max(1, len(todo)))  # no idle processes
    where = f"the Dask cluster at {scheduler}" if scheduler else ("this process" if count == 1 else f"{count} local worker processes")
    if todo:
        echo(f"monitor: calibrating {len(todo)} log{'s' if len(todo) > 1 else ''} ({method}, seed {seed}) on {where}")
    by_log = {f.log: f for f in todo}
    tasks = [LogTask(f.log, str(f.path.resolve()), _resolve(press_arg, BUILTIN_PRESSES), _resolve(job_arg, BUILTIN_JOBS), method, seed,
                     None, torque_unit, workers.single_thread and not (scheduler is None and count == 1),
                     str(Path(log_format).resolve()) if log_format is not None else None) for f in todo]
    done = [0]

    def on_result(task: LogTask, res: dict) -> None:
        f = by_log[task.log]
        inp = inputs_of[f.log]
        if res["status"] == "ok" and res["log_sha256"] != inp["log_sha256"]:
            res = {"status": "failed", "reusable": False, "error": "the log changed while it was calibrated (or the worker reads another "
                   "file at this path); rerun"}
        if res["status"] == "ok" and res["press_fingerprint"] != press.fingerprint:
            res = {"status": "failed", "reusable": False, "error": f"the worker loaded another press ({res['press_fingerprint']}, "
                   f"here {press.fingerprint}): the press file must be the same on every worker"}
        mon = {"log": f.log, "recorded": f.recorded, "status": res["status"], "inputs": inp}
        if res["status"] == "ok":
            rec = dict(res["record"])
            rec.setdefault("press_fingerprint", press.fingerprint)
            write_json(result_path(out, f.log), {**rec, "monitor": mon})
            m = rec["metrics"]
            note = f"RMSE {m['rmse_before_Nm']:.0f} -> {m['rmse_after_Nm']:.0f} N m"
        else:
            mon.update(error=res["error"], reusable=res["reusable"])
            write_json(result_path(out, f.log), {"monitor": mon})
            note = "FAILED: " + res["error"]
        done[0] += 1
        echo(f"  [{done[0]}/{len(tasks)}] {f.log}: {note}")

    run_tasks(tasks, count, scheduler, on_result, (press, job, cmap, cs))

    entries = []
    for f in logs:
        res = _read_result(result_path(out, f.log))
        mon = res["monitor"]
        e = {"log": f.log, "recorded": mon["recorded"], "status": mon["status"]}
        if mon["status"] == "ok":
            e["record"] = {k: v for k, v in res.items() if k != "monitor"}
        else:
            e["error"] = mon["error"]
        entries.append(e)
    return {"press": press, "job": job, "settings": settings, "entries": entries, "calibrated": len(todo), "reused": reused}


def _read_result(path: Path) -> dict | None:
    """A result file, or None when missing or unreadable (a half-written file cannot exist: writes are atomic)."""
    try:
        rec = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return rec if isinstance(rec, dict) and isinstance(rec.get("monitor"), dict) else None
