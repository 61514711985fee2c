"""Intervals for the Eq. 28 estimate: a parametric bootstrap with block-resampled residuals.

The Jacobian intervals of :mod:`calibration.identification.uncertainty` belong to least squares; Eq. 28 is another
estimator (its peak term pins the fit to the measured peak), with another spread and bias. The bootstrap
repeats the estimator itself on logs that the calibrated model could have produced:

1. r = measured - T(x_hat) on the crank grid, the residual of the calibrated model.
2. A synthetic curve T(x_hat) + r*, with r* a circular block bootstrap of r centred on zero (the mean of the
   resampled points taken off first; why below): blocks of ``block_points``
   consecutive grid points, from random starts, laid end to end round the turn. Blocks keep the residual's
   correlation over neighbouring degrees (the stroke average, the interpolation, slow misfit), and are no longer
   than that correlation needs (:func:`calibration.identification.run.block_points`). The points
   that are no stationary noise stay where they are, with their own residual: the die-contact window left
   out of the peak comparison (impact ringing) and the grid points next to a force step (a step smeared by
   interpolation); carried elsewhere they would plant a spike in the peak window.
3. The estimator on that curve: Eq. 28 rebuilt from it (its own Y_RMSE,0, Y_PR,0 and filtered peak) and
   minimised from x_hat by a batched Gauss-Newton (:func:`refit_batch`): every refit's point in one model call per
   iteration, the central-difference Jacobian where it improved in a second, then each linearised Eq. 28 (the peak
   at the model's peak point, the same epigraph form as :mod:`calibration.identification.polish`) solved within a trust
   region. A local solver suffices because every resample lies near the calibrated model; a test checks
   that it reaches the minimum a long SLSQP polish finds, and the coverage benchmark
   (scripts/bench_coverage.py) that the intervals are honest.
4. ``refits`` (R) repetitions give, per parameter, the *basic* (reverse-percentile) interval
   [2 x_hat - q_hi, 2 x_hat - q_lo], with q_lo, q_hi the (R+1) a-th and (R+1)(1-a)-th order statistics of the
   refits, a = (1 - level) / 2 (:func:`order_statistic_quantiles`); and the standard deviations and the
   correlation matrix of the estimates.
5. The reported interval: the basic interval widened on each side by the *window shift* |x_clean - x_hat|, with
   x_clean the same local refit on the log whose kept-in-place points (the die-contact window, the force steps'
   neighbours) hold the calibrated model's own curve instead of the measurement: how far what the model cannot
   follow there pulls the estimate (and the noise on those points, which no resample varies either); plus the
   job's optional *allowance* (a fraction of each calibration range, [calibration.bootstrap.allowance], none in
   the shipped job); clipped to the bounds.

Why the basic interval and not the plain percentile [q_lo, q_hi]: the bootstrap principle is that x* - x_hat
(refit about estimate) is distributed as x_hat - truth (estimate about truth). Where the refits see a bias
of Eq. 28's estimate (from its peak term and the model's nonlinearity) they repeat it about x_hat; the
percentile interval then sits on the wrong side, twice the bias away from the truth, while the basic interval
reflects it back.

Why the residual is centred: a resample stands for a further noise draw, which has mean zero, but Eq. 28's peak
term holds the model's peak on the measured one, so the calibrated model's residual keeps a mean (of the order of
what the peak's own noise moved the fit by, e.g. -12 and +9 N m on two clean SYNTHETIC cushion-test logs, seeds
9505 and 9507). Uncentred, that mean sat under every resample's filtered peak and pulled every refit the same way:
mu_s's refits centred up to 1.7 of their standard deviations off x_hat, on the side opposite to x_hat's error, and
the basic interval reflected that offset onto the truth's side as if it were the estimator's bias (mu_s covered 9 of
12, seeds 9500-9511), while further noise draws of the same truths showed no such bias. Residual resampling
centres the residuals whenever the fit does not make their mean zero (Davison and Hinkley 1997, Sec. 6.2.3).

Why the (R+1) rule: with few refits numpy's default quantile lies well inside the refits' range; with 40
refits its 2.5 and 97.5 % points hold a further draw of the same law only 90 % of the time, so intervals built
on them covered about 90 % even where the bootstrap was right. The (R+1) a-th order statistic is the one whose
interval holds a further draw with the nominal probability (Davison and Hinkley 1997, Sec. 5.2).

Why the window shift: a residual bootstrap cannot see bias from effects the model does not contain. The residual
of the calibrated model is what its parameters could *not* absorb, so refits on it find nothing more to absorb,
while the real estimate has already been pulled by the part they could. On a drive log the largest such effect
sits where the rigid model is not meant to follow: the ringing after die contact (on the SYNTHETIC logs it pulled
J_gear low by 10 % of its range on average, and the refits' own shift had almost no relation to it from log to
log). Replacing the measurement there by the calibrated curve and refitting measures that pull on this log
itself; nothing is fitted to a synthetic truth. (An earlier version widened by a constant fraction of each range
fitted to the synthetic ringing by a coverage study; scripts/bench_coverage.py reports the coverage now.) Model
error elsewhere in the turn is not covered: that is the adequacy test's job (:mod:`calibration.identification.adequacy`), and
the report says when the intervals do not cover it.

Two questions, two answers. Each interval above holds its own parameter's truth at ``level``, one parameter at a
time; over six parameters some interval misses in about a quarter of calibrations even when every one is exact
(1 - 0.95^6 = 26 % for independent estimates). The *joint region* answers "all at once": a box that holds every
truth together at ``level`` (:func:`simultaneous_extra`). Each side of the reported interval is moved out by
(t_S - t_1) s_j, with s_j the refits' standard deviation of parameter j, t_1 the t-quantile (R - 1 degrees of
freedom) at ``level`` and t_S the same at the Sidak level ``level ** (1 / k)`` (:func:`calibration.identification.uncertainty.sidak_level`):
the interval's own half-width is about t_1 s_j, so the side becomes about t_S s_j, the Sidak box, which holds all k
normal estimates at once with probability >= ``level`` whatever their correlation (Sidak 1967). The extra width is
never negative, so the region holds each per-parameter interval, and it is zero for one parameter, so the region
is then that interval. The bias terms (window shift, allowance) are added as they are: they bound a shift, not a
spread at a level. Why not the max-|studentised deviation| quantile of the refits (the textbook simultaneous
bootstrap band): its 95 % point taken from 40 refits is too noisy; on a linear-Gaussian problem with known truth
like tests/test_simultaneous_region.py's (n = 400, six parameters, 40 refits, 4000 replicates, seeds 9 and 10) that
band held all six truths in 92-93 % of replicates (90-91 % scaled onto the basic intervals), this one in 94-95 %.
Why not Bonferroni on the refits' order statistics: 0.05 / 12 a side would need an order statistic beyond the
smallest of 40 refits. Why not Scheffe: the ellipsoid's box is 3.55 standard errors wide
for six parameters against Sidak's 2.63; the box is what is reported.

At a bound the bootstrap fails: refits cannot cross the bound, so they pile up on it and their spread collapses
(the bootstrap is inconsistent for a parameter on the boundary of its space, Andrews 2000, Econometrica 68(2)).
For a parameter whose estimate or refits sit on a bound, :func:`bound_fallback` reports the union of this
interval and the Jacobian interval (a local spread that does not see the bound), and of the joint region and the
Jacobian joint region (:mod:`calibration.identification.uncertainty`, Sidak).

Cost: (iterations + 1) x (2 k + 1) x refits model cycles in iterations + 1 batch calls (8, 6 parameters,
40 refits: 4,680 cycles, about 2-4 s on 2 cores), plus one small SLSQP per refit and iteration.
"""
from __future__ import annotations

