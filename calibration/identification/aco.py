"""Ant colony optimisation over a bounded continuous box: the paper's "improved ACO" (Section 4.2).

The paper gives only its settings: 50 ants, 100 iterations, elite ant quantity coefficient 2, pheromone
importance factor 1.0, heuristic factor importance 2.0, evaporation coefficient adapted within [0.1, 0.9],
pheromone intensity 100. This module is our design around those settings; every extra constant it needs is a
setting as well (read from the job file's ``[calibration.aco]`` table, nothing numeric is defaulted in code).

Algorithm (ACO_R of Socha & Dorigo 2008, with Ant System pheromone trails on the guides)
--------------------------------------------------------------------------------------
The search runs in the unit box u = (x - low) / (high - low), so that parameters whose ranges differ by
many orders of magnitude (an efficiency of 0.8 and a mass of 30,000 kg) are searched alike.

* The pheromone table is a solution archive of ``archive_size`` (k) points, kept sorted by objective value,
  each with a pheromone trail tau_l. It starts as a Latin hypercube sample of the box (plus ``x0`` if given).
* Each iteration, each of the ``ants`` (m) ants makes one decision, like an Ant System ant choosing an edge:
  it picks a guide l of the archive with probability

      p_l = tau_l^alpha * eta_l^beta / sum_j tau_j^alpha * eta_j^beta,

  then samples its solution around the guide from a normal distribution with standard deviation
  sigma_l = xi * (mean distance from guide l to the other archive points, per axis) (ACO_R's kernel),
  reflected at the box walls. The axes are set by ``kernel``: "rotated" takes the archive's principal
  directions (eigenvectors of its covariance: ACO_R's rotation step), so a slanted narrow valley, such as
  Eq. 28's floor across eta_gear and mu_r, is sampled along and across its length instead of parameter by
  parameter; "per-parameter" the parameters themselves; "mixed" (the shipped choice) gives every second ant
  the parameter axes, which keeps optima on the box walls in reach (a rotated draw mixes a pinned parameter
  with free ones and is reflected off the wall).
* The colony's m solutions are evaluated in one vectorised call of the objective.
* Trails: tau <- (1 - rho) tau (evaporation); each ant deposits Q / f'_a on the guide it followed (credit for
  the decision that led to its solution, as an AS ant deposits Q / L on the edges it used); the best-so-far
  solution receives e * Q / f'_best (Dorigo's elitist ants: e extra ants walk the best-so-far path).
* The archive keeps the k best of (archive + colony); a solution new to the archive starts with the mean trail
  of the archive, so pheromone neither favours nor penalises a solution before it could earn deposits.
* MAX-MIN bounds (Stuetzle and Hoos): after the deposits every trail is clipped to [tau_max / R, tau_max],
  tau_max = (1 + e) Q / rho (the steady trail of a point that earns one full deposit and the elitist one every
  iteration), R the ``trail_ratio``. Without them the elitist deposits pile onto the best point and guide
  choice collapses onto it within 30-50 iterations (effective number of guides ~1); with R = 10 no trail
  outgrows another more than tenfold, and the colony keeps drawing from several guides.
* rho adapts to stagnation: rho = rho_min + (rho_max - rho_min) * min(1, s / W), with s the number of
  consecutive iterations in which no ant improved the best-so-far and W the ``stagnation_window``.
* After the last iteration, if a ``polish`` hook is given (the calibration passes the SLSQP polish of Eq. 28,
  :mod:`calibration.identification.polish`), it descends locally from the best point with at most ``polish_evaluations``
  evaluations, counted in nfev; its answer is kept only when it is better. With the paper's 50 + 50 x 100
  evaluations and a polish of 450 the whole run costs at most 5,500 evaluations.

Objective normalisation. The objective can have any sign and unit, so the Ant System's ``Q / f`` is applied
to a normalised cost f' = 1 + (f - f_best) / (f_median - f_best) >= 1, with f_best and f_median the best and
the median objective of the current archive: the best archive point has f' = 1, the median f' = 2. f' is
invariant to shifting and scaling the objective, so ants behave the same whether the objective is in N m
or a relative error, and Q / f' is finite even at a zero minimum.

Every setting and its role
--------------------------
``ants`` (m, paper 50): solutions sampled per iteration; the colony is evaluated in one call of ``fun``.
``iterations`` (paper 100): number of iterations; the search always runs all of them (no early stop), so
    the evaluation count of the colony is fixed: archive_size + ants * iterations (plus the polish's).
``elite_coefficient`` (e, paper 2): number of elitist ants of Dorigo's elitist Ant System. Each iteration the
    best-so-far solution's trail receives e * Q / f'_best = e * Q on top of the ants' deposits, which keeps
    the colony returning to the best-so-far solution. 0 turns elitism off.
``pheromone_weight`` (alpha, paper 1.0): exponent of the trail in the guide probability. 0 ignores trails.
``heuristic_weight`` (beta, paper 2.0): exponent of the heuristic desirability eta_l = 1 / f'_l of guide l
    (its own normalised objective: a priori, a better point is a better guide, as a shorter edge is in the
    TSP). With beta = 2 the best archive point is four times as likely a guide as the median one, for equal
    trails. Points with a non-finite objective have eta = 0 and are never guides.
``evaporation_min``, ``evaporation_max`` (paper 0.1, 0.9): the interval of the adaptive evaporation rho.
    While the best-so-far keeps improving, rho = rho_min: trails remember over about 1 / rho_min iterations
    which guides have produced good solutions, and the colony exploits them. Each iteration without
    improvement raises rho linearly, reaching rho_max after W iterations: the accumulated trails, which now
    concentrate the colony on guides that no longer produce improvements, are forgotten within about one
    iteration, and guide choice falls back on the heuristic and on the latest deposits, spreading the ants
    over the archive. Any improvement resets rho to rho_min.
``pheromone_intensity`` (Q, paper 100): the amount of pheromone an ant deposits for a solution of normalised
    cost f' (Q / f'). Scale-free here, and stated honestly: the initial trail (Q), every deposit and the
    elitist deposit are all proportional to Q, and the guide probabilities are ratios of tau^alpha, so Q
    cancels and does not change the search (a test checks that Q = 1 and Q = 128 give identical runs).
    What it still sets is the unit of the trails reported in ``AcoResult.pheromone``, comparable with other
    ACO codes that deposit Q / L.
``archive_size`` (k, not in the paper): number of solutions kept as the pheromone table. Socha & Dorigo
    used 50; it sets how many distinct regions the colony can remember, and the initial sample size.
``spread`` (xi, not in the paper): ACO_R's width factor of the sampling kernel relative to the archive's
    mean distance. Larger is slower but less greedy convergence; Socha & Dorigo used 0.85.
``stagnation_window`` (W, not in the paper): iterations without improvement of the best-so-far after which
    rho reaches rho_max.
``kernel`` (not in the paper): "rotated", "per-parameter" or "mixed", the sampling axes (see above).
``trail_ratio`` (R, not in the paper): tau_max / tau_min of the MAX-MIN bounds; a huge value turns them off.
``polish_evaluations`` (not in the paper): budget of the final local polish; 0 turns it off.

Bounds are hard: a sample outside [0, 1] in a dimension is reflected back (mirror at the wall, repeated, so
a far overshoot still lands inside), which keeps the kernel's shape near a wall instead of piling samples on
it as clipping would; physical points are finally clipped to [low, high] against rounding in the mapping.
A non-finite objective value (NaN, inf) is treated as worse than every finite value: such a point is ranked
last, is never a guide, never deposits pheromone, and is never returned while any finite value was seen.

The run is deterministic for a given seed: all randomness comes from ``numpy.random.default_rng(seed)``.
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from press_io.errors import PressDataError
from press_model.readers import FieldReader
from press_model.settings_fields import read_value, setting

KERNELS = ("rotated", "per-parameter", "mixed")
_TABLE = "aco"  # the settings table is read as {"aco": table}, so errors name "aco.<key>"


@dataclass(frozen=True)
class AcoSettings:
    """Settings of :func:`minimize_aco`; see the module docstring for the role of each."""

    ants: int = setting(50, "", "ants per iteration (paper 4.2); the colony is one batch evaluation", ge=2)  # two at least: a colony differs from one sample
    iterations: int = setting(100, "", "iterations (paper 4.2); always all run: nfev = archive_size + ants x iterations", ge=1)
    elite_coefficient: float = setting(2.0, "elitist ants", "elitist ants (paper 4.2): the best-so-far trail gets e x Q "
                                       "per iteration; 0 = off", ge=0.0, unit="elitist ants")
    pheromone_weight: float = setting(1.0, "", "alpha, the trail's exponent in the guide probability (paper 4.2)",
                                      ge=0.0, unit="exponent alpha")
    heuristic_weight: float = setting(2.0, "", "beta, exponent of eta = 1 / normalised cost (paper 4.2)",
                                      ge=0.0, unit="exponent beta")
    evaporation_min: float = setting(0.1, "fraction per iteration", "rho while the best-so-far improves (paper 4.2: "
                                     "[0.1, 0.9])", gt=0.0, lt=1.0, unit="fraction per iteration")
    evaporation_max: float = setting(0.9, "fraction per iteration", "rho after stagnation_window iterations without "
                                     "improvement (paper 4.2); at least evaporation_min", lt=1.0,
                                     unit="fraction per iteration, at least evaporation_min")
    pheromone_intensity: float = setting(100.0, "pheromone per deposit", "Q, per deposit of normalised cost 1 (paper 4.2); "
                                         "cancels in selection, sets the trail's unit", gt=0.0, unit="pheromone per deposit")
    archive_size: int = setting(50, "", "k, solutions kept as the pheromone table (Socha & Dorigo 2008)", ge=2)  # the kernel width needs two points
    spread: float = setting(0.85, "fraction of the archive mean distance", "xi, the kernel's width (Socha & Dorigo 2008)",
                            gt=0.0, unit="fraction of the archive mean distance")
    stagnation_window: int = setting(5, "", "iterations without improvement for rho to reach evaporation_max "
                                     "(1..20 differ little)", ge=1)
    kernel: str = setting("mixed", "", "half the ants sample in the archive's principal directions (ACO_R's rotation: the "
                          "slanted eta_gear-mu_r valley of Eq. 28), half per parameter (optima on the bounds)", choices=KERNELS)
    trail_ratio: float = setting(10.0, "tau_max / tau_min", "MAX-MIN trail bounds: no guide's trail outgrows the others "
                                 "by more, so the guide choice cannot collapse onto one archive point", ge=1.0,
                                 unit="tau_max / tau_min")
    polish_evaluations: int = setting(450, "", "model cycles of the final SLSQP polish (calibration/identification/polish.py): "
                                      "50 + 50 x 100 + 450 = 5,500 cycles in all; 0 = none", ge=0)

    @classmethod
    def from_mapping(cls, table: Mapping, source: str) -> AcoSettings:
        """Validated settings from a TOML table (e.g. a job file's ``[calibration.aco]``).

        Absent keys take their defaults; raises PressDataError naming ``aco.<key>`` for a mistyped, out-of-range or unknown key.
        """
        if not isinstance(table, Mapping):
            raise PressDataError(source, _TABLE, table, "must be a table of ACO settings")
        rd = FieldReader(source, {_TABLE: table})
        values = _read_settings(rd)
        rd.reject_unread()
        return cls(**values)


def _read_settings(rd: FieldReader) -> dict:
    """Every field of :class:`AcoSettings` from the table, absent keys their defaults; evaporation_max at least evaporation_min."""
    fields = {f.name: f for f in dataclasses.fields(AcoSettings)}
    v = {}
    for name, f in fields.items():
        if name == "evaporation_max":
            check = f.metadata["check"]
            v[name] = rd.number((_TABLE, name), ge=v["evaporation_min"], default=f.default, **check)
        else:
            v[name] = read_value(rd, (_TABLE, name), f)
    return v


def _validated(settings: AcoSettings) -> AcoSettings:
    """The same checks for settings built in code as for settings read from a file."""
    if not isinstance(settings, AcoSettings):
        raise PressDataError("minimize_aco", "settings", type(settings).__name__, "must be an AcoSettings")
    AcoSettings.from_mapping(dataclasses.asdict(settings), "AcoSettings")
    return settings


@dataclass
class AcoResult:
    """Outcome of :func:`minimize_aco`. Objective values are in the unit of ``fun``; x in physical units."""

    x: np.ndarray  # (d,) best point found
    fun: float  # its objective value (inf if no finite value was ever returned)
    nfev: int  # rows evaluated: archive_size + ants * nit
    nit: int  # iterations run
    history_best: np.ndarray  # (nit + 1,) best-so-far objective after the initial archive and after each iteration
    history_rho: np.ndarray  # (nit,) evaporation coefficient used in each iteration
    time_s: float  # wall time of the run, s
    message: str
    settings: AcoSettings
    seed: int
    pheromone: np.ndarray  # (archive_size,) final trails of the archive, best point first, in units of Q
    history_guides: np.ndarray  # (nit,) effective number of guides 1 / sum p_l^2 of each iteration's choice
    fun_colony: float  # best objective of the colony itself, before the polish
    polish_nfev: int  # evaluations the polish used (included in nfev)


def _check_bounds(low, high, x0):
    src = "minimize_aco"
    try:
        lo = np.asarray(low, dtype=float)
        hi = np.asarray(high, dtype=float)
    except (TypeError, ValueError):
        raise PressDataError(src, "low/high", (low, high), "must be sequences of numbers") from None
    if lo.ndim != 1 or lo.size == 0 or lo.shape != hi.shape:
        raise PressDataError(src, "low/high", (lo.shape, hi.shape), "must be 1-D arrays of the same length >= 1")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
        raise PressDataError(src, "low/high", (lo.tolist(), hi.tolist()), "must be finite with low < high in every dimension")
    if x0 is None:
        return lo, hi, None
    try:
        x = np.asarray(x0, dtype=float)
    except (TypeError, ValueError):
        raise PressDataError(src, "x0", x0, "must be a sequence of numbers") from None
    if x.shape != lo.shape or not np.all(np.isfinite(x)) or np.any(x < lo) or np.any(x > hi):
        raise PressDataError(src, "x0", x.tolist(), f"must be {lo.size} finite numbers within [low, high]")
    return lo, hi, x


def _latin_hypercube(rng: np.random.Generator, n: int, d: int) -> np.ndarray:
    """n points in [0, 1)^d, one per stratum 1/n of every dimension: an even first cover of the box."""
    strata = np.argsort(rng.random((n, d)), axis=0)
    return (strata + rng.random((n, d))) / n


def _reflect(u: np.ndarray) -> np.ndarray:
    """Fold any real numbers into [0, 1] by mirroring at 0 and 1 (a triangle wave of period 2)."""
    v = np.mod(u, 2.0)
    return np.where(v > 1.0, 2.0 - v, v)


def _normalised_cost(f: np.ndarray, f_arch: np.ndarray) -> np.ndarray:
    """f' = 1 + max(f - best, 0) / (median - best) with best and median over the finite archive values f_arch;
    inf where f is not finite (or where the archive holds no finite value yet).

    When at least half the archive ties with the best, the scale is the largest finite value among f_arch and f
    less best; when that is zero too, every finite value equals best and f' = 1 whatever the scale.
    """
    out = np.full(f.shape, np.inf)
    fin = f_arch[np.isfinite(f_arch)]
    if fin.size == 0:
        return out
    best = fin.min()
    scale = np.median(fin) - best
    if not scale > 0.0:
        both = np.concatenate([fin, f[np.isfinite(f)]])
        scale = both.max() - best
    ok = np.isfinite(f)
    excess = np.maximum(f[ok] - best, 0.0)
    out[ok] = 1.0 + (excess / scale if scale > 0.0 else excess)  # excess is all zeros when scale is 0
    return out


def _physical(U: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Points of the unit box in physical units; the clip only guards against rounding in the affine map."""
    return np.clip(lo + U * (hi - lo), lo, hi)


def _evaluate(fun, X: np.ndarray) -> np.ndarray:
    """Objective values (m,) of the physical rows X, non-finite values replaced by +inf (worst)."""
    F = np.asarray(fun(X), dtype=float)
    if F.shape != (X.shape[0],):
        raise ValueError(f"fun must map an (m, d) array to m objective values; it returned shape {F.shape} "
                         f"for {X.shape[0]} rows")
    return np.where(np.isfinite(F), F, np.inf)


def _sample(U: np.ndarray, guides: np.ndarray, spread: float, kernel: str, rng: np.random.Generator) -> np.ndarray:
    """New points of the unit box (m, d), unreflected: one Gaussian draw around each ant's guide.

    Widths are ACO_R's: xi times the guide's mean distance to the other archive points, per axis. With
    ``kernel = "rotated"`` the axes are the archive's principal directions (eigenvectors of its covariance),
    so a slanted valley that the archive has begun to line up along is sampled along its length and across
    its width, instead of parameter by parameter.
    """
    k, d = U.shape
    step = rng.standard_normal((len(guides), d))

    def draw(V, rows):
        Z = U @ V
        sigma = spread * np.abs(Z[:, None, :] - Z[None, :, :]).sum(axis=1) / (k - 1)
        return (Z[guides[rows]] + sigma[guides[rows]] * step[rows]) @ V.T

    out = np.empty((len(guides), d))
    axis = np.ones(len(guides), dtype=bool) if kernel == "per-parameter" else np.zeros(len(guides), dtype=bool)
    if kernel == "mixed":
        axis[1::2] = True  # every second ant samples parameter by parameter
    if (~axis).any():
        _, V = np.linalg.eigh(np.cov(U, rowvar=False).reshape(d, d))  # orthonormal columns; deterministic for a given matrix
        out[~axis] = draw(V, ~axis)
    if axis.any():
        out[axis] = draw(np.eye(d), axis)
    return out


def minimize_aco(
    fun: Callable[[np.ndarray], np.ndarray],
    low,
    high,
    settings: AcoSettings,
    seed: int,
    progress: Callable[[int, float, float], None] | None = None,
    x0=None,
    polish: Callable[[np.ndarray, float, int], tuple[np.ndarray, float, int, str]] | None = None,
) -> AcoResult:
    """Minimise ``fun`` over the box [low, high] with the ant colony of the module docstring.

    ``fun(X)`` takes an (m, d) array of points in physical units (every row within [low, high]) and returns
    the (m,) objective values; the whole colony of an iteration is one call. ``x0``, if given, joins the
    initial archive (e.g. the theoretical parameters). ``progress(iteration, best_f, rho)`` is called after
    each iteration with the best-so-far objective and the evaporation coefficient used.
    Returns an :class:`AcoResult`; nfev = archive_size + ants * iterations + polish_nfev.
    """
    t_start = time.perf_counter()
    s = _validated(settings)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise PressDataError("minimize_aco", "seed", seed, "must be a whole number >= 0")
    lo, hi, x0 = _check_bounds(low, high, x0)
    d = lo.size
    k, m = s.archive_size, s.ants
    alpha, beta, Q, e = s.pheromone_weight, s.heuristic_weight, s.pheromone_intensity, s.elite_coefficient
    rng = np.random.default_rng(seed)

    U = _latin_hypercube(rng, k, d)
    X = _physical(U, lo, hi)
    if x0 is not None:
        U[0], X[0] = (x0 - lo) / (hi - lo), x0  # X keeps x0 exactly, so that the result can return it unchanged
    F = _evaluate(fun, X)
    order = np.argsort(F, kind="stable")
    U, X, F = U[order], X[order], F[order]
    tau = np.full(k, Q)  # the uniform initial trail of Ant System: one deposit of cost f' = 1 on every point
    nfev = k

    history_best = [F[0]]
    history_rho, history_guides = [], []
    stall = 0  # consecutive iterations without improvement of the best-so-far
    last_improved = 0
    for it in range(1, s.iterations + 1):
        rho = s.evaporation_min + (s.evaporation_max - s.evaporation_min) * min(1.0, stall / s.stagnation_window)

        # guide choice: p ~ tau^alpha * eta^beta, eta = 1 / f' (0 for non-finite objective values)
        cost = _normalised_cost(F, F)
        finite = np.isfinite(cost)
        w = np.zeros(k)
        w[finite] = tau[finite] ** alpha * cost[finite] ** -beta  # where() would give 0**0 = 1 at beta = 0
        total = w.sum()
        if not total > 0.0:  # no finite point yet (or every trail underflowed): every eligible guide alike
            w = finite.astype(float) if finite.any() else np.ones(k)
            total = w.sum()
        p = w / total
        history_guides.append(1.0 / float(np.sum(p * p)))
        guides = rng.choice(k, size=m, p=p)

        Unew = _reflect(_sample(U, guides, s.spread, s.kernel, rng))
        Xnew = _physical(Unew, lo, hi)
        Fnew = _evaluate(fun, Xnew)
        nfev += m

        # trails: evaporate, each ant credits its guide with Q / f', elitist ants reinforce the best-so-far
        tau = (1.0 - rho) * tau
        cost_new = _normalised_cost(Fnew, F)
        ok = np.isfinite(cost_new)
        np.add.at(tau, guides[ok], Q / cost_new[ok])

        # archive: the k best of old and new; newcomers start with the mean trail of the survivors
        improved = Fnew.min() < F[0]
        Uall = np.concatenate([U, Unew])
        Xall = np.concatenate([X, Xnew])
        Fall = np.concatenate([F, Fnew])
        tall = np.concatenate([tau, np.full(m, np.nan)])
        keep = np.argsort(Fall, kind="stable")[:k]
        U, X, F, tau = Uall[keep], Xall[keep], Fall[keep], tall[keep]
        new = np.isnan(tau)
        tau[new] = tau[~new].mean() if np.any(~new) else Q
        if np.isfinite(F[0]):
            tau[0] += e * Q  # e elitist ants deposit Q / f'_best each, and f'_best = 1 by construction
        # MAX-MIN bounds: no trail above the steady state of a best point, none below tau_max / trail_ratio
        tau_max = (1.0 + e) * Q / rho
        tau = np.clip(tau, tau_max / s.trail_ratio, tau_max)

        if improved:
            stall, last_improved = 0, it
        else:
            stall += 1
        history_best.append(F[0])
        history_rho.append(rho)
        if progress is not None:
            progress(it, float(F[0]), float(rho))

    x = X[0].copy()  # the very row that was evaluated, so fun(x) reproduces result.fun
    if np.isfinite(F[0]):
        message = f"ran {s.iterations} iterations; the best-so-far last improved at iteration {last_improved}"
    else:
        message = f"ran {s.iterations} iterations; fun returned no finite value"
    f_colony, f_best = float(F[0]), float(F[0])
    polish_nfev = 0
    if polish is not None and s.polish_evaluations > 0 and np.isfinite(f_best):
        px, pf, polish_nfev, pmsg = polish(x, f_best, s.polish_evaluations)
        if polish_nfev > s.polish_evaluations:
            raise ValueError(f"polish used {polish_nfev} evaluations, over its budget of {s.polish_evaluations}")
        nfev += polish_nfev
        if pf < f_best:
            x, f_best = np.clip(np.asarray(px, dtype=float), lo, hi), float(pf)
        message += f"; polish from {f_colony:.6g} to {f_best:.6g} in {polish_nfev} evaluations ({pmsg})"
    return AcoResult(
        x=x, fun=f_best, nfev=nfev, nit=s.iterations,
        history_best=np.asarray(history_best), history_rho=np.asarray(history_rho),
        history_guides=np.asarray(history_guides),
        time_s=time.perf_counter() - t_start, message=message, settings=s, seed=seed, pheromone=tau.copy(),
        fun_colony=f_colony, polish_nfev=polish_nfev,
    )
