"""Logs per minute of `servo-press monitor` on this machine: in one process, on 2 local worker processes
(with and without one numba/BLAS thread per process), and on a Dask cluster (a LocalCluster's real
scheduler and worker processes, reached through --scheduler, measured warm: after one warm-up log per worker).

    python scripts/bench_monitor.py [--logs 8] [--method differential-evolution] [--workers 2]

The fleet is SYNTHETIC (`servo-press experiment --fleet`, seed 0), made once in a temporary folder; every
run starts from an empty output folder, so every log is calibrated (nothing reused). Wall times include
starting the worker processes except for the warm cluster figure.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calibration.fleet.cluster import Workers, local_cluster, run_fleet  # noqa: E402
from calibration.identification.inputs import FitChoice  # noqa: E402
from servo_press.cli import main  # noqa: E402


def timed(label: str, n: int, fn) -> float:
    t0 = time.perf_counter()
    res = fn()
    dt = time.perf_counter() - t0
    ok = sum(e["status"] == "ok" for e in res["entries"])
    print(f"{label:<58} {dt:7.1f} s  {60.0 * n / dt:6.1f} logs/min  ({ok}/{n} calibrated)", flush=True)
    return dt


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=8, help="logs in the synthetic fleet (default 8)")
    ap.add_argument("--method", default=None, help="calibration method (default: the job's, differential-evolution)")
    ap.add_argument("--workers", type=int, default=2, help="local worker processes / cluster workers (default 2)")
    ap.add_argument("--job", default="cushion-test")
    a = ap.parse_args()
    quiet = lambda msg: None  # noqa: E731
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        fleet = tmp / "fleet"
        t0 = time.perf_counter()
        assert main(["experiment", "--job", a.job, "--fleet", str(a.logs), "--out", str(fleet)]) == 0
        print(f"SYNTHETIC fleet of {a.logs} logs written in {time.perf_counter() - t0:.1f} s", flush=True)
        k = a.workers
        common = dict(fit=FitChoice(a.method), echo=quiet)
        timed("1 process (in this process, numba/BLAS threads as default)", a.logs,
              lambda: run_fleet(str(fleet), None, a.job, tmp / "serial", workers=Workers(1), **common))
        timed(f"{k} local worker processes, 1 numba + 1 BLAS thread each", a.logs,
              lambda: run_fleet(str(fleet), None, a.job, tmp / "local", workers=Workers(k), **common))
        timed(f"{k} local worker processes, default numba threads each", a.logs,
              lambda: run_fleet(str(fleet), None, a.job, tmp / "local_mt", workers=Workers(k, single_thread=False), **common))

        from dask.distributed import Client

        with local_cluster(k) as c, Client(c):
            warm = tmp / "warm"
            warm.mkdir()
            for i in range(k):  # one log per worker: imports, numba kernel load, first model build
                (warm / f"w{i}.csv").write_bytes((fleet / f"log_{i % a.logs:03d}.csv").read_bytes())
            timed(f"Dask cluster {c.scheduler_address}, {k} workers: warm-up", k,
                  lambda: run_fleet(str(warm), None, a.job, tmp / "warmup", workers=Workers(scheduler=c.scheduler_address), **common))
            timed(f"Dask cluster, {k} workers (warm)", a.logs,
                  lambda: run_fleet(str(fleet), None, a.job, tmp / "cluster", workers=Workers(scheduler=c.scheduler_address), **common))
    print("note: figures depend on the machine's load; the per-log cost is one calibration (see scripts/bench_calibration.py)")


if __name__ == "__main__":
    run()
