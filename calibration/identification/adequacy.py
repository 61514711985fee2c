"""Is the calibrated model adequate for the log? A lack-of-fit test from the log's replicate strokes, and score tests
that name what is missing.

A drive log holds several strokes of the same motion, so the noise is known without any model: the
stroke-to-stroke deviations from the stroke-mean curve (*pure error*). The calibrated model is compared with
the mean curve; if it describes the press, its residual is the noise of the mean and nothing else.

**Lack of fit** (the classical F test of regression with replicates, e.g. Draper and Smith, *Applied Regression
Analysis*, 3rd ed., Sec. 2.1): on the m grid points of the *mask* (outside the die-contact window and the force
steps' neighbours, where the rigid model is not meant to follow the log), with c_i values at point i,

    SS_LOF = sum_i c_i (T_model,i - mean_i)^2    on m - k degrees of freedom (k calibrated parameters),
    SS_PE  = sum_i sum_j (y_ij - mean_i)^2       on sum_i (c_i - 1),
    F = (SS_LOF / (m - k)) / (SS_PE / dof_PE),

F near 1 when the model is adequate, larger when it misses something systematic. The classical test takes the
least-squares fit on the tested points; the calibrated estimate is Eq. 28's on the whole turn, pulled by what the
rigid model cannot follow in the die-contact window (the ringing). So the residual on the mask is first
projected off the columns of the residual Jacobian: T_model is the calibrated curve moved by the linearised
least-squares step on the mask, what no change of the k parameters can absorb is left, and the test asks
whether *that* exceeds the noise (the window's pull on the estimate is covered by the interval's window shift,
:mod:`calibration.identification.bootstrap`). Neighbouring grid points are
not independent when the noise is coloured; both sums of squares then carry fewer degrees of freedom. With rho
the lag-one correlation of the pure-error deviations along the grid (an AR(1) description of the noise), a sum
of m squares of such noise has the variance of a chi-square on m (1 - rho^2) / (1 + rho^2) degrees of freedom
(Satterthwaite's match of the first two moments); the p-value uses those. When the model curve has an error of its
own (the crank speed and acceleration it is computed from are estimated from the log's noisy speed samples, the same
for every stroke: :mod:`calibration.identification.motion_error`), each point's squared residual is weighed by the
noise of its mean over that noise plus the curve's variance there (errors in the variables), in the sum and in the
projection; an exact curve keeps the classical test.

**Structure**: the residual's lag-one autocorrelation on the same mask, against the pure error's own (the noise
of the mean is correlated as the deviations are). A smooth misfit raises it above the noise's; the one-sided
p-value uses the asymptotic standard error sqrt((1 - rho^2) / pairs) of a lag-one estimate of an AR(1) series.
It is reported as a diagnostic, not part of the verdict: with some 300 points it flags smooth misfits of a few
per cent of the noise variance (the die-contact ringing's pull on the inertia leaves one on every log), which
move no parameter by more than its interval; the verdict rests on the misfit's size (F) and the named effects.
When the pure error's own lag-one correlation exceeds what white noise gives, the noise is *coloured*: no
model error, but the bootstrap's blocks must be longer than its correlation (:func:`calibration.identification.run.block_points`).

**Suspects** (score, or Lagrange-multiplier, tests at the optimum): each candidate effect is one or two extra
columns z beside the residual Jacobian J (both on the mask); the residual is regressed on [J, z] and the
coefficient of z, its standard error and t follow (the variance from the residual of that regression, inflated
by its own AR(1) factor (1 + r1) / (1 - r1)). The coefficient is the size of the effect that the log implies.
When the model curve has an error of its own (as in the lack-of-fit test), the coefficient's variance holds that
error's through the regression, c' (S_noise + S_model) c with c the coefficient's row of the least-squares step (the
same nuisance columns projected off), and the noise's share is the residual's sum of squares less the model's expected
share: a crank motion's error where a ramp ends sits where the torque's slope (the delay's and offset's column) is steep,
and a variance pooled over the turn understates it there (:func:`regress`).
The candidates (:func:`candidate_columns`): channel delay, encoder offset, load-dependent efficiency, viscous
drive loss, constant (Coulomb) drag, lost motion in the gear where its torque reverses (tested with the delay and
offset free beside it, on the log's bin means), ripple at the motor orders; and, when the fit holds some of the job's
parameters at the press file's values (a subset, e.g. a sensitivity's key set), each held parameter: its column is
the model curve's derivative along it (:func:`held_columns`), so its t says whether the log disagrees with the held value
and its coefficient is the change of the parameter the log implies.

Thresholds: the F test and the score tests share the job's ``adequacy_level`` (the chance of a false alarm on
an adequate log) by Bonferroni, so the verdict's false-alarm rate is at most that level. Nothing is
fitted to a synthetic truth.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

REVERSAL_SHARE = 0.05  # the backlash candidate is tested when the torque has each sign on at least this share of the grid


@dataclass(frozen=True)
class Candidate:
    """An effect the model may lack: its columns (n, c) on the grid (N m per unit of the size) and how to report it."""

    name: str
    what: str
    columns: np.ndarray  # (n, c)
    unit: str  # unit of the reported size
    scale: float  # reported size = coefficient x scale (e.g. s -> ms)
    free: np.ndarray | None = None  # (n, f) nuisance columns fitted beside it in its test, not themselves tested
    binned: bool = False  # tested on the log's bin means (:func:`assess`'s ``binned``), as the recording estimate reads shifts
    held: float | None = None  # a held parameter's value (SI): the candidate is that parameter, its size the change implied


@dataclass(frozen=True)
class ScoreTest:
    name: str
    what: str
    t: float  # |coefficient| / standard error (for two columns: sqrt of the Wald statistic)
    p_value: float
    size: float  # implied size, in ``unit`` (for two columns: the amplitude)
    size_std: float
    unit: str
    significant: bool
    t_given_others: float = math.nan  # the smallest t of this candidate beside each other significant one (nan: none other)
    explained_by: str = ""  # the significant candidate beside which this one is no longer significant ("" if none)
    held: float | None = None  # a held parameter's value (SI; None: an effect the model lacks)
    lof_if_freed: float = math.nan  # the lack-of-fit F with this held parameter freed (linearised; nan: not a held one)


@dataclass(frozen=True)
class Adequacy:
    """The verdict of the module docstring (SI units, N m for torques)."""

    lack_of_fit_ratio: float  # F
    p_value: float
    dof: tuple[float, float]  # effective degrees of freedom of F (numerator, denominator)
    residual_rms_Nm: float  # on the mask
    pure_error_rms_Nm: float  # RMS noise of the mean curve on the mask, from the strokes
    residual_lag1: float
    pure_error_lag1: float
    lag1_p_value: float
    mask_points: int
    strokes: int  # complete strokes on the tested points: each covered at least this often (the log's own count there)
    level: float
    tests: tuple[ScoreTest, ...] = ()
    adequate: bool = True
    noise_coloured: bool = False
    reasons: tuple[str, ...] = field(default=())

    @property
    def suspects(self) -> list[ScoreTest]:
        """The significant candidates, the one that best survives the others first (:func:`rank_suspects`); those another
        one explains last."""
        return sorted((t for t in self.tests if t.significant),
                      key=lambda t: (bool(t.explained_by), -(t.t_given_others if math.isfinite(t.t_given_others) else t.t)))

    def record(self) -> dict:
        """The ``adequacy`` entry of calibrated.json."""
        return {
            "adequate": self.adequate,
            "lack_of_fit_ratio": self.lack_of_fit_ratio, "p_value": self.p_value,
            "dof_effective": list(self.dof),
            "residual_rms_Nm": self.residual_rms_Nm, "pure_error_rms_Nm": self.pure_error_rms_Nm,
            "residual_lag1": self.residual_lag1, "pure_error_lag1": self.pure_error_lag1, "lag1_p_value": self.lag1_p_value,
            "noise_coloured": self.noise_coloured,
            "mask_points": self.mask_points, "strokes": self.strokes, "level": self.level,
            "suspects": [s.name for s in self.suspects],
            "score_tests": {t.name: {"t": t.t, "p_value": t.p_value, "size": t.size, "size_std": t.size_std, "unit": t.unit,
                                     "significant": t.significant, "what": t.what,
                                     **({"t_given_others": t.t_given_others, "explained_by": t.explained_by}
                                        if math.isfinite(t.t_given_others) else {}),
                                     **({"held_value": t.held, "lack_of_fit_ratio_if_freed": t.lof_if_freed}
                                        if t.held is not None else {})}
                            for t in self.tests},
            "reasons": list(self.reasons),
            "method": ("lack-of-fit F test of the calibrated curve against the stroke-to-stroke (pure) error on the mask "
                       "outside the die-contact window and the force steps, degrees of freedom reduced for the noise's "
                       "AR(1) correlation; residual lag-one autocorrelation against the pure error's; score tests of "
                       "candidate effects as extra Jacobian columns; all at the job's adequacy_level shared by Bonferroni "
                       "(calibration/identification/adequacy.py)"),
        }

    def warning(self) -> str | None:
        """One plain sentence when the model is not adequate for the log, else None."""
        if self.adequate:
            return None
        sus = self.suspects
        named = ("; the log points at " + ", ".join(f"{s.what} (t = {s.t:.1f}, size {s.size:.3g} {s.unit}"
                                                    + (f"; explained by {s.explained_by} beside it" if s.explained_by else "") + ")"
                                                    for s in sus[:3])
                 if sus else "; no candidate effect explains it")
        return (f"MODEL NOT ADEQUATE for this log: the calibrated model misses the measured curve by "
                f"{math.sqrt(self.lack_of_fit_ratio):.2f} times the stroke-to-stroke noise of the mean "
                f"(lack-of-fit F = {self.lack_of_fit_ratio:.2f}, p = {self.p_value:.2g}; residual lag-1 {self.residual_lag1:.2f} "
                f"against the noise's {self.pure_error_lag1:.2f}){named}. The parameters have absorbed an effect the model "
                "lacks: they and their intervals describe the best fit of a wrong model, and the intervals do not cover "
                "that model error")


def lag1(x: np.ndarray, mask: np.ndarray) -> tuple[float, int]:
    """Lag-one autocorrelation of x (..., n) over the pairs of neighbouring grid points both in ``mask`` (the grid is
    periodic), pooled over leading axes; returns (r1, number of pairs)."""
    x = np.asarray(x, float)
    pair = mask & np.roll(mask, -1)
    a, b = x[..., pair], np.roll(x, -1, axis=-1)[..., pair]
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    xm = x[..., mask]
    xm = xm[np.isfinite(xm)]
    mu = float(np.mean(xm)) if xm.size else 0.0
    den = float(np.sum((xm - mu) ** 2)) * (a.size / max(xm.size, 1))
    return (float(np.sum((a - mu) * (b - mu)) / den) if den > 0 else 0.0), int(a.size)


def effective_dof(m: float, rho: float) -> float:
    """Degrees of freedom of a sum of m squares of AR(1) noise with lag-one correlation rho (Satterthwaite)."""
    r2 = min(max(rho, 0.0), 0.999) ** 2
    return m * (1.0 - r2) / (1.0 + r2)


def shift_columns(theta: np.ndarray, theta_dot: np.ndarray, torque: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What the measured curve gains per second of torque-channel delay (-omega dT/dtheta, N m / s) and per radian
    of encoder offset (-dT/dtheta, N m / rad), at the curve ``torque`` on the uniform periodic grid ``theta``."""
    step = float(theta[1] - theta[0])
    dT = (np.roll(torque, -1) - np.roll(torque, 1)) / (2.0 * step)  # periodic central difference, N m / rad
    return -theta_dot * dT, -dT


