"""Count the solves of `reproduce`'s door-panel plans per row and mode: IPOPT solves and iterations, toppra solves, full-model
friction fixed points (planning.path_dynamics.full_crank_torques) and path dynamics built, with the CPU seconds of each.

The three rows are planned in one process as `compare` plans them (mode = "auto": theoretical, calibrated at the
calibrated values, robust over the calibration's joint region started from it), for a calibrated.json of the reference
press (`reproduce`'s calibration/calibrated.json). An IPOPT solve whose inputs (start, parameters, bounds) repeat an earlier
one's is counted as a repeat of the row and mode that made it first.

    python scripts/bench_plan_count.py OUT/calibration/calibrated.json
"""
from __future__ import annotations

import argparse
import collections
import contextlib
import dataclasses
import functools
import hashlib
import json
import time

import numpy as np

import planning.evaluation as evaluation
import planning.modes as modes
import planning.optimal as optimal
import planning.path_dynamics as path_dynamics
import planning.pendulum as pendulum
import planning.planner as planner
import planning.robust as robust

WHERE: list[str] = []  # the row, mode and swing being planned
COUNTS: dict = collections.defaultdict(collections.Counter)
SECONDS: dict = collections.defaultdict(collections.Counter)
FIRST_SEEN: dict = {}  # an IPOPT solve's inputs -> where it was first solved


@contextlib.contextmanager
def at(label: str):
    """Count what runs inside under ``label`` (appended to the current place)."""
    WHERE.append(label)
    try:
        yield
    finally:
        WHERE.pop()


def counted(module, name: str, what: str) -> None:
    """Replace ``module.name`` by a wrapper counting its calls and CPU seconds as ``what``."""
    inner = getattr(module, name)

    @functools.wraps(inner)
    def wrapper(*args, **kw):
        t0 = time.process_time()
        try:
            return inner(*args, **kw)
        finally:
            place = "/".join(WHERE)
            COUNTS[place][what] += 1
            SECONDS[place][what] += time.process_time() - t0

    setattr(module, name, wrapper)


def _solver_counted(call_solver):
    @functools.wraps(call_solver)
    def wrapper(solver, **args):
        t0 = time.process_time()
        res = call_solver(solver, **args)
        place = "/".join(WHERE)
        COUNTS[place]["ipopt solves"] += 1
        COUNTS[place]["ipopt iterations"] += int(solver.stats().get("iter_count", 0))
        SECONDS[place]["ipopt solves"] += time.process_time() - t0
        digest = hashlib.sha1(b"".join(np.ascontiguousarray(np.asarray(args[k], float)).tobytes()
                                       for k in ("x0", "p", "lbg", "ubg", "ubx"))).hexdigest()
        if digest in FIRST_SEEN:
            COUNTS[place][f"ipopt repeats of {FIRST_SEEN[digest]}"] += 1
        FIRST_SEEN.setdefault(digest, place)
        return res
    return wrapper


def instrument() -> None:
    """Wrap the solvers and the modes (each mode's plan counted under its name)."""
    optimal.call_solver = _solver_counted(optimal.call_solver)
    counted(planner, "solve_toppra", "toppra solves")
    counted(path_dynamics, "full_crank_torques", "full-model fixed points")
    evaluation.full_crank_torques = path_dynamics.full_crank_torques
    counted(path_dynamics, "build_path_dynamics", "path dynamics built")
    robust.build_path_dynamics = pendulum.build_path_dynamics = planner.build_path_dynamics = path_dynamics.build_path_dynamics
    for name, mode in list(modes.MODES.items()):
        def plan(*args, _plan=mode.plan, _name=name, **kw):
            with at(_name):
                return _plan(*args, **kw)
        modes.MODES[name] = dataclasses.replace(mode, plan=plan)
    swing = pendulum.plan_swing_robust

    def plan_swing_robust(*args, **kw):
        with at("robust swing"):
            return swing(*args, **kw)
    pendulum.plan_swing_robust = plan_swing_robust


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("calibrated", help="calibrated.json of the reference press with a joint region")
    args = ap.parse_args()
    instrument()
    from planning.compare import plan_theoretical, unpack_plan
    from planning.modes import plan_in_mode
    from planning.optimal import clear_solvers
    from planning.settings import read_planning
    from press_model.jobs import load_job
    from press_model.model import PressModel
    from press_model.params import apply_overrides
    from press_model.press_data import load_press

    press, door = load_press("reference"), load_job("door-panel")
    spec = dataclasses.replace(read_planning(door), mode="auto")
    cal = json.loads(open(args.calibrated).read())
    values = cal["parameters"]
    box = robust.Box.from_calibration(press, values, {n: tuple(v) for n, v in cal["joint_region"]["box"].items()},
                                      "--calibrated", "joint region")
    cpu = {}
    t0 = time.process_time()
    theoretical = PressModel(press)
    with at("theoretical"):
        unpack_plan(plan_theoretical(theoretical, door, spec), theoretical)
    cpu["theoretical"], t0 = time.process_time() - t0, time.process_time()
    clear_solvers()
    calibrated = PressModel(apply_overrides(press, values, "--calibrated"))
    with at("calibrated"):
        nominal = plan_in_mode(planner.StrokeProblem.build(calibrated, door.process, spec))
    cpu["calibrated"], t0 = time.process_time() - t0, time.process_time()
    with at("robust"):
        robust.plan_robust(calibrated, door.process, spec, box, nominal=nominal)
    cpu["robust"] = time.process_time() - t0
    print("CPU s per row: " + ", ".join(f"{k} {v:.1f}" for k, v in cpu.items()))
    for place in COUNTS:
        counts = ", ".join(f"{k} {v}" + (f" ({SECONDS[place][k]:.2f} s)" if SECONDS[place][k] else "") for k, v in COUNTS[place].items())
        print(f"{place}: {counts}")


if __name__ == "__main__":
    main()
