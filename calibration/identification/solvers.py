"""Three solvers for the same calibration objective, with one result type so they can be compared.

* ``aco``: the paper's ant colony (:mod:`calibration.identification.aco`) on Eq. 28.
* ``least-squares``: scipy's ``least_squares`` (trust-region reflective, bounded) on the residual vector
  T_pred - T_meas from several starts. It minimises Y_RMSE, not Eq. 28; its Eq. 28 value is reported.
* ``differential-evolution``: scipy's ``differential_evolution`` on Eq. 28 itself, vectorised.

Every solver reports its evaluations in model cycles (one parameter set over the 360-point turn).
"""
from __future__ import annotations

import dataclasses
import hashlib
import inspect
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import differential_evolution, least_squares

from press_model.batch import BatchModel
from press_model.disk_cache import press_key

from calibration.identification.aco import minimize_aco
from calibration.identification.polish import polish_two_part
from calibration.identification.problem import Objective
from calibration.identification.settings import CalibrationSettings


@dataclass(frozen=True)
class SolverRun:
    method: str
    x: np.ndarray  # calibrated values, SI units, in problem.names order
    objective: float  # Eq. 28 at x
    cycles: int  # model cycles evaluated
    time_s: float
    detail: str


class _Counted:
    """The objective with a count of the parameter sets it evaluated."""

    def __init__(self, obj: Objective):
        self.obj, self.cycles = obj, 0

    def __call__(self, P):
        P = np.atleast_2d(P)
        self.cycles += len(P)
        return self.obj(P)

    def residuals(self, x):
        self.cycles += 1
        return self.obj.residuals(x)

    def residual_map(self, fun, points):
        """``least_squares``' ``workers`` map: the residuals (:meth:`residuals`) of all the finite-difference Jacobian's
        points in one model call (a set's curve is the same bytes whatever else is in its batch) in place of one call
        each; ``fun``, scipy's wrapper of :meth:`residuals`, is not called."""
        P = np.array(list(points), dtype=float)
        self.cycles += len(P)
        return list(self.obj.residual_rows(P))

    def parts_of(self, P):
        P = np.atleast_2d(P)
        self.cycles += len(P)
        return self.obj.parts_of(P)


def run_aco(obj: Objective, cs: CalibrationSettings, seed: int, progress: Callable | None = None) -> SolverRun:
    t0 = time.perf_counter()
    f = _Counted(obj)
    p = obj.problem
    hook = None if progress is None else (lambda it, best, rho: progress(it, cs.aco.iterations, best))
    r = minimize_aco(f, p.low, p.high, cs.aco, seed, progress=hook, x0=p.theoretical, polish=eq28_polish(f, obj))
    return SolverRun("aco", r.x, float(obj(r.x[None])[0]), f.cycles, time.perf_counter() - t0,
                     f"{cs.aco.ants} ants x {r.nit} iterations, archive {cs.aco.archive_size}, {cs.aco.kernel} kernel, "
                     f"trail ratio {cs.aco.trail_ratio:g}; {r.message}")


def eq28_polish(f: "_Counted", obj: Objective):
    """The local polish of Eq. 28 (:func:`calibration.identification.polish.polish_two_part`) as minimize_aco's ``polish`` hook;
    its evaluations are counted by ``f``."""
    p = obj.problem

    def run(x, fx, budget):
        res = polish_two_part(f.parts_of, x, (p.low, p.high), (p.weight, obj.rmse0, abs(obj.pr0)), budget, f0=fx)
        return res.x, res.fun, res.nfev, res.message

    return run


def run_least_squares(obj: Objective, cs: CalibrationSettings, seed: int, progress: Callable | None = None) -> SolverRun:
    t0 = time.perf_counter()
    f = _Counted(obj)
    p = obj.problem
    rng = np.random.default_rng(seed)
    starts = [p.theoretical] + [p.low + rng.random(len(p.low)) * (p.high - p.low) for _ in range(cs.least_squares.starts - 1)]
    best = None
    for i, x0 in enumerate(starts):
        # the 2-point Jacobian's points in one model call each (scipy 1.16's workers map), one call a point before
        r = least_squares(f.residuals, x0, bounds=(p.low, p.high), x_scale=p.high - p.low, method="trf",
                          **({"workers": f.residual_map} if _BATCHED_JACOBIAN else {}))
        if best is None or r.cost < best.cost:
            best = r
        if progress is not None:
            progress(i + 1, len(starts), float(obj(best.x[None])[0]))
    return SolverRun("least-squares", best.x, float(obj(best.x[None])[0]), f.cycles, time.perf_counter() - t0,
                     f"{len(starts)} starts (theoretical + {len(starts) - 1} seeded random); best RMSE {np.sqrt(2 * best.cost / np.count_nonzero(obj.peak_points)):.1f} N m "
                     "(outside the die-contact window)")


