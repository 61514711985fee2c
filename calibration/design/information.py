"""What a calibration run can tell: the information matrix of the calibrated parameters and the recording's nuisance
effects, the intervals it predicts, and the D-optimal criterion.

``calibrate`` fits the motor torque curve on the crank grid. Linearised least squares gives cov = s^2 c (J^T J)^-1
with J the residual Jacobian, s^2 the variance of the noise on one grid point of the stroke-averaged curve and c
the AR(1) factor of that noise's correlation along the grid. The same formula *before* the run, with J from the model
of the planned run at the expected parameters and s^2 c from a calibration already made
(:mod:`calibration.design.noise`: the job's ``[design] noise_rms_Nm`` and ``noise_inflation``, or the
stroke-to-stroke noise a calibrated.json records), predicts the intervals of that run. s is the *noise*, not the
residual RMS of a calibration: that also holds what the model does not follow (the points next to a force step, the
die-contact ringing), which is the same in every log of a run and moves no estimate from seed to seed; on the
reference cushion test it is 151 N m with c = 1.94 against a noise of 72 N m with c = 1, and the intervals predicted
from it came out 2-4 times the estimates' scatter over seeds (psi, m8, J_gear, mu_r; scripts/check_design_coverage.py).
Eq. 28 then holds the model's peak at the measured (filtered) peak, which is noisier than the least-squares estimate
of the peak: :func:`pinned_covariance` replaces the variance along the peak's gradient by the measured peak's.
Several runs fitted to one parameter set add their information:

    F = sum_runs [J_r Z_r]^T [J_r Z_r] / (s_r^2 c_r),

summed over the grid points Eq. 28 compares (:func:`fitted_points`: outside the die-contact window, whose ringing
`calibrate` leaves out of Y_RMSE and the peaks), with Z_r the nuisance columns of the recording (:func:`nuisance_columns`): a torque-channel delay d adds
-omega dT/dtheta x d to the measured curve, an encoder zero offset delta adds -dT/dtheta x delta
(:mod:`calibration.identification.recording`). They are one delay and one offset for all runs (the same drive and channels), so
each run's columns add to the same two unknowns; the parameters' covariance is the parameter block of F^-1, which
accounts for what the nuisance effects could absorb.

A run whose process force is logged (the model takes the logged curve, :mod:`calibration.identification.force_noise`)
adds that curve's noise: :func:`force_covariance` linearises its effect on the (pinned) estimate from the noise of one
grid point of the stroke-averaged force (``force_noise_N`` of :class:`calibration.design.noise.NoiseLevel`), the
calibration's smoothing of the force and the model torque per N (calibration/design/report.py ``run_force_noise``).
The criterion below leaves it out (it moves the intervals, not which runs inform most).

The logged force's stated accuracy (its scale and offset, [calibration.process_force] logged_scale_accuracy and
logged_offset_accuracy) is no noise: one error of the channel, the same in every run's log, which `calibrate` does not
estimate but carries into its intervals by what a refit with the force a step off moves the estimate
(calibration/identification/force_accuracy.py). The prediction carries it the same way (:func:`carried_covariance`:
the pinned least-squares move per step, :func:`force_move`, made a standard deviation by `calibrate`'s own rule,
:func:`per_standard_deviation`), and so does the search's criterion: without it the design chose runs whose force
set mu_s no better than the force's scale does (on an edited crank-slider both calibrations reached mu_s's whole range).

D-optimal design maximises log det F (columns scaled by each parameter's calibration range and by 1 ms and 0.1 deg,
which shifts log det by a constant only): the smallest joint confidence region of parameters and nuisance effects.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from press_model.batch import DEFAULT_CHUNK, BatchModel, evaluate_chunk, features, motor_torque_eq16
from calibration.identification.adequacy import shift_columns
from calibration.identification.force_accuracy import accuracy_sd
from calibration.identification.peak import _window_points, filter_curve
from calibration.identification.process_force import FORCE_STEP
from calibration.identification.problem import CalibrationProblem, peak_points
from calibration.identification.uncertainty import central_difference, central_sets

NUISANCE = ("channel_delay_s", "angle_offset_deg")
NUISANCE_UNIT = (1e-3, math.radians(0.1))  # s, rad: the columns' scale (conditioning only; log det moves by a constant)
NUISANCE_REPORT = (1.0, math.radians(1.0))  # SI per reported unit: delay in s, offset in deg (rad per deg)


def nuisance_columns(theta: np.ndarray, theta_dot: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """(n, 2): what the measured curve gains per second of torque-channel delay (-omega dT/dtheta, N m / s) and per
    radian of encoder offset (-dT/dtheta, N m / rad) at the model curve ``torque`` on the uniform periodic grid ``theta``."""
    return np.column_stack(shift_columns(theta, theta_dot, torque))


@dataclass(frozen=True)
class RunColumns:
    """The scaled regression columns of one run at one parameter set: J (n, k) N m per calibration range, Z (n, 2) N m per
    1 ms and per 0.1 deg, and the model curve (n,) N m per motor."""

    J: np.ndarray
    Z: np.ndarray
    torque: np.ndarray

    def information(self, variance_Nm2: float, nuisance: bool = True, fitted: np.ndarray | None = None) -> np.ndarray:
        """(k + 2, k + 2) information of this run on the parameters and the nuisance effects; (k, k) on the parameters
        alone when ``nuisance`` is off (a calibration that does not estimate them). ``fitted`` (bool, n): the grid
        points the fit compares (:func:`fitted_points`; default all)."""
        A = np.hstack([self.J, self.Z]) if nuisance else self.J
        if fitted is not None:
            A = A[np.asarray(fitted, bool)]
        return A.T @ A / variance_Nm2


def contact_angle(theta: np.ndarray, height: np.ndarray, height_dot: np.ndarray, contact_height_m: float) -> float | None:
    """The crank angle (rad) where the slide passes ``contact_height_m`` on its way down, linearly between the grid
    points ``theta`` of its height (m above BDC) and vertical speed's sign; None when it never does. The grid's own
    reading of :func:`press_model.kinematics.force_step_angles`' die contact (a root search per run would cost 0.1 s)."""
    h = np.asarray(height, float) - contact_height_m
    n = len(theta)
    for i in range(n):
        j = (i + 1) % n
        if h[i] > 0.0 >= h[j] and height_dot[i] <= 0.0 and height_dot[j] <= 0.0:
            step = (theta[j] - theta[i]) % (2.0 * math.pi)
            return float((theta[i] + step * h[i] / (h[i] - h[j])) % (2.0 * math.pi))
    return None


