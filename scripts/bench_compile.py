#!/usr/bin/env python
"""Benchmark: numba's compiles on an empty cache, per compiled function, and the functions' outputs for a bit check.

One run (a fresh process, numba's and the project's disk caches in a new empty folder) drives every function that
:func:`press_model.jit.compiled` compiles through the calls the suite makes (a turn of kinematic states, forward and
inverse dynamics at them, a trilateration of 100 rows, Eq. 16 of 100 sets, the responses of 100 curves, a CUSUM run
of 10,000 strokes, the planner's normal-force fixed point, a run family's sums) and prints the CPU seconds of each
compile, by function and signature (numba's type inference, lowering and LLVM of it and of what it calls; the first
use of numba in the process included in the first compile).
--against TREE: another checkout (a git worktree of an older commit) and this one in alternating pairs (the host's
speed drifts), a run per tree and target, each a fresh process with PYTHONPATH at the tree; medians per function.
--outputs FILE: write the outputs of those calls (npz); --compare A B: whether two such files hold the same bits.

Usage: python scripts/bench_compile.py [--cpu avx2,host] [--against TREE [--pairs 3]] [--outputs FILE]
       python scripts/bench_compile.py --compare OLD.npz NEW.npz
"""
import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cpu_targets import TARGETS, host_line  # noqa: E402 (scripts/ beside this file)

_MARK = "compile-cpu "  # the line a run prints its figures on


def timed_compiles() -> dict:
    """{"function signature": CPU s} filled as numba compiles (or loads) each function press_model.jit hands it."""
    import press_model.jit as jit

    seconds = {}
    wrap = jit.one_compile_at_a_time

    def one_compile_at_a_time(dispatcher):
        dispatcher = wrap(dispatcher)
        compile_ = dispatcher.compile

        def compile_timed(sig):
            t0 = time.process_time()
            try:
                return compile_(sig)
            finally:
                name = f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"
                seconds[f"{name} {len(seconds)}"] = time.process_time() - t0

        dispatcher.compile = compile_timed
        return dispatcher

    jit.one_compile_at_a_time = one_compile_at_a_time
    return seconds


def workload() -> dict:
    """The outputs (name: array) of the calls that compile every function, on fixed inputs."""
    import numpy as np

    from calibration.design.run_family import family_sums
    from calibration.responses import all_responses
    from monitoring.drift import _alarms
    from planning.path_dynamics import _normals_fixed_point
    from press_model.dynamics import inverse_dynamics, slide_loads
    from press_model.forward import ForwardModel, ForwardWorkspace, forward_dynamics
    from press_model.geometry import trilaterate
    from press_model.jit import compiled
    from press_model.jobs import load_job
    from press_model.kinematics import linear_solve, state_at
    from press_model.model import PressModel, Workspace
    from press_model.motor import eq16_loops
    from press_model.press_data import load_press

    out, rng = {}, np.random.default_rng(3)
    pm = PressModel(load_press())  # its assembly sweep: loop rows and Newton steps
    out["assembly_qs"] = pm.assembly.qs
    loads = slide_loads(pm, load_job("cushion-test").process)
    ws = Workspace(pm)
    states = [state_at(pm, ws, math.radians(deg), rng.uniform(0.3, 3.0), rng.uniform(-20, 20)) for deg in range(0, 360, 7)]
    for name in ("q", "v", "a"):
        out[f"state_{name}"] = np.array([getattr(st, name) for st in states])
    dyn = [inverse_dynamics(pm, Workspace(pm), st, loads) for st in states]
    out["inverse_torque"] = np.array([d.crank_torque for d in dyn])
    out["inverse_reactions"] = np.array([d.joint_reactions for d in dyn])
    out["inverse_iterations"] = np.array([d.iterations for d in dyn])
    fm = ForwardModel(pm)
    fws = ForwardWorkspace(fm)
    fwd = [forward_dynamics(fm, fws, st.q + rng.normal(0, 1e-6, len(st.q)), st.v, rng.uniform(-20000, 20000), loads)
           for st in states]
    out["forward_a"] = np.array([r.a for r in fwd])
    out["forward_iterations"] = np.array([r.iterations for r in fwd])
    K = np.array(ws.K_last)
    out["solve_vector"] = linear_solve(K, rng.normal(size=len(K)))
    out["solve_matrix"] = linear_solve(K, np.eye(len(K)))
    points = np.array([[0.0, 0.0], [0.4, 0.05], [0.1, 0.35]])
    com = np.array([0.15, 0.12])
    d = np.hypot(*(com - points).T)
    out["trilaterate"] = np.concatenate(trilaterate(points, d * rng.uniform(0.98, 1.02, (100, 3)))[0])
    B, n = 100, 180
    crank, td, tdd = rng.normal(0, 2e4, (B, n)), rng.normal(0, 2, n), rng.normal(0, 20, n)
    J, eta = rng.uniform(0.01, 0.1, B), rng.uniform(0.85, 0.97, B)
    eq16 = np.empty((B, n))
    compiled(eq16_loops)(crank, td, tdd, J, eta, 12.0, 24.0, True, eq16)
    out["eq16"] = eq16
    out["responses"] = all_responses(crank, crank[0], np.abs(td) + 0.1, 12.0)
    out["alarms"] = _alarms(rng.normal(0, 1, 10000), 0.5, 4.0)
    F, n, k, j = 2, 90, 5, 6  # frictions, knots, reactions, friction inputs: the planner's fixed point over normals
    normals = rng.uniform(1e3, 1e5, (F, n, k))
    change, scale = np.empty((F, n)), np.empty((F, n))
    compiled(_normals_fixed_point)(rng.normal(0, 1e4, (F, n, 2 * k)), rng.normal(0, 1e-3, (F, n, 2 * k, j)), normals,
                                   1e-9, 50, change, scale)
    out["normals"] = normals
    parts = [rng.normal(size=(n, 40)) for _ in range(4)]  # a run family's sums: angles x entries, two forces
    sums = np.empty((2, n, 40))
    compiled(family_sums)(*parts, td[:n] ** 2, tdd[:n], rng.uniform(0, 1e5, (2, n)), sums)
    out["family_sums"] = sums
    return out