import difflib
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from scipy import stats

from press_model.readers import FieldReader
from press_model.settings_fields import own, setting

from calibration.identification.problem import Objective
from calibration.identification.slsqp_box import minimize_box
from calibration.identification.uncertainty import sidak_level


def _read_allowance(rd: FieldReader, path: tuple) -> dict:
    """The optional [calibration.bootstrap.allowance] table: parameter name -> widening of its interval on each side,
    a fraction of its range (>= 0; a name absent widens nothing).

    A name the job does not calibrate is kept and unused (a copied job may calibrate fewer parameters, and
    --parameters may choose others); one that looks like a misspelling of a calibrated name ([calibration]
    parameters) is refused."""
    names = rd.node(("calibration", "parameters"), required=False)
    names = [n for n in names if isinstance(n, str)] if isinstance(names, list) else []
    table = rd.table(path, required=False)
    out = {}
    for key in table:
        close = difflib.get_close_matches(key, names, n=1, cutoff=0.8)
        if key not in names and close:
            rd.fail((*path, key), table[key], f"names no key parameter (misspelled? did you mean '{close[0]}'?)")
        out[key] = rd.number((*path, key), ge=0.0, lt=1.0, unit="fraction of the parameter's range")
    return out


@dataclass(frozen=True)
class BootstrapSection:
    """[calibration.bootstrap] of a job (:class:`calibration.identification.settings.CalibrationSettings` ``.bootstrap``):
    the parametric bootstrap of the intervals (:func:`parametric_bootstrap`), with its optional ``allowance`` table
    (parameter = fraction of its range)."""

    refits: int = setting(40, "", "refits on resampled logs: (iterations + 1) x 13 x 40 = 4,680 model cycles", ge=0)
    block_deg: float = setting(1.0, "deg", "shortest block of the residual resampling, one grid step: blocks are made as "
                               "long as the residual's measured correlation needs (block_noise_lengths); longer ones lose the "
                               "noise the fit absorbed (calibration/identification/run.py block_points)", ge=1.0, lt=360.0, unit="deg")
    block_noise_lengths: float = setting(5.0, "correlation lengths", "under coloured noise a block holds at least this "
                                         "many correlation lengths (an AR(1)'s correlation falls below 1 % over five)",
                                         ge=1.0, unit="correlation lengths")
    step_guard_deg: float = setting(2.0, "deg", "grid points this close to a force step keep their own residual (a smeared "
                                    "step is no noise)", ge=0.0, lt=90.0, unit="deg")
    iterations: int = setting(8, "", "iterations of the batched local refit (Gauss-Newton on Eq. 28 with a trust region)", ge=1)
    allowance: dict = own(_read_allowance, dict)  # parameter name -> widening of its interval each side, fraction of its range