def fitted_points(theta: np.ndarray, motion, contact: float | None, window_s: float) -> np.ndarray:
    """(bool, n) the grid points ``calibrate`` compares in Eq. 28 (Y_RMSE and the peaks): those farther than
    ``window_s`` after die contact at the crank angle ``contact`` (rad; None: no contact, every point) of a run
    with crank ``motion`` (:func:`calibration.identification.problem.peak_points`). The ringing there is no
    information: the fit leaves those points out, and so must the information it is predicted from."""
    return peak_points(theta, motion.time, [] if contact is None else [contact], window_s)


def run_columns(bm: BatchModel, problem: CalibrationProblem, x: np.ndarray) -> RunColumns:
    """The columns of one run (its batch model ``bm``) at the calibrated parameters' values ``x`` (SI, problem order)."""
    return draw_columns(bm, draw_sets(bm, problem, np.asarray(x, float)[None]))[0]


@dataclass(frozen=True, eq=False)
class DrawSets:
    """The parameter sets :func:`draw_columns` evaluates for draws (D, k) of the calibrated parameters: per draw the draw
    itself and the 2 k central-difference sets of its Jacobian, as full parameter sets with their batch features.

    The features (masses, first and second moments of each body) depend on the press and the sets only, not on the run's
    motion or cushion, so the sets of a design search are made once and serve every candidate run of the press.

    ``kernel_row`` maps each set to the first set with the same friction kernel inputs (its friction coefficients and
    features): a set that differs only in what Eq. 16 alone reads (the gear's efficiency and inertia) has the crank
    torque of that set, so the kernel runs once per distinct row (36 of the reference press's 52 sets)."""

    problem: CalibrationProblem
    X: np.ndarray  # (D (2 k + 1), all parameters), SI
    feats: tuple[np.ndarray, np.ndarray]  # batch.features of X
    steps: np.ndarray  # (k,) central-difference steps, SI
    bodies: tuple  # the batch model's bodies the features were computed for
    kernel_row: np.ndarray  # (D (2 k + 1),) int: the first set with the same kernel inputs

    @property
    def draws(self) -> int:
        return len(self.X) // (2 * len(self.steps) + 1)

    @property
    def draw_rows(self) -> np.ndarray:
        """The rows of X that are the draws themselves (D,)."""
        return np.arange(self.draws) * (2 * len(self.steps) + 1)