def run_once(outputs: str | None) -> None:
    """Compile everything on the caches this process was given; print the figures as one JSON line."""
    seconds = timed_compiles()
    t0 = time.process_time()
    out = workload()
    total = time.process_time() - t0
    if outputs:
        import numpy as np

        np.savez(outputs, **out)
    print(_MARK + json.dumps({"compiles": seconds, "workload": total}), flush=True)


def fresh_run(tree: Path, target: str, outputs: str | None = None) -> dict:
    """The figures of one run of this script on ``tree`` for ``target``, on empty caches."""
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, **TARGETS[target][1], "PYTHONPATH": str(tree), "NUMBA_CACHE_DIR": os.path.join(tmp, "numba"),
               "XDG_CACHE_HOME": os.path.join(tmp, "xdg")}
        cmd = [sys.executable, __file__, "--child"] + (["--outputs", outputs] if outputs else [])
        done = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True)
        if done.returncode != 0:
            sys.exit(f"the run on {tree} failed:\n{done.stderr[-3000:]}")
        line = next(l for l in done.stdout.splitlines() if l.startswith(_MARK))
        return json.loads(line[len(_MARK):])


def by_function(compiles: dict) -> dict:
    """CPU s per function, its signatures summed."""
    per = {}
    for key, s in compiles.items():
        name = key.rsplit(" ", 1)[0]
        per[name] = per.get(name, 0.0) + s
    return per


def compare(a: str, b: str) -> int:
    """Print whether the outputs in the npz files ``a`` and ``b`` hold the same bits; the number that differ."""
    import numpy as np

    x, y = np.load(a), np.load(b)
    bad = 0
    for name in sorted(set(x.files) | set(y.files)):
        same = name in x.files and name in y.files and x[name].shape == y[name].shape and x[name].tobytes() == y[name].tobytes()
        bad += not same
        print(f"{name:22s} {'same bits' if same else 'DIFFERENT'}")
    return bad


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cpu", default="avx2,host", help=f"comma-separated targets ({', '.join(TARGETS)})")
    ap.add_argument("--against", type=Path, help="an older checkout, run in alternating pairs with this one")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--outputs", help="write the workload's outputs to this npz file (one run)")
    ap.add_argument("--compare", nargs=2, metavar=("OLD", "NEW"), help="compare two --outputs files bit for bit")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.compare:
        return min(compare(*args.compare), 1)
    if args.child:
        run_once(args.outputs)
        return 0
    here = Path(__file__).resolve().parents[1]
    print(host_line())
    for target in args.cpu.split(","):
        if args.outputs:
            fresh_run(here, target, args.outputs)
            print(f"{target}: outputs written to {args.outputs}")
            continue
        trees = [("old", args.against.resolve()), ("new", here)] if args.against else [("new", here)]
        runs = {name: [] for name, _ in trees}
        for p in range(args.pairs if args.against else 1):
            for name, tree in trees if p % 2 == 0 else trees[::-1]:
                runs[name].append(fresh_run(tree, target))
        print(f"\n{target}: {TARGETS[target][0]}\ncompile CPU s on an empty cache, median of {len(runs['new'])} runs per tree")
        names = sorted({f for rs in runs.values() for r in rs for f in by_function(r["compiles"])})
        med = {t: {f: statistics.median(by_function(r["compiles"]).get(f, 0.0) for r in rs) for f in names} for t, rs in runs.items()}
        header = "  ".join(f"{t:>7s}" for t in runs) + ("    new/old" if args.against else "")
        print(f"{'function':58s} {header}")
        for f in names + ["total"]:
            vals = {t: (sum(m.values()) if f == "total" else m[f]) for t, m in med.items()}
            ratio = f"    {vals['new'] / vals['old']:.2f}" if args.against and vals["old"] > 0 else ""
            print(f"{f:58s} " + "  ".join(f"{v:7.2f}" for v in vals.values()) + ratio)
        for t, rs in runs.items():
            sigs = max(len(r["compiles"]) for r in rs)
            print(f"{t}: {sigs} compiles (function, signature); the workload's whole CPU "
                  f"{statistics.median(r['workload'] for r in rs):.1f} s (median)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