@dataclass(frozen=True)
class Bootstrap:
    """Refit estimates and what follows from them (SI units, problem.names order)."""

    estimates: np.ndarray  # (B, k) the refits
    low: np.ndarray  # the reported interval: basic interval widened by the allowance, clipped to the bounds, (k,)
    high: np.ndarray
    low_basic: np.ndarray  # the basic (reverse-percentile) interval alone, clipped to the bounds
    high_basic: np.ndarray
    low_percentile: np.ndarray  # the plain percentile interval of the refits, for comparison
    high_percentile: np.ndarray
    std: np.ndarray  # (k,)
    correlation: np.ndarray  # (k, k)
    level: float
    refits: int
    block_points: int
    cycles: int  # model cycles the refits used
    fixed_points: int  # grid points kept in place (not resampled)
    allowance: np.ndarray  # (k,) the job's extra widening on each side, as a fraction of each range
    window_shift: np.ndarray  # (k,) x_clean - x_hat (SI): the pull of the kept-in-place points; |.| widens each side
    on_bound: np.ndarray | None = None  # (k,) bool, set by bound_fallback: interval joined with the Jacobian interval
    joint_low: np.ndarray | None = None  # (k,) the joint region at ``level``: a box holding every truth at once
    joint_high: np.ndarray | None = None
    joint_extra: np.ndarray | None = None  # (k,) SI, :func:`simultaneous_extra`: each side's distance beyond the interval
    measured_peaks: np.ndarray | None = None  # (B,) N m: each refit's filtered measured peak (Eq. 28 rebuilt on its curve)