def run_differential_evolution(obj: Objective, cs: CalibrationSettings, seed: int, progress: Callable | None = None) -> SolverRun:
    t0 = time.perf_counter()
    f = _Counted(obj)
    p = obj.problem
    gen = [0]

    def callback(xk, convergence=None):
        gen[0] += 1
        if progress is not None:
            progress(gen[0], cs.differential_evolution.max_generations, float(obj(np.asarray(xk)[None])[0]))

    r = differential_evolution(lambda P: f(P.T), list(zip(p.low, p.high)), vectorized=True, updating="deferred",
                               seed=seed, popsize=cs.differential_evolution.population, maxiter=cs.differential_evolution.max_generations, tol=cs.differential_evolution.tolerance,
                               polish=False, callback=callback, x0=p.theoretical)
    return SolverRun("differential-evolution", r.x, float(obj(r.x[None])[0]), f.cycles, time.perf_counter() - t0,
                     f"population {cs.differential_evolution.population} x {len(p.names)}, {r.nit} generations; {r.message}")


_BATCHED_JACOBIAN = "workers" in inspect.signature(least_squares).parameters  # scipy >= 1.16

SOLVERS = {"aco": run_aco, "least-squares": run_least_squares, "differential-evolution": run_differential_evolution}
_SECTIONS = {"aco": "aco", "least-squares": "least_squares", "differential-evolution": "differential_evolution"}


MEMO_RUNS = 32  # solver runs remembered per process (a few hundred bytes each): then it starts again
_RUNS: dict = {}  # content key of a run's inputs (method, its settings, seed, Eq. 28) -> its SolverRun, x read-only


def solve(method: str, obj: Objective, cs: CalibrationSettings, seed: int, progress: Callable | None = None) -> SolverRun:
    """``SOLVERS[method](obj, cs, seed, progress)``: the run made before in this process for the same method, the same
    settings of that method (``cs``' section of it, the only part it reads), the same seed and the same Eq. 28 (its
    problem, measured curve, peak points, normalisation and batch models, by content), else a new one. A process that
    calibrates one log under settings that differ only after the fit (a force tolerance, the bootstrap, the adequacy
    test's freeing of held parameters) fitted the same colony each time, a third to a half of a calibration's CPU. The
    runs are deterministic for their seed, so a remembered run is the one a new run would make, but for its wall time
    and its progress lines (none printed)."""
    key = _run_key(method, obj, getattr(cs, _SECTIONS[method]), seed)
    run = _RUNS.get(key) if key is not None else None
    if run is None:
        run = SOLVERS[method](obj, cs, seed, progress)
        if key is None:  # an input not known by its content: never remembered
            return run
        if len(_RUNS) >= MEMO_RUNS:
            _RUNS.clear()
        _RUNS[key] = dataclasses.replace(run, x=np.array(run.x, dtype=float))
        _RUNS[key].x.setflags(write=False)
    return dataclasses.replace(run, x=np.array(run.x, dtype=float))  # the caller's own copy


def _run_key(method: str, obj: Objective, section, seed: int) -> str | None:
    """The content key of a solver run's inputs: a SHA-256 over the method, :func:`_feed` of its settings' values, the
    seed and :func:`_feed` of Eq. 28; None where some input is not known by its content."""
    digest = hashlib.sha256(repr((method, int(seed))).encode())
    try:
        _feed(digest, section)
        _feed(digest, obj)
    except TypeError:
        return None
    return digest.hexdigest()


def _feed(digest, value) -> None:
    """Feed ``value`` into ``digest`` by content: arrays by dtype, shape and bytes, dataclasses field by field (a batch
    model's press by :func:`press_model.disk_cache.press_key`), sequences and mappings item by item, numbers, strings
    and None by repr (exact); TypeError for anything else (whose repr may not hold all of it)."""
    if isinstance(value, np.ndarray):
        digest.update(repr((value.dtype.str, value.shape)).encode())
        digest.update(np.ascontiguousarray(value).tobytes())
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        digest.update(type(value).__qualname__.encode())
        for f in dataclasses.fields(value):
            v = getattr(value, f.name)
            if isinstance(value, BatchModel) and f.name == "press":
                v = repr(press_key(v))
            digest.update(f.name.encode())
            _feed(digest, v)
    elif isinstance(value, (tuple, list)):
        digest.update(f"{type(value).__name__}{len(value)}".encode())
        for v in value:
            _feed(digest, v)
    elif isinstance(value, dict):
        digest.update(f"dict{len(value)}".encode())
        for k, v in value.items():
            _feed(digest, k)
            _feed(digest, v)
    elif value is None or isinstance(value, (bool, int, float, str, np.generic)):
        digest.update(f"{type(value).__name__}:{value!r}".encode())
    else:
        raise TypeError(f"no content key for {type(value).__name__}")
