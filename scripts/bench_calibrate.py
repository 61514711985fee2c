#!/usr/bin/env python
"""Benchmark: `servo-press calibrate --log LOG --out DIR` on one SYNTHETIC cushion-test log, timed as a whole process.

Issue 43's criterion: `calibrate` on one log stays under 10 s on an AVX2 machine without AVX-512. Each run is a fresh
process, interpreter start and imports included, as a user types the command; its CPU time (user + system, the
operating system's own accounting of the finished child) is quoted beside its wall time. CPU time is the figure to
compare on a shared machine: every run gets one BLAS and one numba thread (``OPENBLAS_NUM_THREADS``,
``OMP_NUM_THREADS``, ``NUMBA_NUM_THREADS`` = 1), so on a quiet machine its wall time would be about its CPU time.

Runs once per CPU target (``--cpu``, scripts/cpu_targets.py: ``avx2`` is numba's haswell build, ``host`` this CPU's
own), each after one warm-up run that fills numba's disk cache for that target and Python's bytecode cache, so the
counted runs are what a user's second and later runs cost. The log is made first with
``servo-press experiment --seed SEED`` (default 3).

``--calibrate-args`` adds arguments to each run's command line (``"--parameters eta_gear --method least-squares"``: the
one-parameter fit whose held parameters are freed one round at a time).

``--against TREE`` compares this checkout with another (a git worktree of an older commit): each counted run becomes a
pair, the other tree's run then this one's (``python -m servo_press.cli`` with ``PYTHONPATH`` and the working folder at
each tree, so each imports its own code), after a warm-up pair; printed: each pair's CPU times and their ratio, and the
median ratio. On a shared machine whose speed drifts from minute to minute only such pairs resolve a change.

Usage: python scripts/bench_calibrate.py [--seed 3] [--runs 5] [--cpu avx2,host] [--log LOG] [--calibrate-args ARGS]
       [--against TREE]
"""
from __future__ import annotations

import argparse
import os
import resource
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cpu_targets import add_cpu_argument, current, run_per_target  # noqa: E402

ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}


def cpu_model() -> str:
    """The CPU's model name as /proc/cpuinfo gives it ('unknown' where it does not)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def timed_run(argv: list[str], env: dict, cwd: Path | None = None) -> tuple[float, float]:
    """Run ``argv`` to its end (in ``cwd``, default this process's folder); returns (wall s, CPU s = user + system of
    the child and anything it waited for). A failed run stops the benchmark with its output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run(argv, env=env, capture_output=True, text=True, cwd=cwd)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} exited {res.returncode}:\n{res.stdout}\n{res.stderr}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def bench_one_target(args) -> int:
    """The counted runs of this process's target; prints median, min and max of wall and CPU."""
    env = {**os.environ, **ONE_THREAD}
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # an installed package has its bytecode: so do the counted runs
    tmp = Path(tempfile.mkdtemp(prefix="bench_calibrate_"))
    log = Path(args.log) if args.log else tmp / f"synthetic_seed{args.seed}.csv"
    if not log.exists():
        subprocess.run(["servo-press", "experiment", "--seed", str(args.seed), "--out", str(log)], env=env, check=True,
                       stdout=subprocess.DEVNULL)

    def argv(i):
        return ["servo-press", "calibrate", "--log", str(log), *shlex.split(args.calibrate_args), "--out", str(tmp / f"cal{i}")]

    if args.against:
        return bench_pairs(args, env, log, tmp)
    timed_run(argv("_warmup"), env)  # numba's cache for this target, the bytecode cache
    walls, cpus = [], []
    for i in range(args.runs):
        w, c = timed_run(argv(i), env)
        walls.append(w)
        cpus.append(c)
        print(f"  run {i + 1}: wall {w:.2f} s, CPU {c:.2f} s", flush=True)
    load = os.getloadavg()[0]

    def fig(xs):
        return f"{statistics.median(xs):.2f} s (min {min(xs):.2f}, max {max(xs):.2f})"

    print(f"{current()}: servo-press calibrate on {log.name} ({'seed ' + str(args.seed) if not args.log else 'given log'}"
          f"{', ' + args.calibrate_args if args.calibrate_args else ''}), "
          f"{args.runs} runs, one BLAS/numba thread, load average {load:.1f}: CPU {fig(cpus)}, wall {fig(walls)}; "
          f"target: under 10 s", flush=True)
    return 0


def bench_pairs(args, env: dict, log: Path, tmp: Path) -> int:
    """``--against``: the counted runs as pairs, the other tree's run then this checkout's; prints each pair's CPU
    times and ratio (this / other) and the median ratio."""
    trees = {"other": Path(args.against).resolve(), "this": Path(__file__).resolve().parent.parent}

    def run(which: str, i) -> float:
        tree = trees[which]
        argv = [sys.executable, "-m", "servo_press.cli", "calibrate", "--log", str(log.resolve()),
                *shlex.split(args.calibrate_args), "--out", str(tmp / f"{which}{i}")]
        return timed_run(argv, {**env, "PYTHONPATH": str(tree)}, cwd=tree)[1]  # -m puts the working folder first

    run("other", "_warmup"), run("this", "_warmup")  # numba's and the bytecode caches of both trees
    ratios = []
    for i in range(args.runs):
        old, new = run("other", i), run("this", i)
        ratios.append(new / old)
        print(f"  pair {i + 1}: CPU {trees['other'].name} {old:.2f} s, this {new:.2f} s, ratio {new / old:.3f} "
              f"(load average {os.getloadavg()[0]:.1f})", flush=True)
    print(f"{current()}: servo-press calibrate on {log.name}{', ' + args.calibrate_args if args.calibrate_args else ''}, "
          f"{args.runs} pairs against {trees['other']}: CPU ratio this / other, median {statistics.median(ratios):.3f} "
          f"(min {min(ratios):.3f}, max {max(ratios):.3f})", flush=True)
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=3, help="noise seed of the SYNTHETIC cushion-test log (default 3)")
    ap.add_argument("--runs", type=int, default=5, help="counted runs per target, after one warm-up (default 5)")
    ap.add_argument("--log", help="calibrate this log instead of making a SYNTHETIC one")
    ap.add_argument("--calibrate-args", default="", help="more arguments of each calibrate run, one string "
                    "(e.g. \"--parameters eta_gear --method least-squares\"; default none)")
    ap.add_argument("--against", metavar="TREE", help="another checkout (e.g. a git worktree of an older commit): "
                    "time it and this one in pairs, each run a pair (module docstring)")
    add_cpu_argument(ap)
    args = ap.parse_args()
    if current() is not None:
        return bench_one_target(args)
    print(f"CPU model: {cpu_model()}", flush=True)
    return run_per_target(args.cpu)


if __name__ == "__main__":
    sys.exit(main())