def candidate_columns(theta: np.ndarray, theta_dot: np.ndarray, torque: np.ndarray, gear_ratio: float,
                      rated_Nm: float, ripple_orders=(6,)) -> list[Candidate]:
    """The candidate effects' columns at the calibrated curve ``torque`` (N m per motor) on the uniform periodic grid
    ``theta`` (rad) with crank speed ``theta_dot`` (rad/s). Each column is what the measured curve gains per unit of
    the effect, to first order:

    * channel delay d (torque logged at t behind the angle): T(theta) - d omega dT/dtheta -> column -omega dT/dtheta;
    * encoder offset delta (logged angle = true + delta): T(theta - delta) -> column -dT/dtheta;
    * gear efficiency falling by a x |T| / T_rated: T / (1 - a |T| / T_rated) driving, T (1 - a |T| / T_rated)
      braking, both T + a T^2 / T_rated to first order -> column T^2 / T_rated;
    * viscous drive loss c omega_m (motor speed omega_m = u omega) -> column omega_m;
    * constant drag d sgn(omega_m) (Coulomb friction of the motor and gearbox bearings and seals; on the gear's side it
      passes the efficiency, d / eta or d eta, which one log cannot tell from d) -> column sgn(omega_m);
    * lost motion b (motor radians) in the gear, with the angle taken from the motor side: the crank lags the motor by
      b / (2 u) while the gear torque drives and leads it by as much while it brakes, T(theta - sgn(T) b / (2 u)) ->
      column -sgn(T) dT/dtheta / (2 u); only where the torque reverses (at least ``REVERSAL_SHARE`` of the grid on
      each side), else it is the encoder offset's column. Tested with the delay and offset columns free beside it
      (``free``): a torque that drives over most of the turn makes the lost motion mostly a constant shift, which the
      recording estimate takes as an offset (16 motor deg read as +0.33 .. +0.48 deg on SYNTHETIC logs); what tells
      lost motion from an offset is the shift's change of sign where the torque reverses, which is what is left of the
      column beside them. It is a shift along the angle, so it is read on the bin means, as the recording estimate
      reads the delay and offset (``binned``; :mod:`calibration.identification.recording`: the interpolated curve leaves
      most samples unread and doubles the shifts' standard error), each bin weighted by its share of the samples
      (:func:`assess`; a bin mean's noise variance is the samples' over their count, which follows the crank's
      slowness: over 25 clean SYNTHETIC cushion-test logs, seeds 9320-9344, the t had an RMS of 1.24 unweighted, 1.03 weighted).
      A bin mean is the torque averaged over its samples' angles, so the bin means are compared with the model's own
      bin means (``binned`` from :func:`calibration.identification.recording.bin_smear`): a first-order angle correction
      leaves the curvature over each bin, a deterministic residual that flips where the torque's slope does and read
      as lost motion where the crank changes speed within a few degrees;
    * ripple at order q per motor turn -> columns sin(q u theta), cos(q u theta) (amplitude reported).
    """
    delay, offset = shift_columns(theta, theta_dot, torque)
    rms = math.sqrt(float(np.mean(torque ** 2)))
    wm = gear_ratio * theta_dot
    out = [
        Candidate("channel_delay", "a torque channel delayed behind the angle", delay[:, None], "ms", 1e3),
        Candidate("angle_offset", "an encoder zero offset", offset[:, None], "deg", math.degrees(1.0)),
        Candidate("load_dependent_efficiency", "a gear efficiency that falls with load (fall at rated torque)",
                  (torque ** 2 / rated_Nm)[:, None], "% at rated torque", 100.0),
        Candidate("viscous_loss", "a speed-proportional drive loss (RMS as % of the RMS torque)", wm[:, None],
                  "% of RMS torque", 100.0 * math.sqrt(float(np.mean(wm ** 2))) / rms),
        Candidate("coulomb_drag", "a constant drag opposing the motor's rotation (size as % of the RMS torque)",
                  np.sign(wm)[:, None], "% of RMS torque", 100.0 / rms),
    ]
    sign = np.sign(torque)
    if min(np.mean(sign > 0), np.mean(sign < 0)) >= REVERSAL_SHARE:
        out.append(Candidate("backlash", "lost motion in the gear where its torque reverses (motor degrees)",
                             (sign * offset / (2.0 * gear_ratio))[:, None], "motor deg", math.degrees(1.0),
                             free=np.column_stack([delay, offset]), binned=True))
    for q in ripple_orders:
        ph = q * gear_ratio * theta
        out.append(Candidate(f"ripple_{q:g}", f"a torque ripple at {q:g} per motor turn (amplitude as % of the RMS torque)",
                             np.column_stack([np.sin(ph), np.cos(ph)]), "% of RMS torque", 100.0 / rms))
    return out