def draw_sets(bm: BatchModel, problem: CalibrationProblem, draws: np.ndarray) -> DrawSets:
    """The :class:`DrawSets` of ``draws`` (D, k) (SI, problem order) on the press of ``bm``."""
    span = problem.high - problem.low
    X, feats, ok, steps = [], [], [], None
    for x in np.atleast_2d(np.asarray(draws, float)):
        P, steps = central_sets(span, x)
        for sets in (x[None], P):  # grouped as two batch calls would group them: the features are those calls' to the bit
            Xs = problem.full_sets(bm, sets)
            f, o = features(bm, Xs)
            X.append(Xs), feats.append(f), ok.append(o)
    X, feats, ok = np.vstack(X), np.vstack(feats), np.concatenate(ok)
    # the kernel's inputs per set (evaluate_chunk: the friction coefficients and the features), compared bit for bit
    inputs = np.column_stack([bm.c_r.take(X), bm.c_s.take(X), bm.mu_r.take(X), bm.mu_s.take(X), feats, ok])
    first: dict[bytes, int] = {}
    kernel_row = np.array([first.setdefault(row.tobytes(), i) for i, row in enumerate(inputs)])
    return DrawSets(problem, X, (feats, ok), steps, bm.bodies, kernel_row)


def draw_cranks(bm: BatchModel, sets: DrawSets, rows: np.ndarray, known: dict | None = None) -> np.ndarray:
    """(len(rows), n) N m: the crank torque (the friction kernel's output) of the sets ``rows`` of ``sets`` on the run
    ``bm``, the kernel run once per distinct :attr:`DrawSets.kernel_row` not in ``known`` (kernel row -> its crank
    torque, which this fills in). Each set's curve is the one it has alone: the kernel's lanes do not mix."""
    if sets.bodies is not bm.bodies:
        raise ValueError("draw_cranks: the sets' features belong to another press's batch model")
    known = {} if known is None else known
    todo = [int(r) for r in dict.fromkeys(sets.kernel_row[rows]) if int(r) not in known]
    fe, ok = sets.feats
    for a in range(0, len(todo), DEFAULT_CHUNK):
        r = np.array(todo[a:a + DEFAULT_CHUNK])
        crank = evaluate_chunk(bm, sets.X[r], feats=(fe[r], ok[r]), offset=int(r[0])).crank_torque
        known.update(zip(r.tolist(), crank))
    return np.array([known[int(r)] for r in sets.kernel_row[rows]]).reshape(len(rows), bm.n_points)


def draw_columns(bm: BatchModel, sets: DrawSets, known: dict | None = None) -> list[RunColumns]:
    """The columns of one run (its batch model ``bm``) at each draw of ``sets``: every draw's curve and Jacobian sets
    (:func:`draw_cranks`, ``known`` its crank torques already computed, e.g. the draws' by :func:`draw_curves`), then
    Eq. 16 for every set."""
    rows = np.arange(len(sets.X))
    T = motor_torque_eq16(bm, sets.X, draw_cranks(bm, sets, rows, known))
    span = sets.problem.high - sets.problem.low
    per = 2 * len(sets.steps) + 1
    out = []
    for d in range(sets.draws):
        Td = T[d * per:(d + 1) * per]
        curve = Td[0].copy()  # not a view: a search keeps thousands of these, and a view would keep all of T alive
        J = central_difference(Td[1:], sets.steps) * span
        Z = nuisance_columns(bm.theta, bm.theta_dot, curve) * np.array(NUISANCE_UNIT)
        out.append(RunColumns(J, Z, curve))
    return out


