#!/usr/bin/env python
"""Benchmark: CPU of one batch-model build (`press_model.batch.build_batch_model`) on the crank motion of a drive log, as
`calibrate` builds it for every log (its fitted motion and logged force), with the batch model's disk cache bypassed.

The motion and force are the ones `calibrate --log LOG` passes to its first build (the command is run in this process
up to that call). Each pass builds the model again; ``--cold`` bypasses the press geometry's cached grid positions too
(the first build on a press). Prints the best and the median of ``--repeat`` passes, after one that compiles or loads
numba's loops (not counted). It calls only `build_batch_model` and the disk cache's `cached_arrays`, so the same script
times an older tree: PYTHONPATH=OLD_TREE python scripts/bench_build.py.

Usage: python scripts/bench_build.py [--log LOG] [--repeat 5] [--cold]  (without --log: `experiment --seed 0`'s log)
"""
from __future__ import annotations

import argparse
import contextlib
import io
import statistics
import tempfile
import time
from pathlib import Path


class _Captured(Exception):
    """Raised in place of calibrate's first build, once its arguments are kept."""


def captured_build(log: Path) -> tuple:
    """(press, motion, process, pm) of `calibrate --log LOG`'s first batch-model build."""
    import calibration.identification.run as run
    from servo_press.cli import main

    kept = {}

    def keep(press, motion, process, step_deg=1.0, pm=None):
        kept.update(args=(press, motion, process, pm))
        raise _Captured

    real, run.build_batch_model = run.build_batch_model, keep
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            main(["calibrate", "--log", str(log), "--out", tempfile.mkdtemp()])
    except _Captured:
        pass
    finally:
        run.build_batch_model = real
    if "args" not in kept:
        raise SystemExit(f"calibrate --log {log} did not reach its batch-model build")
    return kept["args"]


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--log", type=Path, default=None)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--cold", action="store_true", help="bypass the cached grid positions too")
    args = ap.parse_args()

    import press_model.batch as batch
    from press_model import kinematic_tables

    log = args.log
    if log is None:
        from servo_press.cli import main as servo_press

        log = Path(tempfile.mkdtemp()) / "log.csv"
        with contextlib.redirect_stdout(io.StringIO()):
            servo_press(["experiment", "--seed", "0", "--out", str(log)])
    press, motion, process, pm = captured_build(log)

    def computed(kind, key, names, compute):
        return compute()

    batch.cached_arrays = computed
    if args.cold:
        kinematic_tables.cached_arrays = computed

    def build():
        return batch.build_batch_model(press, motion, process, pm=pm)

    build()
    times = []
    for _ in range(args.repeat):
        t0 = time.process_time()
        build()
        times.append((time.process_time() - t0) * 1e3)
    print(f"build_batch_model{' (cold)' if args.cold else ''}: CPU best {min(times):.0f} ms, median "
          f"{statistics.median(times):.0f} ms ({args.repeat} passes, {len(batch.crank_grid(1.0))} points, {pm.press.name})",
          flush=True)


if __name__ == "__main__":
    main()