def _weighted(X: np.ndarray, y: np.ndarray, v: np.ndarray, s2: float, rounds: int = 4):
    """Weighted least squares of y on X with row variances s^2 + v (v the model curve's, s^2 the noise's, unknown):
    returns (coefficients, the step A = (X'WX)^-1 X'W, s^2). s^2 is the root of sum_i e_i^2 / (s^2 + v_i) = n - p
    (the weighted residual e's sum of squares at its degrees of freedom), alternated with the fit ``rounds`` times
    from ``s2``: the rows the fit leans on then set it. The unweighted residual less the model's expected share
    (:func:`regress`) understated it where v is large beside the noise (the coefficients' RMS error over their stated
    standard error 1.29 with v 16 x the noise's variance on a third of the rows); 0 where even that is more than the
    residual holds (v overstated)."""
    n, p = X.shape
    beta = A = None
    floor = 1e-12 * max(float(np.mean(y * y)), 1e-300)  # a variance: keeps a row with v = 0 finite at s^2 = 0
    for _ in range(rounds):
        w = 1.0 / np.maximum(s2 + v, floor)
        Xw = X * w[:, None]
        A = np.linalg.pinv(X.T @ Xw) @ Xw.T
        beta = A @ y
        e2 = (y - X @ beta) ** 2
        hi = float(np.sum(e2)) / max(n - p, 1)  # sum e^2 / (hi + v) <= n - p there

        def excess(t):
            return float(np.sum(e2 / np.maximum(t + v, 1e-300))) - (n - p)

        lo = 1e-12 * hi
        s2 = 0.0 if hi <= 0.0 or excess(lo) <= 0.0 else (hi if excess(hi) >= 0.0 else optimize.brentq(excess, lo, hi, rtol=1e-6))
    return beta, A, s2