def draw_curves(bm: BatchModel, sets: DrawSets, known: dict | None = None) -> np.ndarray:
    """(D, n) N m per motor: the model curve of each draw of ``sets`` on the run ``bm`` (the draws alone, without their
    Jacobian sets; e.g. the run with its process force a step higher). ``known``: as :func:`draw_cranks`'s (filled in)."""
    rows = sets.draw_rows
    return motor_torque_eq16(bm, sets.X[rows], draw_cranks(bm, sets, rows, known))


def filter_gain(theta: np.ndarray, steps, i: int, window_deg: float, order: int) -> float:
    """sqrt(sum c_j^2) of the job's peak filter (Savitzky-Golay of ``window_deg`` and ``order``, [calibration]
    peak_filter_window_deg and peak_filter_order) at grid point ``i``: the coefficients c_j the filtered value at i
    gives each point j, the filter applied piecewise between the force-step angles ``steps`` (rad) as
    :func:`calibration.identification.peak.filter_curve` does, so a point near a step gets its piece's edge
    coefficients (larger than the centre's)."""
    n = len(theta)
    win = _window_points(window_deg, math.degrees(theta[1] - theta[0]), order)
    c = []
    for j in range(i - win, i + win + 1):  # a point's filtered value depends on at most a window either side
        e = np.zeros(n)
        e[j % n] = 1.0
        c.append(filter_curve(theta, e, steps, window_deg, order)[i])
    return float(np.sqrt(np.sum(np.square(c))))


def filter_gain_key(theta: np.ndarray, steps, i: int, window_deg: float, order: int) -> tuple:
    """What :func:`filter_gain` at grid point ``i`` depends on: the filter of a piece (between the force steps ``steps``,
    rad, cut as :func:`calibration.identification.peak.filter_curve` cuts) gives a point its coefficients by its place
    in the piece alone: ("start", r) within half a window of its start, ("end", r) of its end, "centre" between, or
    "unfiltered" in a piece shorter than the window. Equal keys, equal gains: a search's memo (calibration/design/runs.py)."""
    n = len(theta)
    win = _window_points(window_deg, math.degrees(theta[1] - theta[0]), order)
    cuts = sorted({int(np.searchsorted(theta, a % (2.0 * math.pi))) % n for a in steps})
    if not cuts:
        return ("centre",)
    c = max((k for k in cuts if k <= i), default=cuts[-1])  # the piece's first point: the last cut at or before i
    length = (cuts[(cuts.index(c) + 1) % len(cuts)] - c) % n or n
    r = (i - c) % n
    if length < win:
        return ("unfiltered",)
    if r < win // 2:
        return ("start", r)
    if length - 1 - r < win // 2:
        return ("end", length - 1 - r)
    return ("centre",)


def log_det(F: np.ndarray) -> float:
    """log det F (the D criterion); -inf when F is singular."""
    sign, val = np.linalg.slogdet(F)
    return float(val) if sign > 0 else -math.inf