def block_resample(resid: np.ndarray, fixed: np.ndarray, block: int, rng: np.random.Generator) -> np.ndarray:
    """A circular block bootstrap of ``resid`` (n,) over the points not ``fixed``, centred: the free points are drawn
    from their values less their mean (module docstring); fixed points keep their value. Returns (n,), resid's unit."""
    free = np.flatnonzero(~fixed)
    pool = resid[free] - resid[free].mean()
    n = pool.size
    starts = rng.integers(0, n, size=-(-n // block))
    idx = (starts[:, None] + np.arange(block)[None, :]).ravel()[:n] % n
    out = resid.copy()
    out[free] = pool[idx]
    return out


def _local_step(lin, eq28, lo, hi):
    """Minimise the linearised Eq. 28, w |r + J s| / a0 + (1 - w) |g + h s| / b0 over the box lo <= s <= hi
    (epigraph form, SLSQP (:func:`calibration.identification.slsqp_box.minimize_box`: minimize's steps, bit for bit),
    analytic gradients; no model calls). ``lin``: the linearisation (r, J, g, h), r (n,) N m
    divided by sqrt(n), J (n, d) likewise; ``eq28``: its weight and normalisations (w, a0, b0)."""
    r, J, g, h = lin
    w, a0, b0 = eq28
    d = J.shape[1]

    def val(v):
        e = r + J @ v[:d]
        return w * np.sqrt(e @ e) / a0 + (1.0 - w) * v[d]

    def grad(v):
        e = r + J @ v[:d]
        nrm = max(np.sqrt(e @ e), 1e-300)
        return np.concatenate([w * (J.T @ e) / (nrm * a0), [1.0 - w]])

    def both(v):  # the epigraph's two sides, t >= +-(g + h s) / b0, as one constraint: one call of it a step
        q = (g + h @ v[:d]) / b0
        return np.array([v[d] - q, v[d] + q])

    rows = np.vstack([np.concatenate([-h / b0, [1.0]]), np.concatenate([h / b0, [1.0]])])
    v0 = np.concatenate([np.zeros(d), [abs(g) / b0]])
    v = minimize_box(val, grad, v0, (np.append(lo, 0.0), np.append(hi, np.inf)), both, rows, maxiter=100, ftol=1e-14)
    return np.clip(v[:d], lo, hi)


def refit_batch(objs: list[Objective], x0: np.ndarray, iterations: int, radius: float = 0.05) -> tuple[np.ndarray, np.ndarray, int]:
    """Minimise each objective of ``objs`` (all on the same batch model and problem) from ``x0`` by a batched
    Gauss-Newton with a box trust region: each iteration evaluates every refit's point in one model call, then the
    central-difference Jacobian of those whose point improved (the new best point, whose linearisation the next step
    solves) in a second, and solves each linearised Eq. 28 (peak at the model's peak point) within the trust region
    (``radius``, a fraction of each range; doubled after a good step, quartered after a rejected one). A rejected
    step steps again from its best point's stored linearisation, and the last iteration takes no step: neither needs
    a Jacobian, so none is computed (each set's curve is the model's alone, whatever else is in its batch).

    Returns (X (B, d) the best point of each, F (B,) Eq. 28 there, model cycles used).
    """
    o0 = objs[0]
    p = o0.problem
    span = p.high - p.low
    B, d = len(objs), len(x0)
    hstep = 1e-5 * span
    X = np.tile(np.asarray(x0, float), (B, 1))  # point evaluated this iteration
    best_X, best_F = X.copy(), np.full(B, np.inf)
    rad = np.full(B, radius)
    cycles = 0
    lin: list = [None] * B  # linearisation (r, J, g, h) at each refit's best point
    for it in range(iterations + 1):
        T0 = o0.torques(np.clip(X, p.low, p.high))
        cycles += B
        F = np.array([float(ob.value(T0[b][None])[0]) for b, ob in enumerate(objs)])
        better = F < best_F
        if it < iterations and better.any():
            _linearise(objs, np.flatnonzero(better), X, T0, hstep, lin)
            cycles += int(better.sum()) * 2 * d
        for b in range(B):
            if better[b]:
                if np.isfinite(best_F[b]):
                    rad[b] = min(2.0 * rad[b], 0.5)
                best_X[b], best_F[b] = X[b].copy(), F[b]
            else:
                rad[b] *= 0.25  # rejected: a shorter step from the best point, on its stored linearisation
            if it < iterations:
                u = (best_X[b] - p.low) / span
                s = _local_step(lin[b], (p.weight, objs[b].rmse0, abs(objs[b].pr0)), np.maximum(-rad[b], -u),
                                np.minimum(rad[b], 1.0 - u))
                X[b] = np.clip(best_X[b] + s * span, p.low, p.high)
    return best_X, best_F, cycles


def _linearise(objs: list[Objective], which: np.ndarray, X: np.ndarray, T0: np.ndarray, hstep: np.ndarray, lin: list) -> None:
    """Fill ``lin[b]`` for each refit b of ``which``: the linearisation (r, J, g, h) of its Eq. 28 at X[b], whose model
    curve T0[b] is known, with the central-difference Jacobian (steps ``hstep``, clipped to the bounds) of one model
    call over all of them; r and J over the Y_RMSE and peak points divided by their root count, g and h the relative
    peak error and its gradient at the model's peak point."""
    o0 = objs[0]
    p = o0.problem
    span = p.high - p.low
    d, n = X.shape[1], o0.bm.n_points
    m = o0.peak_points  # Y_RMSE's points and the peaks'
    sq = np.sqrt(m.sum())
    P = np.repeat(X[which], 2 * d, axis=0).reshape(len(which), 2 * d, d)
    for j in range(d):
        P[:, 2 * j, j] += hstep[j]
        P[:, 2 * j + 1, j] -= hstep[j]
    P = np.clip(P, p.low, p.high)
    T = o0.torques(P.reshape(-1, d)).reshape(len(which), 2 * d, n)
    for i, b in enumerate(which):
        ob = objs[b]
        dx = P[i, 0::2, :].diagonal() - P[i, 1::2, :].diagonal()
        J = ((T[i, 0::2] - T[i, 1::2]) / dx[:, None]).T * span  # N m per unit of range
        Tm = np.abs(T0[b])
        jm = int(np.flatnonzero(m)[np.argmax(Tm[m])])  # the model's peak point
        sgn = np.sign(T0[b, jm]) or 1.0
        lin[b] = ((T0[b] - ob.measured)[m] / sq, J[m] / sq, (Tm[jm] - ob.measured_peak) / ob.measured_peak,
                  sgn * J[jm] / ob.measured_peak)


def order_statistic_quantiles(X: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    """The (R+1) a-th and (R+1)(1-a)-th order statistics of the R refits X (R, k), a = (1 - level) / 2, per column
    (interpolated between neighbours when (R+1) a is no whole number; Davison and Hinkley 1997, Sec. 5.2).

    With R = 39 and level 0.95 these are the smallest and the largest refit. numpy's default quantile (positions
    1 + (R-1) a) lies inside them: with 40 refits its 2.5-97.5 % range holds a further draw of the same law only
    (R + 1 - 2 x 1.975) / (R + 1) = 90 % of the time, and so did intervals built on it."""
    a = (1.0 - level) / 2.0
    return np.quantile(X, a, axis=0, method="weibull"), np.quantile(X, 1.0 - a, axis=0, method="weibull")


def simultaneous_extra(X: np.ndarray, level: float) -> np.ndarray:
    """(k,) SI: how far each side of a per-parameter ``level`` interval of the refits X (R, k) moves out to make the
    joint region (module docstring): (t_S - t_1) s_j, s_j the refits' standard deviation, t_1 and t_S the
    t-quantiles with R - 1 degrees of freedom at ``level`` and at the Sidak level ``level ** (1 / k)``. Never
    negative; zero for one parameter."""
    X = np.atleast_2d(np.asarray(X, float))
    R, k = X.shape
    if R < 2:
        return np.zeros(k)
    t_1, t_s = (stats.t.ppf(0.5 + a / 2.0, R - 1) for a in (level, sidak_level(level, k)))
    return max(t_s - t_1, 0.0) * X.std(axis=0, ddof=1)


def parametric_bootstrap(obj: Objective, x_hat: np.ndarray, make_objective: Callable[[np.ndarray], Objective],
                         fixed: np.ndarray, block_points: int, settings: BootstrapSection, level: float,
                         seed: int) -> Bootstrap:
    """The bootstrap of the module docstring at the confidence ``level``. ``make_objective(curve)`` builds Eq. 28
    against a curve (N m, on obj's grid) exactly as the calibration built it against the log; ``fixed`` (bool, n) the
    points kept in place; ``block_points`` the resampled blocks' length; ``settings`` the job's
    [calibration.bootstrap]: its ``refits``, the ``iterations`` of the batched local solver (:func:`refit_batch`) and
    its ``allowance``, an extra widening on each side, a fraction of each parameter's calibration range."""
    refits, iterations = settings.refits, settings.iterations
    allowance = np.array([settings.allowance.get(n, 0.0) for n in obj.problem.names])
    rng = np.random.default_rng(seed)
    T_hat = obj.torques(np.asarray(x_hat, float)[None])[0]
    resid = obj.measured - T_hat
    objs = [make_objective(T_hat + block_resample(resid, fixed, block_points, rng)) for _ in range(refits)]
    objs.append(make_objective(np.where(fixed, T_hat, obj.measured)))  # the log without what the fixed points hold
    X, _, cycles = refit_batch(objs, np.asarray(x_hat, float), iterations)
    shift = X[-1] - np.asarray(x_hat, float)
    X = X[:-1]
    q_lo, q_hi = order_statistic_quantiles(X, level)
    p = obj.problem
    span = p.high - p.low
    allow = np.zeros(len(x_hat)) if allowance is None else np.asarray(allowance, float)
    low_b, high_b = 2.0 * x_hat - q_hi, 2.0 * x_hat - q_lo
    low = np.clip(low_b - np.abs(shift) - allow * span, p.low, p.high)
    high = np.clip(high_b + np.abs(shift) + allow * span, p.low, p.high)
    extra = simultaneous_extra(X, level)
    joint_low = np.clip(low_b - extra - np.abs(shift) - allow * span, p.low, p.high)
    joint_high = np.clip(high_b + extra + np.abs(shift) + allow * span, p.low, p.high)
    std = X.std(axis=0, ddof=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.atleast_2d(np.corrcoef(X, rowvar=False))  # one parameter: corrcoef gives a scalar
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    return Bootstrap(X, low, high, np.clip(low_b, p.low, p.high), np.clip(high_b, p.low, p.high), q_lo, q_hi, std, corr,
                     level, refits, block_points, cycles + refits + 1, int(fixed.sum()), allow, shift, None,
                     joint_low, joint_high, extra, np.array([ob.measured_peak for ob in objs[:-1]]))


def refits_on_bound(boot: Bootstrap, x_hat: np.ndarray, low: np.ndarray, high: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """(k,) bool: the estimate or any refit lies within ``tol`` of its range from a bound."""
    span = high - low
    X = np.vstack([boot.estimates, np.asarray(x_hat, float)[None]])
    return np.any(X <= low + tol * span, axis=0) | np.any(X >= high - tol * span, axis=0)


def bound_fallback(boot: Bootstrap, x_hat: np.ndarray, low: np.ndarray, high: np.ndarray,
                   jac_low: np.ndarray, jac_high: np.ndarray, jac_joint_low: np.ndarray | None = None,
                   jac_joint_high: np.ndarray | None = None) -> tuple[Bootstrap, np.ndarray]:
    """The bootstrap with each on-bound parameter's interval (:func:`refits_on_bound`) replaced by its union with the
    Jacobian interval, and its side of the joint region by the union with the Jacobian joint region (module
    docstring); returns (the bootstrap, the on-bound mask)."""
    at = refits_on_bound(boot, x_hat, low, high)
    return join_where(boot, at, jac_low, jac_high, jac_joint_low, jac_joint_high, on_bound=at), at


def join_where(boot: Bootstrap, where: np.ndarray, jac_low, jac_high, jac_joint_low=None, jac_joint_high=None, **more) -> Bootstrap:
    """The bootstrap with the intervals (and the joint region's sides) of the parameters ``where`` (k,) bool joined
    with the Jacobian ones (union); ``more`` further fields to replace."""
    lo = np.where(where, np.minimum(boot.low, jac_low), boot.low)
    hi = np.where(where, np.maximum(boot.high, jac_high), boot.high)
    if boot.joint_low is not None and jac_joint_low is not None:
        more.update(joint_low=np.where(where, np.minimum(boot.joint_low, jac_joint_low), boot.joint_low),
                    joint_high=np.where(where, np.maximum(boot.joint_high, jac_joint_high), boot.joint_high))
    return replace(boot, low=lo, high=hi, **more)


BOUND_SHARE = 1e-3  # an estimate within this share of its range from a range bound sits on the bound


def on_bound(x, bound_low, bound_high) -> np.ndarray:
    """(k,) bool: the estimates ``x`` that sit on a bound of their calibration range (within :data:`BOUND_SHARE`)."""
    x, lo, hi = (np.asarray(a, float) for a in (x, bound_low, bound_high))
    return np.minimum(x - lo, hi - x) <= BOUND_SHARE * (hi - lo)


def statements(problem, intervals, corr_limit: float, width_limit: float, source: str, x=None) -> list[str]:
    """Plain statements from one rule, so that they cannot contradict each other: of the parameters ``problem.names``
    with their calibration ranges ``problem.low`` .. ``problem.high`` (a :class:`CalibrationProblem`), from the
    intervals ``intervals.low`` .. ``intervals.high`` and the estimates' correlation ``intervals.correlation`` (a
    :class:`Bootstrap` or :class:`calibration.identification.uncertainty.Uncertainty`).

    Each parameter gets exactly one label: *on a range bound, not identified* when its estimate ``x`` (if given)
    sits on a bound of its calibration range (the data pull it beyond the range: its interval is clipped there and
    says nothing); otherwise *poorly identified* when its interval is wider than
    ``width_limit`` of its calibration range; otherwise *identified only in combination* when its estimate
    correlates beyond ``corr_limit`` with another parameter's; otherwise *identified*. The pairs are listed
    once, with their correlation.
    """
    names, bound_low, bound_high = list(problem.names), problem.low, problem.high
    low, high, corr = intervals.low, intervals.high, intervals.correlation
    width = (np.asarray(high) - np.asarray(low)) / (np.asarray(bound_high) - np.asarray(bound_low))
    k = len(names)
    bound = [] if x is None else [int(i) for i in np.flatnonzero(on_bound(x, bound_low, bound_high))]
    pairs = [(i, j) for i in range(k) for j in range(i + 1, k) if abs(corr[i, j]) > corr_limit]
    in_pair = {i for pr in pairs for i in pr}
    poor = [i for i in range(k) if width[i] > width_limit and i not in bound]
    combo = [i for i in range(k) if i not in poor and i not in bound and i in in_pair]
    good = [i for i in range(k) if i not in poor and i not in bound and i not in in_pair]
    out = [f"(from the {source}: interval width as a share of the calibration range, limit {width_limit:g}; "
           f"correlation of the estimates, limit |{corr_limit:g}|)"]
    if good:
        out.append("identified: " + ", ".join(f"{names[i]} ({100 * width[i]:.1f} % of its range)" for i in good) + ".")
    if combo:
        out.append("identified only in combination: " + ", ".join(f"{names[i]} ({100 * width[i]:.1f} % of its range)" for i in combo)
                   + "; the experiment sees a combination of each correlated pair better than either parameter alone.")
    if poor:
        out.append("poorly identified: " + ", ".join(f"{names[i]} ({100 * width[i]:.0f} % of its range)" for i in poor) + ".")
    if bound:
        out.append("on a range bound, not identified: " + ", ".join(names[i] for i in bound) + "; the data pull these beyond "
                   "their calibration range, so their intervals are cut off there and say nothing.")
    for i, j in pairs:
        out.append(f"correlated pair: {names[i]} and {names[j]} ({corr[i, j]:+.2f}).")
    if not pairs:
        out.append(f"no pair of estimates is correlated beyond |{corr_limit:g}|.")
    return out