def regress(resid: np.ndarray, J: np.ndarray, Z: np.ndarray, mask: np.ndarray,
            model_variance: np.ndarray | None = None, weighted: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """Regress ``resid`` (n,) on [J, Z] over ``mask``: the coefficients of Z's c columns (c,), their covariance (c, c)
    and the effective degrees of freedom of the noise's share of it. The covariance is the noise's (the regression's
    residual variance, inflated by its AR(1) factor (1 + r1) / (1 - r1)) plus, when the residual's rows carry a
    model curve's own variance ``model_variance`` (n,) (errors in the variables, :func:`lof_weights`), that variance
    through the least-squares step A = (X'X)^-1 X': A diag(v) A'. The residual's sum of squares then holds both, so
    the noise's variance is taken from it less the model's expected share, sum_i (1 - h_i) v_i (h the leverages).

    ``weighted`` (with ``model_variance``): the coefficients by weighted least squares, each row weighed by the inverse
    of its variance s^2 + v_i (s^2 the noise's variance from the unweighted pass above; one feasible-GLS step), so rows
    whose model curve is uncertain (a sharp speed ramp's ends, :mod:`calibration.identification.motion_error`) do not
    drive them; the covariance is then A diag(s^2 (AR(1) factor) + v) A' with A = (X'WX)^-1 X'W. Without a noise
    variance left (s^2 = 0) the rows are not weighed."""
    Z = np.asarray(Z, float).reshape(len(mask), -1)
    X = np.column_stack([J[mask], Z[mask]])
    y = resid[mask]
    sc = np.sqrt(np.sum(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    Xs = X / sc  # columns of any unit (kg, efficiency, seconds) on one scale
    beta, *_ = np.linalg.lstsq(Xs, y, rcond=None)
    e = y - Xs @ beta
    n, p = Xs.shape
    full = np.zeros(len(mask))
    full[mask] = e
    r1, _ = lag1(full, mask)
    infl = (1.0 + r1) / (1.0 - r1) if 0.0 < r1 < 1.0 else 1.0
    inv = np.linalg.pinv(Xs.T @ Xs)
    ss = float(e @ e)
    v = None
    if model_variance is not None:
        v = np.asarray(model_variance, float)[mask]
        v = np.where(np.isfinite(v), np.maximum(v, 0.0), 0.0)
        lev = np.einsum("ij,jk,ik->i", Xs, inv, Xs)
        ss = max(ss - float(np.sum((1.0 - lev) * v)), 0.0)
    s2 = ss / max(n - p, 1)
    cov = inv * (s2 * infl)
    if v is not None and weighted and np.any(v > 0.0):
        beta, A, s2 = _weighted(Xs, y, v, float(e @ e) / max(n - p, 1))
        cov = (A * (s2 * infl + v)[None]) @ A.T
    elif v is not None:
        A = inv @ Xs.T
        cov = cov + (A * v[None]) @ A.T
    c = Z.shape[1]
    return beta[-c:] / sc[-c:], cov[-c:, -c:] / np.outer(sc[-c:], sc[-c:]), max(effective_dof(n - p, r1), 1.0)


def in_span(J: np.ndarray, Z: np.ndarray, tol: float = 1e-6) -> bool:
    """True when every column of ``Z`` is a combination of ``J``'s columns (to ``tol`` of its norm): the calibrated
    parameters already contain that effect (e.g. the press file's viscous drive loss c_drive), so a score test of it
    has no direction left and would divide by zero."""
    Z = np.asarray(Z, float).reshape(len(J), -1)
    J = J / np.maximum(np.sqrt(np.sum(J ** 2, axis=0)), 1e-300)  # columns of any unit on one scale
    coef, *_ = np.linalg.lstsq(J, Z, rcond=None)
    left = np.sqrt(np.sum((Z - J @ coef) ** 2, axis=0))
    return bool(np.all(left <= tol * np.maximum(np.sqrt(np.sum(Z ** 2, axis=0)), 1e-300)))


def beside(J: np.ndarray, cand: Candidate) -> np.ndarray:
    """The columns a candidate is tested beside: ``J`` (n, k) and its ``free`` nuisance columns."""
    return J if cand.free is None else np.column_stack([J, cand.free])


def score_test(resid: np.ndarray, J: np.ndarray, cand: Candidate, mask: np.ndarray, alpha: float,
               model_variance: np.ndarray | None = None) -> ScoreTest:
    """The candidate's coefficient in the regression of the residual (measured - model, N m) on [J, its free
    columns, z] over the mask, and its test at ``alpha`` (two-sided t; for two columns the Wald F); ``model_variance``
    (n,) N m^2 the model curve's own variance in the residual's rows (:func:`regress`; None: an exact curve)."""
    b, V, dof = regress(resid, beside(J, cand), cand.columns, mask, model_variance)
    c = len(b)
    if c == 1:
        sd = math.sqrt(max(V[0, 0], 0.0))
        t = abs(b[0]) / sd if sd > 0 else math.inf
        pv = 2.0 * stats.t.sf(t, dof)
        size, size_sd = b[0] * cand.scale, sd * cand.scale
    else:
        w = float(b @ np.linalg.pinv(V) @ b)
        pv = float(stats.f.sf(w / c, c, dof))
        t = math.sqrt(w)
        size, size_sd = float(np.hypot(*b[:2])) * cand.scale, math.sqrt(max(np.trace(V) / 2.0, 0.0)) * cand.scale
    return ScoreTest(cand.name, cand.what, float(t), float(pv), float(size), float(size_sd), cand.unit, bool(pv < alpha),
                     held=cand.held)


def rank_suspects(resid, J: np.ndarray, cands: list[Candidate], tests: tuple[ScoreTest, ...],
                  mask: np.ndarray, alpha: float, rows=None, model_variance=None) -> tuple[ScoreTest, ...]:
    """``tests`` with each significant one's ``t_given_others``: its t in the regression of its residual (``resid``:
    one (n,) for all, or a list of one per candidate) on [J, its free columns, another significant candidate's
    columns, its columns], the smallest over the others; ``rows`` (a list of one per candidate, (n,) or None) the
    scale of each candidate's regression rows (:func:`assess`'s weighted tests), ``model_variance`` (a list of one per
    candidate, (n,) N m^2 in those rows, or None) the model curve's own variance (:func:`regress`). Two effects that look alike once
    the parameters have taken their share (a constant drag and a viscous loss at a mildly varying speed) are both
    significant alone; beside each other, the one the log shows keeps its t and the other loses it, so the suspects are
    named in that order; one no longer significant at ``alpha`` beside another is ``explained_by`` it."""
    sig = [i for i, t in enumerate(tests) if t.significant]
    if len(sig) < 2:
        return tests
    res = resid if isinstance(resid, list) else [resid] * len(cands)
    rows = rows or [None] * len(cands)
    mvar = model_variance or [None] * len(cands)
    out = list(tests)
    for i in sig:
        worst, by = math.inf, ""
        for j in sig:
            if j == i:
                continue
            sw = np.ones(len(mask)) if rows[i] is None else rows[i]
            b, V, dof = regress(res[i] * sw, np.column_stack([beside(J, cands[i]), cands[j].columns]) * sw[:, None],
                                cands[i].columns * sw[:, None], mask, mvar[i])
            c = len(b)
            w = float(b @ np.linalg.pinv(V) @ b)
            t = math.sqrt(max(w, 0.0))
            p = 2.0 * stats.t.sf(t, dof) if c == 1 else float(stats.f.sf(w / c, c, dof))
            if t < worst:
                worst = t
            if p >= alpha and not by:
                by = cands[j].name
        out[i] = ScoreTest(**{**tests[i].__dict__, "t_given_others": float(worst), "explained_by": by})
    return tuple(out)


def lof_weights(count: np.ndarray, noise_var: float, model_variance: np.ndarray | None) -> np.ndarray:
    """(n,) the weight of each point's squared residual in the lack-of-fit sum, relative to an exact model curve: the
    noise of the mean (``noise_var`` N m^2 per sample over ``count`` samples) over the residual's whole variance, that
    noise plus the model curve's own ``model_variance`` (n,) N m^2 (errors in the variables); ones when it is None."""
    c = np.asarray(count, float)
    if model_variance is None or noise_var <= 0.0:
        return np.ones(c.shape)
    v = np.where(np.isfinite(model_variance), np.maximum(model_variance, 0.0), 0.0)
    return 1.0 / (1.0 + c * v / noise_var)


def _scaled(c: Candidate, w: np.ndarray) -> Candidate:
    """The candidate with its regression rows scaled by ``w`` (n,) (a weighted least-squares test)."""
    return Candidate(c.name, c.what, c.columns * w[:, None], c.unit, c.scale,
                     None if c.free is None else c.free * w[:, None], c.binned, c.held)


@dataclass(frozen=True)
class Suspects:
    """What the score tests of :func:`assess` test: ``J`` (n, k) the residual Jacobian, ``candidates`` (none: no suspect
    is named); ``binned`` (n,) the log's bin means at the grid points
    (:func:`calibration.identification.recording.measured_curve`, with its bin-angle correction), the curve the
    candidates marked ``binned`` are tested on (None: the mean for all), in a regression weighted by ``bin_weight``
    (n,), proportional to the samples in each bin (None: unweighted)."""

    J: np.ndarray | None = None
    candidates: list[Candidate] | None = None
    binned: np.ndarray | None = None
    bin_weight: np.ndarray | None = None


def unabsorbed(r: np.ndarray, J: np.ndarray | None, use: np.ndarray, wt: np.ndarray) -> np.ndarray:
    """The residual ``r`` (n,) N m less its weighted least-squares projection on ``J``'s columns over ``use`` (weights
    ``wt``, :func:`lof_weights`): what no change of the parameters (to first order) can absorb; ``r`` itself without J."""
    if J is None:
        return r
    sw = np.sqrt(wt[use])
    Js = J[use] * sw[:, None]
    Js = Js / np.maximum(np.sqrt(np.sum(Js ** 2, axis=0)), 1e-300)
    r = np.array(r, dtype=float)
    r[use] -= Js @ np.linalg.lstsq(Js, r[use] * sw, rcond=None)[0] / sw
    return r


def assess(stroke_torque: np.ndarray, mean: np.ndarray, model: np.ndarray, mask: np.ndarray, k: int, level: float,
           suspects: Suspects = Suspects(), model_variance: np.ndarray | None = None) -> Adequacy:
    """The verdict of the module docstring.

    ``stroke_torque`` (S, n) each stroke on the grid (NaN where a turn has no data), ``mean`` (n,) their mean (the
    calibrated curve), ``model`` (n,) the calibrated model's curve, ``mask`` (n,) bool the points tested, ``k`` the
    number of calibrated parameters, ``level`` the false-alarm probability of the whole verdict; ``suspects`` the
    Jacobian the lack-of-fit test projects off and the score tests' candidates (:class:`Suspects`); ``model_variance``
    (n,) N m^2 the model curve's own variance at each point (the crank motion's uncertainty,
    :mod:`calibration.identification.motion_error`; None: an exact model curve), which the lack-of-fit sum weighs
    each point's residual by beside the noise of its mean and the score tests add to their coefficients' variance.
    """
    J, candidates, binned, bin_weight = suspects.J, suspects.candidates, suspects.binned, suspects.bin_weight
    Y = np.asarray(stroke_torque, float)
    mask = np.asarray(mask, bool)
    count = np.sum(np.isfinite(Y), axis=0)
    use = mask & (count >= 2)
    if use.sum() <= k + 2:
        raise ValueError("too few grid points covered by two strokes outside the die-contact window for a lack-of-fit test")
    dev = Y - mean[None]
    ss_pe = float(np.nansum(dev[:, use] ** 2))
    dof_pe = float(np.sum(count[use] - 1))
    wt = lof_weights(count, ss_pe / dof_pe, model_variance)
    r = unabsorbed(model - mean, J, use, wt)
    ss_lof = float(np.sum(wt[use] * count[use] * r[use] ** 2))
    m = int(use.sum())
    rho_pe, _ = lag1(np.where(np.isfinite(dev), dev, np.nan), use)
    d1, d2 = effective_dof(m - k, rho_pe), effective_dof(dof_pe, rho_pe)
    F = (ss_lof / (m - k)) / (ss_pe / dof_pe) if ss_pe > 0 else math.inf
    p = float(stats.f.sf(F, d1, d2))
    r1, pairs = lag1(r, use)
    se = math.sqrt(max(1.0 - min(max(rho_pe, 0.0), 0.999) ** 2, 1e-6) / max(pairs, 1))
    p_lag = float(stats.norm.sf((r1 - rho_pe) / se))
    cands = [c for c in candidates or []
             if J is None or not in_span(beside(J, c)[use], c.columns[use])]  # a loss the model has is no suspect
    n_tests = 1 + len(cands)
    alpha = level / n_tests  # Bonferroni: the verdict's false-alarm chance is at most `level`
    on_bins = [c.binned and binned is not None for c in cands]
    rows = [np.sqrt(bin_weight) if b and bin_weight is not None else None for b in on_bins]
    res = [(binned if b else mean) - model for b in on_bins]
    # the model curve's own variance in each test's rows (errors in the variables, as in the lack-of-fit sum)
    mvar = [None if model_variance is None else np.where(np.isfinite(model_variance), np.maximum(model_variance, 0.0), 0.0)
            * (1.0 if w is None else w ** 2) for w in rows]
    tests = ()
    if J is not None:
        tests = tuple(score_test(e, J, c, use, alpha, v) if w is None
                      else score_test(e * w, J * w[:, None], _scaled(c, w), use, alpha, v)
                      for e, c, w, v in zip(res, cands, rows, mvar))
        tests = rank_suspects(res, J, cands, tests, use, alpha, rows, mvar)
        # a held parameter's F once freed: the misfit the parameters and it together cannot absorb, on one more column
        tests = tuple(t if c.held is None else dataclasses.replace(t, lof_if_freed=(
            float(np.sum(wt[use] * count[use] * unabsorbed(model - mean, np.column_stack([J, c.columns]), use, wt)[use] ** 2))
            / (m - k - 1)) / (ss_pe / dof_pe) if ss_pe > 0 else math.inf) for t, c in zip(tests, cands))
    reasons = []
    if p < alpha:
        reasons.append(f"lack-of-fit F = {F:.2f} on ({d1:.0f}, {d2:.0f}) effective degrees of freedom, p = {p:.2g} < {alpha:.2g}")
    reasons += [f"score test of {t.name}: t = {t.t:.1f}, p = {t.p_value:.2g} < {alpha:.2g}" for t in tests if t.significant]
    # the noise is coloured when the pure error's own lag-one correlation is beyond what white noise gives
    coloured = rho_pe > stats.norm.ppf(1.0 - alpha) / math.sqrt(max(pairs, 1))
    return Adequacy(float(F), p, (d1, d2), math.sqrt(float(np.mean(r[use] ** 2))),
                    math.sqrt(ss_pe / dof_pe / float(np.mean(count[use]))), r1, rho_pe, p_lag, m,
                    int(np.min(count[use])), level, tests, not reasons, bool(coloured), tuple(reasons))