@dataclass(frozen=True)
class Prediction:
    """Predicted intervals of a design: standard errors and 95 % half-widths (SI units), correlations."""

    names: tuple[str, ...]
    std: np.ndarray  # (k,) SI units
    half_width: np.ndarray  # (k,) SI units, the level's t-quantile x std
    correlation: np.ndarray  # (k, k) of the parameters
    half_width_given_nuisance: np.ndarray  # (k,) SI: with delay and offset known (the parameter block of F alone)
    nuisance_std: np.ndarray  # (2,) s, deg (NaN without nuisance)
    nuisance_correlation: float  # delay vs offset
    log_det: float
    level: float
    dof: int
    span: np.ndarray  # (k,) calibration ranges, SI

    def width_of_range(self) -> np.ndarray:
        """Interval width (2 x half-width) as a share of each calibration range."""
        return 2.0 * self.half_width / self.span

    def max_abs_correlation(self) -> tuple[float, str, str]:
        """The largest |correlation| between two parameters and their names."""
        k = len(self.names)
        if k < 2:
            return 0.0, "", ""
        c = np.abs(self.correlation - np.eye(k))
        i, j = np.unravel_index(int(np.argmax(c)), c.shape)
        return float(c[i, j]), self.names[i], self.names[j]

    def record(self) -> dict:
        """The ``{"half_widths", "correlation", ...}`` entry of prediction.json (SI units; offset in deg)."""
        c, a, b = self.max_abs_correlation()
        return {
            "half_widths": {n: float(h) for n, h in zip(self.names, self.half_width)},
            "standard_errors": {n: float(s) for n, s in zip(self.names, self.std)},
            "half_widths_given_nuisance": {n: float(h) for n, h in zip(self.names, self.half_width_given_nuisance)},
            "width_share_of_range": {n: float(w) for n, w in zip(self.names, self.width_of_range())},
            "correlation": {"names": list(self.names), "matrix": np.round(self.correlation, 6).tolist()},
            "max_abs_correlation": {"value": c, "pair": [a, b]},
            "nuisance_standard_errors": {n: (None if not np.isfinite(s) else float(s)) for n, s in zip(NUISANCE, self.nuisance_std)},
            "nuisance_correlation": None if not np.isfinite(self.nuisance_correlation) else self.nuisance_correlation,
            "log_det_information": self.log_det,
            "level": self.level,
            "degrees_of_freedom": self.dof,
        }


@dataclass(frozen=True)
class PeakPin:
    """Eq. 28's peak term as the estimator sees it: the model's peak is pinned to the measured (filtered) peak. ``row``
    (m,) is what the model's peak gains per unit of each scaled column of :class:`RunColumns` ([J Z] at the peak
    point), ``sigma_Nm`` the noise left in the measured peak (N m). Stacks (..., m) and (...) pin a stack of estimates."""

    row: np.ndarray
    sigma_Nm: float | np.ndarray


def pinned_covariance(cov: np.ndarray, pin: PeakPin) -> np.ndarray:
    """The covariance (scaled) of the estimate that minimises the squared residual with the model's peak held at the
    measured peak, from the least-squares covariance ``cov`` = F^-1: linearised, the estimate is the least-squares one
    moved along g = cov a until a^T x meets the measured peak, so that

        cov_pinned = cov - (1 - sigma_p^2 / v) g g^T / v,   v = a^T cov a,

    the least-squares variance along a replaced by the measured peak's sigma_p^2 (the peak's noise and the least-squares
    estimate's, from many more points, taken as independent). When the measured peak is noisier than the least-squares
    estimate of the peak (sigma_p^2 > v), pinning to it widens the intervals of the parameters the peak moves."""
    a = np.asarray(pin.row, float)
    g = (cov @ a[..., None])[..., 0]
    v = np.einsum("...i,...i->...", a, g)
    vs = np.where(v > 0.0, v, 1.0)
    f = np.where(v > 0.0, (1.0 - np.square(pin.sigma_Nm) / vs) / vs, 0.0)  # no pin where the peak moves with nothing
    return cov - f[..., None, None] * g[..., :, None] * g[..., None, :]


@dataclass(frozen=True)
class ForceNoise:
    """An error of the logged process force as the estimate sees it, over the runs together: ``E`` (m, W) what the
    least-squares normal equations gain per unit of the error's coordinates w (W of them: the noise's standard normals,
    or the stated accuracy's steps of scale and offset, :class:`ForceAccuracy`), sum over the runs of [J Z]^T
    diag(torque per N) L_F / (s^2 c) on the fitted points (:func:`force_noise_terms`), and ``peak`` (W,) what the
    pinned run's model peak gains per unit of w (0 without a pin or a force at the peak)."""

    E: np.ndarray
    peak: np.ndarray


def per_standard_deviation(effect: ForceNoise, st) -> ForceNoise:
    """The logged force's stated accuracy as the estimate sees it: ``effect`` (:class:`ForceNoise` of two columns, per
    :data:`FORCE_STEP` of the force's scale and per FORCE_STEP of each run's peak force as an offset where the force is
    on; one channel, so one error common to every run's log; stacks (..., m, 2) too) made per standard deviation of
    each error by the rule `calibrate` widens with (:func:`calibration.identification.force_accuracy.accuracy_sd`,
    ``st``: [calibration.process_force], 95 % bounds). A nuisance `calibrate` does not estimate but carries with its
    prior; so does the prediction (:func:`carried_covariance`)."""
    E, peak = np.asarray(effect.E, float), np.asarray(effect.peak, float)
    return ForceNoise(accuracy_sd(E[..., 0], E[..., 1], st).reshape(E.shape),
                      accuracy_sd(peak[..., 0], peak[..., 1], st).reshape(peak.shape))


def torque_per_newton(torque: np.ndarray, torque_more: np.ndarray, curve: np.ndarray, step: float) -> np.ndarray:
    """(n,) N m / N: what the model torque gains per N of process force at each grid point, from the model curve
    ``torque`` with the force ``curve`` (n,) N and ``torque_more`` with it the share ``step`` higher; 0 where unloaded."""
    curve = np.asarray(curve, float)
    loaded = curve != 0.0
    return np.where(loaded, (np.asarray(torque_more) - np.asarray(torque)) / np.where(loaded, step * curve, 1.0), 0.0)


def accuracy_factor(curve: np.ndarray) -> np.ndarray:
    """(n, 2) N: the logged force's change per :data:`FORCE_STEP` of its scale (FORCE_STEP x the ``curve``, N) and per
    FORCE_STEP of its peak as an offset where it is on, as `calibrate` probes them
    (calibration/identification/force_accuracy.py ``shifted``)."""
    curve = np.asarray(curve, float)
    peak = float(np.max(np.abs(curve))) if curve.size else 0.0
    return FORCE_STEP * np.column_stack([curve, np.where(curve != 0.0, peak, 0.0)])


def carried_covariance(F: np.ndarray, k: int, pin: PeakPin | None = None, accuracy: ForceNoise | None = None) -> np.ndarray:
    """(..., m, m) scaled: the covariance of Eq. 28's estimate from the information ``F`` (..., m, m; pseudo-inverted):
    the least-squares one, its model peak pinned by ``pin`` (:func:`pinned_covariance`), plus what the logged force's
    stated accuracy adds to the k parameters (``accuracy``: :func:`per_standard_deviation`'s, stacks alike), the estimate
    moved as `calibrate`'s refit with the force off moves it: the recording's delay and offset held (the k-block of F),
    its peak pinned (:func:`force_move`), the errors independent. What a prediction reports and the search's criterion
    weighs (calibration/design/runs.py)."""
    cov = np.linalg.pinv(F, hermitian=True)
    out = cov if pin is None else pinned_covariance(cov, PeakPin(np.asarray(pin.row)[..., :F.shape[-1]], pin.sigma_Nm))
    if accuracy is None:
        return out
    cov_k = np.linalg.pinv(F[..., :k, :k], hermitian=True)
    K = force_move(cov_k, accuracy, None if pin is None else PeakPin(np.asarray(pin.row)[..., :k], pin.sigma_Nm))
    out = out.copy()
    out[..., :k, :k] += K @ np.swapaxes(K, -1, -2)
    return out


def force_noise_terms(cols: RunColumns, fitted: np.ndarray, variance_Nm2: float, torque_per_N: np.ndarray,
                      factor: np.ndarray, nuisance: bool = True) -> np.ndarray:
    """(m, W) one run's share of :attr:`ForceNoise.E`: its scaled columns [J Z] (J alone without ``nuisance``) on the
    ``fitted`` points, times the model torque per N of force (n,) N m / N, times the force curve's noise ``factor`` (n, W)
    N per unit standard normal, over the run's noise variance s^2 c (N^2 m^2)."""
    A = np.hstack([cols.J, cols.Z]) if nuisance else cols.J
    A = A * np.asarray(fitted, bool)[:, None]
    return A.T @ (np.asarray(torque_per_N, float)[:, None] * factor) / variance_Nm2


def force_covariance(cov: np.ndarray, force: ForceNoise, pin: PeakPin | None) -> np.ndarray:
    """(m, m) scaled: the covariance the logged force's noise adds to the estimate of least-squares covariance ``cov``
    (= F^-1), linearised: K K^T with K of :func:`force_move`."""
    K = force_move(cov, force, pin)
    return K @ K.T


def force_move(cov: np.ndarray, force: ForceNoise, pin: PeakPin | None) -> np.ndarray:
    """(m, W) scaled: K, the estimate of least-squares covariance ``cov`` (= F^-1) moves by -K w when the logged force
    carries the error of coordinates w (``force``), linearised. The model fitted with the force F + e fits the log as the
    model with F fits it less G e, so the least-squares estimate moves by -cov E w; with the model's peak pinned to the
    measured peak (:func:`pinned_covariance`) that move is projected off the peak's gradient a and the model peak's own
    force error moves the estimate along g = cov a: K = (I - g a^T / v) cov E + g peak^T / v, v = a^T g."""
    m = cov.shape[-1]
    K = cov @ np.asarray(force.E, float)[..., :m, :]
    if pin is None:
        return K
    a = np.asarray(pin.row, float)[..., :m]
    g = (cov @ a[..., None])[..., 0]
    v = np.einsum("...i,...i->...", a, g)
    aK = np.einsum("...i,...iw->...w", a, K)
    step = g[..., :, None] * (aK - np.asarray(force.peak, float))[..., None, :] / np.where(v > 0.0, v, 1.0)[..., None, None]
    return np.where((v > 0.0)[..., None, None], K - step, K)


def predict(F: np.ndarray, problem: CalibrationProblem, points: int, level: float, pin: PeakPin | None = None,
            force: ForceNoise | None = None, accuracy: ForceNoise | None = None) -> Prediction:
    """Intervals from the information ``F`` (scaled, see :func:`run_columns`; with or without the nuisance block) of
    ``points`` grid values in all; with ``pin``, of the estimate whose model peak is pinned to the measured one
    (:func:`pinned_covariance`: Eq. 28, whose peak term `calibrate` meets exactly when that is where its minimum lies);
    with ``force``, plus the logged process force's noise (:func:`force_covariance`); with ``accuracy``, plus its
    stated scale and offset accuracy (:func:`per_standard_deviation`; :func:`carried_covariance`), as `calibrate`'s
    intervals carry it."""
    k = len(problem.names)
    nuisance = F.shape[0] > k
    Fu = F
    span = problem.high - problem.low
    cov = carried_covariance(Fu, k, pin, accuracy)
    if force is not None:
        cov = cov + force_covariance(np.linalg.pinv(Fu), force, pin)
    sd_scaled = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr_all = cov / np.outer(sd_scaled, sd_scaled)
    corr_all = np.where(np.isfinite(corr_all), corr_all, 0.0)
    np.fill_diagonal(corr_all, 1.0)
    dof = max(points - Fu.shape[0], 1)
    q = float(stats.t.ppf(0.5 + level / 2.0, dof))
    std = sd_scaled[:k] * span
    if nuisance:
        nstd = sd_scaled[k:] * np.array(NUISANCE_UNIT) / np.array(NUISANCE_REPORT)
        ncorr = float(corr_all[k, k + 1])
        pin_k = None if pin is None else PeakPin(pin.row[:k], pin.sigma_Nm)
        cov_given = carried_covariance(F[:k, :k], k, pin_k, accuracy)
        if force is not None:
            cov_given = cov_given + force_covariance(np.linalg.pinv(F[:k, :k]), force, pin_k)
        given = np.sqrt(np.clip(np.diag(cov_given), 0.0, None)) * span * q
    else:
        nstd, ncorr, given = np.full(2, np.nan), math.nan, q * std
    return Prediction(problem.names, std, q * std, corr_all[:k, :k], given, nstd, ncorr, log_det(Fu), level, dof, span)
