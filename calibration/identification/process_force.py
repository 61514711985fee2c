"""The process force of a calibration: the logged force put into the model in place of the job's nominal curve, or,
when the log has none, what an error of the job's force does to the estimate.

**Logged** (column ``process_force_N`` of a drive log, or the role of that name in a channel map): the force each turn
logged on the crank grid (:attr:`calibration.traces.drive_log.DriveLog.stroke_force`) finds the steps, the bin means of
every sample (:attr:`calibration.traces.drive_log.DriveLog.force_binned`, all turns) are the values, then
smoothed by a Savitzky-Golay filter applied piecewise between the force's own steps (the grid points where it jumps by
more than ``step_fraction`` of its peak: a filter across die contact would smear the step the rigid model needs); a
piece where the job has no force and the log's mean there is within ``unloaded_standard_errors`` of zero is taken as
zero (the sensor's noise on an unloaded slide); a grid point whose bin straddles a step takes the side its own angle
lies on (:func:`snap_transitions`). Its
timing is checked against the job's: the angle where the logged force first reaches half its peak must lie within
``contact_limit_deg`` of the angle where the job's curve does (a warning beyond ``contact_warning_deg``); a force of the
other sign than the job's is refused. The model is then built on :class:`LoggedProcess`, the smoothed curve as a
function of the slide's height and direction (Eq. 14's arguments), which gives that curve at each grid point. The
curve is linear in the bin means, and :attr:`LoggedForce.noise_factor` is that map times the bin means' standard
errors from the log's turns: the noise the model takes with the force, which
:mod:`calibration.identification.force_noise` carries into the intervals.

**Not logged**: on a cushion test the force scale and eta_gear move the torque almost alike (Jacobian correlation
+0.997 on the reference press's cushion test), so the log cannot estimate the force as a nuisance beside eta_gear; the
calibration says instead how far a 1 % error of the job's force moves each parameter (Eq. 28 refitted locally with the
force 1 % higher) and the peak torque of the calibrated model (:func:`force_sensitivity`), and the correlation that
decides it (:class:`ForceSensitivity`); the force accuracy the job states ([calibration.process_force]
job_force_tolerance) is carried into the intervals through that sensitivity (calibration/identification/run.py). Two
more things follow from it:

* a score test of the force scale beside the other suspects (:func:`force_candidate`: the torque the model gains per
  unit of relative force scale, as one more column of :mod:`calibration.identification.adequacy`), which names a force
  error the parameters could not absorb (on a cushion test they absorb most of it: of 12 SYNTHETIC runs with the force
  4 % off, the test named 7 at its Bonferroni share of the adequacy level, scripts/check_force_scale.py);
* what the test cannot see, the rule covers: when the job's tolerance moves eta_gear or psi by more than
  ``warning_shift`` (:func:`force_warning`), one warning says so (the missing column, the move of each, the peak torque
  a plan made from these values may lack), instead of a note.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.signal import savgol_filter

from press_model.batch import with_process
from press_model.disk_cache import array_digest
from press_io.errors import PressDataError
from press_model.forces import ProcessForce
from press_model.settings_fields import setting

from calibration.identification.adequacy import Candidate
from calibration.identification.bootstrap import refit_batch
from calibration.identification.force_noise import binned_standard_errors, spread_of_mean
from calibration.identification.joint import joint_objective
from calibration.identification.uncertainty import jacobian

FORCE_STEP = 0.01  # the force error the sensitivity is stated for: 1 % (a linear response, stated per percent)
# The logged force against the job's, before it replaces the job's curve. A servo die cushion holds its set force to ~2 %
# and a part's forming force spreads by some 10 %: a peak 3 times the job's or a third of it is no such spread but
# another unit (kN: 1/1000, lbf: 4.45) or channel scale, or a log of another job, refused with the ratio named;
FORCE_SCALE_LIMIT = 3.0
# a least-squares ratio off 1 by more than 10 % (3 job_force_tolerance of the cushion test) is warned about: the model
# takes the logged force, so a channel scaled wrong moves every parameter, and the warning names the ratio;
FORCE_SCALE_WARNING = 0.10
# where the job has no force (the slide off the die) a force channel reads its noise around zero: a mean there above a
# quarter of the logged peak is an offset, a constant or another signal, not the force on the slide (refused);
FORCE_UNLOADED_LIMIT = 0.25
# a force channel reads to ~0.5 % of its peak per sample (a cushion's pressure signal; a tonnage monitor ~1 %): noise
# above 10 % of the peak is a channel fault (interference, a range too wide for the signal), warned about by name
FORCE_NOISE_WARNING = 0.10
FORCE_WARNING = "PROCESS FORCE NOT LOGGED"  # how the warning of :func:`force_warning` starts (the console marks it WARNING)
WARNED_PARAMETERS = ("eta_gear", "psi")  # the parameters whose move by the force tolerance decides the warning


@dataclass(frozen=True)
class ProcessForceSection:
    """[calibration.process_force]: a logged process force (column process_force_N) in place of the job's, and the
    job's force tolerance when the log has none (module docstring)."""

    filter_window_deg: float = setting(15.0, "deg", "Savitzky-Golay window of the stroke-mean force between its steps: "
                                       "its noise enters the model torque as a smooth misfit; 15 points of order 2 keep 0.39 of "
                                       "the bin means' noise", gt=0.0,
                                       lt=180.0, unit="deg")
    filter_order: int = setting(2, "", "quadratic local fit: keeps the curvature of a forming force's rise", ge=0)
    step_fraction: float = setting(0.2, "of the peak force", "a jump between neighbouring grid points larger than this is a "
                                   "force step (die contact, release), where the filter is cut", gt=0.0, lt=1.0)
    contact_warning_deg: float = setting(2.0, "deg", "the logged force rising farther than this from the job's die contact "
                                         "is named in a warning (two grid steps)", ge=0.0, lt=180.0, unit="deg")
    contact_limit_deg: float = setting(10.0, "deg", "farther than this the force channel belongs to another run or die "
                                       "height: refused", gt=0.0, lt=180.0, unit="deg")
    unloaded_standard_errors: float = setting(3.0, "standard errors", "a stretch where the job has no force and the log's "
                                              "mean force is within this many standard errors of zero is zero (sensor "
                                              "noise); beyond, the log's force stays", ge=0.0, unit="standard errors")
    job_force_tolerance: float = setting(0.03, "fraction of the force", "a log without the force column: how well the job's "
                                         "force is known (a 95 % bound), carried into the intervals by what it moves the "
                                         "estimate: a servo die cushion holds its set force to about 2 % against its own "
                                         "pressure or current signal, and the force on the slide differs from that by what "
                                         "the control does not see (piston area and back pressure, seal and guide friction, "
                                         "about 1 % more); 0 takes the job's force as exact (the paper's assumption)",
                                         ge=0.0, lt=0.5)
    warning_shift: float = setting(0.02, "fraction of the estimate", "a warning when the job's force tolerance (a log "
                                   "without the force column) or the logged force's accuracy (a log with it) moves eta_gear "
                                   "or psi by more than this: 2 % of eta_gear is 2 % of every driving torque the plan "
                                   "predicts, a fifth of the 10 % torque margin", gt=0.0, lt=1.0)
    logged_scale_accuracy: float = setting(0.015, "fraction of the force", "a log with the force column: how well the "
                                           "force channel's scale is known (a 95 % bound), carried into the intervals by what "
                                           "it moves the estimate: a servo cushion's force is its cylinder pressure times "
                                           "the piston area, the pressure transducer of accuracy class 0.5 (0.5 % of span, "
                                           "IEC 60770) read at about half its span gives 1 %, the piston area and the seals' "
                                           "drag 0.5 % more; a tonnage monitor calibrated against load cells on the press "
                                           "reads to about 1 % of its capacity; 0 takes the channel's scale as exact",
                                           ge=0.0, lt=0.5)
    logged_offset_accuracy: float = setting(0.005, "fraction of the logged peak force", "a log with the force column: "
                                            "how well its zero is known (a 95 % bound) where the force is on: a transducer's "
                                            "zero error within its class, 0.5 % of a span about the force's peak; 0: exact",
                                            ge=0.0, lt=0.5)


@dataclass(frozen=True)
class LoggedProcess:
    """A process force given on the crank grid, as the model's process force: ``__call__(height, height_dot)`` -> N (up).

    ``down_*`` / ``up_*``: the force against the slide height (m, rising) on the downstroke (height_dot <= 0) and the
    upstroke; between grid points linear in height. ``contact_height``, ``heights``, ``forces`` and ``source`` are the
    job's, for the model's checks of the job; the peak window and the bootstrap's step guard take the logged force's
    own steps (:attr:`LoggedForce.steps`)."""

    down_h: np.ndarray
    down_f: np.ndarray
    up_h: np.ndarray
    up_f: np.ndarray
    contact_height: float
    heights: tuple
    forces: tuple
    source: str

    def cache_key(self) -> dict:
        """What the model built on this force depends on, for the disk cache of
        :func:`press_model.batch.build_batch_model`: its curves and the job's figures (``source`` left out: a file's
        name changes no force, and the same log read from another folder builds the same model)."""
        return {"down_h": array_digest(self.down_h), "down_f": array_digest(self.down_f), "up_h": array_digest(self.up_h),
                "up_f": array_digest(self.up_f), "contact_height": self.contact_height, "heights": list(self.heights),
                "forces": list(self.forces)}

    def __call__(self, height, height_dot):
        h = np.asarray(height, dtype=float)
        down = np.interp(h, self.down_h, self.down_f) if self.down_h.size else np.zeros_like(h)
        up = np.interp(h, self.up_h, self.up_f) if self.up_h.size else np.zeros_like(h)
        return np.where(np.asarray(height_dot) <= 0.0, down, up)


@dataclass(frozen=True)
class LoggedForce:
    """The logged process force of one log on its grid: ``curve`` (n,) N the smoothed stroke mean the model uses,
    ``mean`` (n,) N the plain stroke mean, ``noise_N`` the RMS stroke-to-stroke scatter of the mean (N), ``strokes``
    the complete strokes averaged (every crank angle covered at least this often, as the log's own count), ``scale``
    the least-squares factor logged ~ scale x the job's curve (NaN for a job without a force), ``rise_deg`` /
    ``job_rise_deg`` where each first reaches half its peak, ``process`` the model's force."""

    curve: np.ndarray
    mean: np.ndarray
    noise_N: float
    strokes: int
    scale: float
    rise_deg: float
    job_rise_deg: float
    process: LoggedProcess
    warnings: tuple[str, ...] = ()
    steps: tuple[float, ...] = ()  # rad: where the logged force steps, each half a grid step before its first point; die contact first
    # (n, n) N: the curve's noise as noise_factor @ w, w standard normal (n,): the smoothing, snapping and zeroing above
    # as a matrix on the bin means, times each bin mean's standard error from the log (:func:`calibration.identification.
    # force_noise.binned_standard_errors`); None when not estimated
    noise_factor: np.ndarray | None = None
    binned_noise_N: float = math.nan  # N: RMS standard error of the bin means the curve is made of, over the points it keeps loaded
    sample_noise_N: float = math.nan  # N: the force channel's noise per sample (pooled stroke-to-stroke scatter of the bin means)

    def record(self) -> dict:
        """calibrated.json's account of the logged force (N, deg)."""
        return {"source": "logged (process_force_N)", "strokes_averaged": self.strokes, "peak_N": float(np.max(np.abs(self.curve))),
                "noise_of_mean_N": self.noise_N, "scale_to_job": self.scale, "rise_deg": self.rise_deg,
                "job_rise_deg": self.job_rise_deg, "warnings": list(self.warnings),
                "noise_of_sample_N": _finite_or_none(self.sample_noise_N),
                "noise_of_binned_point_N": _finite_or_none(self.binned_noise_N),
                "noise_what": "the force channel's noise from the log itself: each turn's bin means of process_force_N scatter "
                              "from turn to turn (pooled over each piece between the force's steps); noise_of_sample_N per sample, "
                              "noise_of_binned_point_N the RMS standard error of one grid point of the stroke-averaged bin means over "
                              "the loaded points (what design-experiment --calibrated takes)"}


def _finite_or_none(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


@dataclass(frozen=True)
class ForceSensitivity:
    """What a 1 % error of the job's process force does to a calibration whose log has no force column.

    ``shift`` (k,) SI: the error of each parameter's estimate when the true force is 1 % *above* the job's (minus the
    move of Eq. 28's local refit with the model's force 1 % higher); ``correlation`` of the force scale with each
    parameter in the Jacobian (the force as one more column); ``multiple_correlation``: the force column's with all the
    parameters' columns together (sqrt(1 - 1/VIF)): a force error the parameters can absorb jointly is not separable
    however small each pairwise correlation; ``peak_shift_of_tmax``: how much more peak torque the
    true press needs than the calibrated model predicts on the log's cycle when the true force is 1 % *below* the
    job's, as a fraction of T_max (what a plan made from these values loses of its torque margin per percent the job
    overstates the force; negative: it gains)."""

    names: tuple[str, ...]
    shift: np.ndarray
    relative_shift: np.ndarray
    correlation: np.ndarray
    peak_shift_of_tmax: float
    separable: bool
    correlation_limit: float
    multiple_correlation: float = float("nan")

    def line(self) -> str:
        """One console line."""
        i = self.names.index("eta_gear") if "eta_gear" in self.names else int(np.argmax(np.abs(self.correlation)))
        top = self.names[int(np.argmax(np.abs(self.correlation)))]
        told = ("cannot be told apart from the parameters (multiple correlation "
                f"{self.multiple_correlation:.3f}; largest single one {self.correlation[self.names.index(top)]:+.3f}, with {top})"
                if not self.separable else f"could be told apart from the parameters (largest correlation "
                f"{self.correlation[self.names.index(top)]:+.3f}, with {top})")
        return (f"process force: the job's nominal curve (the log has no process_force_N column); on this log its scale {told}: "
                f"a true force 1 % above the job's moves {self.names[i]} by {100.0 * self.relative_shift[i]:+.2f} % (and "
                f"{', '.join(f'{n} {100.0 * r:+.1f} %' for n, r in zip(self.names, self.relative_shift) if n != self.names[i])}); "
                f"a true force 1 % below the job's makes the press need {100.0 * self.peak_shift_of_tmax:+.2f} % of T_max more peak "
                "torque than these values predict (out of a plan's torque margin). Log the cushion's force (process_force_N) to "
                "take this out")

    def record(self) -> dict:
        return {"source": "job (nominal curve, not logged)", "force_error_for": "a true force 1 % above the job's",
                "shift": dict(zip(self.names, map(float, self.shift))),
                "relative_shift": dict(zip(self.names, map(float, self.relative_shift))),
                "correlation_with_force_scale": dict(zip(self.names, map(float, self.correlation))),
                "multiple_correlation_with_the_parameters": self.multiple_correlation,
                "separable": self.separable, "correlation_limit": self.correlation_limit,
                "peak_torque_shift_of_tmax_for_force_1pct_below": self.peak_shift_of_tmax,
                "why": "the force scale is not estimated as a nuisance: on this log the parameters together absorb it beyond "
                       "the correlation limit" if not self.separable else
                       "the force scale is separable on this log but not estimated; log process_force_N to use the force"}


def _rise(theta: np.ndarray, force: np.ndarray, sign: float) -> float:
    """deg: the first grid angle (counted from the largest gap below half) where sign x force reaches half its peak."""
    f = sign * force
    above = f >= 0.5 * float(np.max(f))
    up = np.flatnonzero(above & ~np.roll(above, 1))
    if up.size == 0:
        return math.nan
    return float(np.degrees(theta[up[0]]))


def step_indices(curve: np.ndarray, fraction: float) -> np.ndarray:
    """Grid indices where the periodic curve jumps from the point before by more than ``fraction`` of its peak."""
    return np.flatnonzero(np.abs(curve - np.roll(curve, 1)) > fraction * float(np.max(np.abs(curve))))


def _unloaded_as_zero(curve: np.ndarray, base: np.ndarray, cuts: np.ndarray, job: np.ndarray, z: float) -> np.ndarray:
    """``curve`` with each piece between the steps ``cuts`` where the job has no force and the logged values ``base``
    average to within ``z`` standard errors of zero set to zero: there the log holds the force sensor's noise on an
    unloaded slide, which the model would otherwise read as force (at up to 0.01 N m of motor torque per N, a few kN of
    filtered noise is a misfit the adequacy test sees)."""
    n = curve.size
    starts = cuts if cuts.size else np.array([0])
    out = curve.copy()
    for i, c in enumerate(starts):
        length = ((starts[(i + 1) % starts.size] - c) % n) or n
        idx = (c + np.arange(length)) % n
        if length < 3 or np.any(job[idx] != 0.0):
            continue
        v = base[idx]
        se = float(np.std(v, ddof=1)) / math.sqrt(length)
        if abs(float(np.mean(v))) <= z * se:
            out[idx] = 0.0
    return out


def smooth_between_steps(mean: np.ndarray, base: np.ndarray, cuts: np.ndarray, window_deg: float, theta: np.ndarray,
                         order: int) -> np.ndarray:
    """N: the periodic force ``base`` (n,) smoothed piece by piece between the steps starting at ``cuts`` (grid indices) by
    a Savitzky-Golay filter of ``window_deg``; each piece's first and last point (either may hold part of the step: a
    sample pair or a bin across it) are left out of the fit and take the value of the piece's local polynomial there.
    ``mean`` (the interpolated stroke mean) is where the steps were found; a piece too short for the window keeps ``base``.
    ``base`` may be (n, m): each column smoothed alike (the identity gives the filter's matrix, :func:`logged_force`)."""
    n = base.shape[0]
    step_deg = math.degrees(theta[1] - theta[0])
    win = max(order + 2, int(round(window_deg / step_deg)) | 1)
    if cuts.size == 0:
        return savgol_filter(base, win, order, mode="wrap", axis=0)
    out = base.copy()
    for i, c in enumerate(cuts):
        nxt = cuts[(i + 1) % cuts.size]
        length = (nxt - c) % n or n
        idx = (c + np.arange(length)) % n
        inner = idx[1:-1]
        if inner.size < win:
            continue
        out[inner] = savgol_filter(base[inner], win, order, mode="interp", axis=0)
        x = np.arange(length, dtype=float)
        for end, near in ((0, slice(1, 1 + win)), (length - 1, slice(length - 1 - win, length - 1))):
            coef = np.polyfit(x[near], base[idx[near]], order)
            out[idx[end]] = np.polyval(coef, x[end])
    return out


def snap_transitions(curve: np.ndarray, cuts: np.ndarray, longest: int = 2, down: np.ndarray | None = None) -> np.ndarray:
    """N: ``curve`` with each piece of at most ``longest`` grid points between two steps (``cuts``) set, point by point,
    to the nearer of the values on either side of it (the end of the piece before, the start of the piece after).
    Such a piece is a grid point whose bin holds samples from both sides of a step (a die contact between two grid
    points): its mean is a share of the step that no crank angle has, whereas the rigid model's force at the grid
    angle is one side's. The bins are centred on the grid points, so the nearer side is the side of the grid angle
    itself (a bin more than half after the step has its grid angle after it); a share left in would be a model torque
    of that share of the step at one point, ~10 kN m on the reference press, that the torque log does not have.

    Where the slide reverses inside the bin (``down`` (n,) bool, the slide moving down or resting, dH/dtheta <= 0 at
    each grid point: the two sides move in opposite directions) the step lies at the grid angle itself, no nearer side
    exists and the force channel's noise would pick one (on the crank-slider press BDC is the 180-degree grid point:
    the noise took the unloaded side in some logs and not in others, and mu_s of one log moved 0.073 -> 0.106 with it);
    there the point takes the side moving the way the point itself does, the convention of the model's force
    (:class:`LoggedProcess`, Eq. 14's direction: dH/dtheta <= 0 is the downstroke)."""
    n = curve.size
    if cuts.size < 2:
        return curve
    out = curve.copy()
    for i, c in enumerate(cuts):
        nxt = cuts[(i + 1) % cuts.size]
        length = (nxt - c) % n or n
        if length > longest:
            continue
        before, after = curve[(c - 1) % n], curve[nxt % n]
        reverses = down is not None and bool(down[(c - 1) % n]) != bool(down[nxt % n])
        for k in (c + np.arange(length)) % n:
            if reverses:
                out[k] = before if bool(down[k]) == bool(down[(c - 1) % n]) else after
            else:
                out[k] = before if abs(curve[k] - before) <= abs(curve[k] - after) else after
    return out


def logged_force(source: str, theta: np.ndarray, stroke_force: np.ndarray, heights: tuple[np.ndarray, np.ndarray],
                 job_process: ProcessForce, st: ProcessForceSection, binned: np.ndarray | None = None,
                 turns: tuple[np.ndarray, np.ndarray] | None = None) -> LoggedForce:
    """The logged force of a log (:class:`LoggedForce`, module docstring); ``stroke_force`` (S, n) N per turn on the
    grid ``theta``; ``heights`` from :func:`press_model.kinematics.grid_heights`; ``turns``: each turn's bin means and
    counts (:attr:`calibration.traces.drive_log.DriveLog.stroke_force_binned`, ``stroke_force_counts``), from which the
    curve's noise is estimated (None: not estimated). Refuses a force that covers not every grid angle, is zero,
    has the other sign than the job's, or rises farther than ``contact_limit_deg`` from the job's."""
    F = np.asarray(stroke_force, dtype=float)
    count = np.sum(np.isfinite(F), axis=0)
    if np.any(count == 0):
        raise PressDataError(source, "process_force_N", f"no value at {int(np.sum(count == 0))} crank angles",
                             "must hold the force over every crank angle of the turn (empty cells in every turn there): "
                             "log the force channel with the others")
    mean = np.nanmean(F, axis=0)
    if not np.any(mean != 0.0):
        raise PressDataError(source, "process_force_N", 0.0, "is 0 in every row: the column holds no force; leave it out to "
                             "calibrate with the job's force, or log the cushion's force in N")
    h, hd = heights
    job = np.asarray(job_process(h, hd), dtype=float)  # hd per unit crank speed has the sign of the slide's rate
    _check_against_job(source, mean, job)
    both = count >= 2
    spread = np.nanstd(F[:, both], axis=0, ddof=1) if both.any() else np.array([math.nan])
    noise = float(np.sqrt(np.mean(spread ** 2 / count[both]))) if both.any() else math.nan
    base = mean.copy()
    if binned is not None:  # every sample of a degree, not the two the interpolation reads
        use = np.isfinite(binned)
        base[use] = binned[use]
    cuts = step_indices(mean, st.step_fraction)
    operator = smooth_between_steps(mean, np.eye(mean.size), cuts, st.filter_window_deg, theta, st.filter_order)
    smoothed = smooth_between_steps(mean, base, cuts, st.filter_window_deg, theta, st.filter_order)
    curve = snap_transitions(smoothed, cuts, down=hd <= 0.0)
    operator = _snapped_rows(operator, smoothed, curve)
    se = None
    if turns is not None:
        se, sample_noise = binned_standard_errors(turns[0], turns[1], cuts)
        if binned is not None:  # a bin without samples took the interpolated stroke mean: its own scatter
            se = np.where(np.isfinite(binned), se, spread_of_mean(F))
    cuts = step_indices(curve, st.step_fraction)  # a transition point snapped to one side moves its step to the other
    half = 0.5 * float(theta[1] - theta[0])
    rises = [k for k in cuts if abs(curve[k]) > abs(curve[k - 1])]
    order = sorted(cuts, key=lambda k: (k not in rises[:1], k))  # the first rise (die contact) first
    steps = tuple(float(theta[k]) - half for k in order)
    kept = _unloaded_as_zero(curve, base, cuts, job, st.unloaded_standard_errors)
    operator[(kept == 0.0) & (curve != 0.0)] = 0.0  # a piece set to zero carries no noise
    curve = kept
    warnings = []
    scale, rise, job_rise = math.nan, _rise(theta, curve, 1.0 if np.max(curve) >= -np.min(curve) else -1.0), math.nan
    if np.any(job != 0.0):
        scale = float(np.dot(curve, job) / np.dot(job, job))
        if scale <= 0.0:
            raise PressDataError(source, "process_force_N", f"logged / job's force = {scale:.3g}",
                                 "must be positive: the column has the other sign than the job's [process] forces_N (the force "
                                 "on the slide, up positive); multiply it by -1 (or sign = -1 in the channel map)")
        sign = 1.0 if np.max(job) >= -np.min(job) else -1.0
        rise, job_rise = _rise(theta, curve, sign), _rise(theta, job, sign)
        off = abs((rise - job_rise + 180.0) % 360.0 - 180.0)
        what = (f"rises to half its peak at {rise:.1f} deg, the job's force at {job_rise:.1f} deg ({off:.1f} deg apart)")
        if off > st.contact_limit_deg:
            raise PressDataError(source, "process_force_N", f"rise at {rise:.1f} deg",
                                 f"must lie within {st.contact_limit_deg:g} deg of the job's ({job_rise:.1f} deg: die contact at "
                                 f"contact_height_m = {job_process.contact_height:g}) ([calibration.process_force] "
                                 "contact_limit_deg): the force channel belongs to another run or die height, or is logged late; "
                                 "check the job's [process] and the channel's timing")
        if off > st.contact_warning_deg:
            warnings.append(f"the logged process force {what}: beyond {st.contact_warning_deg:g} deg "
                            "([calibration.process_force] contact_warning_deg); the model, the peak window and the force steps "
                            "follow the logged force: check the job's contact_height_m and the force channel's timing")
        if abs(scale - 1.0) > FORCE_SCALE_WARNING:
            warnings.append(f"the logged process force (process_force_N) is {scale:.3f} times the job's [process] forces_N "
                            f"(least squares over the turn; more than {100.0 * FORCE_SCALE_WARNING:g} % off): the model takes the "
                            "logged force, so if the job's force is right the force channel's scale or unit is wrong and every "
                            "parameter absorbs it: check the channel (its unit N, its scale), else correct the job's [process]")
    down, up = hd <= 0.0, hd > 0.0
    od, ou = np.argsort(h[down]), np.argsort(h[up])
    proc = LoggedProcess(h[down][od], curve[down][od], h[up][ou], curve[up][ou], job_process.contact_height,
                         tuple(job_process.heights), tuple(job_process.forces), source)
    for a in (proc.down_h, proc.down_f, proc.up_h, proc.up_f):
        a.flags.writeable = False
    peak = float(np.max(np.abs(curve)))
    if se is not None and math.isfinite(sample_noise) and sample_noise > FORCE_NOISE_WARNING * peak:
        warnings.append(f"the force channel (process_force_N) is noisy: {sample_noise:.3g} N per sample from turn to turn, "
                        f"{100.0 * sample_noise / peak:.0f} % of its {peak:.3g} N peak (a force channel reads to about 1 %, "
                        f"warned above {100.0 * FORCE_NOISE_WARNING:g} %): the model takes that noisy force; check the channel "
                        "(interference, its range or filter), or leave the column out to calibrate with the job's force")
    factor, binned_noise = None, math.nan
    if se is not None:
        factor = operator * se[None, :]
        factor.flags.writeable = False
        loaded = np.any(operator != 0.0, axis=1) & (np.abs(curve) > st.step_fraction * float(np.max(np.abs(curve))))
        binned_noise = float(np.sqrt(np.mean(se[loaded] ** 2))) if loaded.any() else math.nan
    return LoggedForce(curve, mean, noise, int(np.min(count)), scale, rise, job_rise, proc,
                       tuple(warnings), steps, factor, binned_noise, sample_noise if se is not None else math.nan)


def _check_against_job(source: str, mean: np.ndarray, job: np.ndarray) -> None:
    """Refuse a logged stroke-mean force ``mean`` (n,) N that cannot be the job's force ``job`` (n,) N on the same grid
    as logged: a peak off the job's by more than :data:`FORCE_SCALE_LIMIT` either way (a unit or channel scale; the
    ratio named, with the unit it looks like), or a mean where the job has no force above :data:`FORCE_UNLOADED_LIMIT`
    of the logged peak (an offset or a constant, not a force on the slide). A job without a force is not compared."""
    job_peak, peak = float(np.max(np.abs(job))), float(np.max(np.abs(mean)))
    if not job_peak > 0.0:
        return
    ratio = peak / job_peak
    if not 1.0 / FORCE_SCALE_LIMIT <= ratio <= FORCE_SCALE_LIMIT:
        looks = next((f"looks like {unit}: multiply it by {factor:g}" for unit, factor in (("kN", 1e3), ("MN", 1e6), ("lbf", 4.4482216))
                      if abs(math.log(ratio * factor)) < math.log(1.5)), None)
        raise PressDataError(source, "process_force_N", f"logged / job's peak force = {ratio:.3g}",
                             f"must lie within a factor {FORCE_SCALE_LIMIT:g} of the job's [process] forces_N (peak "
                             f"{job_peak:.4g} N; the logged peak is {peak:.4g} N): "
                             + (f"the column {looks} (or set its scale in the channel map)" if looks else
                                "the column's unit (N) or scale is wrong, or the log is of another job")
                             + "; or leave the column out to calibrate with the job's force")
    unloaded = job == 0.0
    if unloaded.any():
        off = float(np.mean(mean[unloaded]))
        if abs(off) > FORCE_UNLOADED_LIMIT * peak:
            raise PressDataError(source, "process_force_N", f"{off:.4g} N where the job has no force",
                                 f"must be near 0 where the slide is off the die (the job's force is 0 over "
                                 f"{100.0 * np.mean(unloaded):.0f} % of the turn), not {100.0 * abs(off) / peak:.0f} % of the "
                                 "logged peak: the column holds an offset or a constant, not the force on the slide; remove the "
                                 "offset, or leave the column out to calibrate with the job's force")


def _snapped_rows(operator: np.ndarray, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """The smoothing matrix ``operator`` (n, n) with the row of each point :func:`snap_transitions` set to a neighbour's
    value (``before`` -> ``after``) replaced by that neighbour's row: the snapped point is that neighbour's value, noise
    and all."""
    out = operator.copy()
    n = before.size
    for k in np.flatnonzero(after != before):
        for d in (-1, 1, -2, 2, -3, 3):
            j = (k + d) % n
            if before[j] == after[k]:
                out[k] = operator[j]
                break
    return out


def scaled(process: ProcessForce, factor: float) -> ProcessForce:
    """The job's process force times ``factor``."""
    return dataclasses.replace(process, forces=tuple(factor * f for f in process.forces))


def force_sensitivity(problem, obj, obj_scaled, x: np.ndarray, refit, t_max: float, correlation_limit: float) -> ForceSensitivity:
    """:class:`ForceSensitivity` at the estimate ``x``: ``obj`` Eq. 28 as calibrated, ``obj_scaled`` the same with the
    model's process force 1 % higher (:data:`FORCE_STEP`) on every log without a logged force; ``refit(objective, x)``
    the local refit of Eq. 28 (calibration/identification/bootstrap.py); ``t_max`` the motor's peak torque (N m)."""
    x = np.asarray(x, dtype=float)
    x_hi = refit(obj_scaled, x)
    move = x_hi - x  # the estimate with 1 % more force in the model: where the truth lies when the true force is 1 % above
    J = jacobian(obj, x)
    col = (obj_scaled.torques(x[None])[0] - obj.torques(x[None])[0]) / FORCE_STEP
    A = np.column_stack([J, col])
    norm = np.sqrt(np.sum(A ** 2, axis=0))
    norm[norm == 0.0] = 1.0
    C = np.linalg.pinv((A / norm).T @ (A / norm))
    d = np.sqrt(np.clip(np.diag(C), 1e-300, None))
    corr = C[-1, :-1] / (d[-1] * d[:-1])
    # the force column against every parameter column at once: C[-1, -1] of the normalised information is its VIF
    multiple = float(np.sqrt(max(0.0, 1.0 - 1.0 / max(float(C[-1, -1]), 1.0))))
    T = obj.torques(np.vstack([x, x - move]))  # calibrated; the truth when the true force is 1 % below the job's
    peak = (float(np.max(np.abs(T[1]))) - float(np.max(np.abs(T[0])))) / t_max
    shift = -move
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(x != 0.0, shift / x, 0.0)
    return ForceSensitivity(tuple(problem.names), shift, rel, corr, peak, multiple <= correlation_limit, correlation_limit,
                            multiple)


def force_candidate(column: np.ndarray) -> Candidate:
    """The score-test candidate of a process force other than the job's on a log without the force column: ``column`` (n,)
    N m, the motor torque the model gains per unit of relative force scale at the estimate (its size is reported in %
    of the job's force)."""
    return Candidate("process_force_scale", "a process force scale other than the job's (the log has no process_force_N "
                     "column; size in % of the job's force)", np.asarray(column, float)[:, None], "% of the job's force", 100.0)


def force_warning(sens: ForceSensitivity, tolerance: float, limit: float) -> str | None:
    """The warning when the job's force tolerance (a 95 % bound, fraction) moves eta_gear or psi (:data:`WARNED_PARAMETERS`)
    by more than ``limit`` (fraction of the estimate), linearly by the sensitivity ``sens``; None when it moves neither
    that far. It names the missing column, each parameter's move and the peak torque (% of T_max) a plan made from
    these values may lack."""
    moves = {n: abs(float(r)) * tolerance / FORCE_STEP for n, r in zip(sens.names, sens.relative_shift) if n in WARNED_PARAMETERS}
    if not moves or max(moves.values()) <= limit:
        return None
    peak = abs(sens.peak_shift_of_tmax) * tolerance / FORCE_STEP
    told = (f"cannot tell a force error from the parameters (multiple correlation {sens.multiple_correlation:.3f})"
            if not sens.separable else "could tell a force error from the parameters, but the force scale is not estimated")
    return (f"{FORCE_WARNING}: the log has no process_force_N column, so the model takes the job's nominal process force, "
            f"known to +-{100.0 * tolerance:g} % ([calibration.process_force] job_force_tolerance, a 95 % bound); this log "
            f"{told}, and that tolerance alone makes "
            + " and ".join(f"{n} uncertain by +-{100.0 * m:.1f} %" for n, m in moves.items() if m > limit)
            + "".join(f" ({n} +-{100.0 * m:.1f} %)" for n, m in moves.items() if m <= limit)
            + f", more than the {100.0 * limit:g} % of [calibration.process_force] warning_shift. A plan made from these "
            f"values may need up to {100.0 * peak:.1f} % of T_max more peak torque than they predict, out of its torque "
            "margin; the intervals and the joint region carry the tolerance, so a plan robust over the joint region keeps "
            "its margin only if the force is within it. Log the cushion's force as process_force_N (a servo cushion or a "
            "tonnage monitor has it) to take this out")


def job_force_models(jobs, problem, pm, lps):
    """(Eq. 28 as calibrated, the same with the job's force 1 % higher (:data:`FORCE_STEP`) on each log without a
    logged force, the parts of the second per log) for the log problems ``lps`` (calibration/identification/run.py
    ``LogProblem``, each with its job in ``jobs``); None when every log has its force logged or no job has one. What the
    score test's columns (:func:`force_columns`) and the account (:func:`process_force_account`) are both read from,
    built once."""
    logged = [lp for lp in lps if lp.force is not None]
    if not (len(logged) < len(lps) and any(max(np.abs(jb.process.forces)) > 0.0 for jb in jobs)):
        return None
    parts = []
    for lp, jb in zip(lps, jobs):
        if lp.force is not None or not max(np.abs(jb.process.forces)) > 0.0:
            parts.append(lp.objective)
            continue
        # the log's own model under the scaled force: the numbers of one built on it, without its RNEA runs
        bm = with_process(lp.objective.bm, lp.process, scaled(jb.process, 1.0 + FORCE_STEP), pm)
        parts.append(dataclasses.replace(lp.objective, bm=bm))
    return joint_objective(problem, [lp.objective for lp in lps]), joint_objective(problem, parts), parts


def force_columns(lps, models, x: np.ndarray) -> list:
    """Each log's force-scale column at the estimate ``x`` (N m per unit of relative scale, :func:`force_candidate`;
    None for a log with its force logged or a job without one) from :func:`job_force_models`' ``models`` (None: every
    log's is None)."""
    if models is None:
        return [None] * len(lps)
    obj, obj_hi, parts = models
    T_at = obj.torques(np.asarray(x, float)[None])[0]
    col = np.split((obj_hi.torques(np.asarray(x, float)[None])[0] - T_at) / FORCE_STEP,
                   np.cumsum([lp.objective.bm.n_points for lp in lps])[:-1])
    return [c if p is not lp.objective else None for c, p, lp in zip(col, parts, lps)]


def process_force_account(press, cs, problem, lps, x: np.ndarray, models) -> tuple[dict, str, list[str], np.ndarray]:
    """calibrated.json's ``process_force``, the console's line on it, its warnings and the standard deviation (k,) SI it
    adds to each parameter, for the log problems ``lps`` (calibration/identification/run.py ``LogProblem``) at the
    estimate ``x``: each log's logged force (:class:`LoggedForce`), and for the logs without one (``models``: their
    :func:`job_force_models`, None where there are none) what a 1 % error of the job's force does to the estimate
    (:func:`force_sensitivity`), carried into the intervals at ``[calibration.process_force] job_force_tolerance`` (a
    95 % bound of the job force's relative error; 0: exact), with a warning when that moves eta_gear or psi by more
    than ``warning_shift`` (:func:`force_warning`)."""
    spread = np.zeros(len(x))
    logged = [lp.force for lp in lps if lp.force is not None]
    record: dict = {"logs": [lp.force.record() if lp.force is not None else {"source": "job (nominal curve, not logged)"}
                             for lp in lps]}
    warnings = [w for f in logged for w in f.warnings]
    lines = []
    if logged:
        lines.append(f"process force: logged (process_force_N) in {len(logged)} of {len(lps)} log{'s' if len(lps) > 1 else ''}, "
                     "stroke mean smoothed between its steps; logged / job's force "
                     + ", ".join(f"{f.scale:.3f}" for f in logged) + "; rises at "
                     + ", ".join(f"{f.rise_deg:.0f} deg (job {f.job_rise_deg:.0f})" for f in logged))
    if models is not None:
        obj, obj_hi, _ = models

        def refit(o, x0):
            return refit_batch([o], x0, cs.bootstrap.iterations)[0][0]

        sens = force_sensitivity(problem, obj, obj_hi, x, refit, press.motor.peak_torque, cs.correlation_limit)
        record["sensitivity"] = sens.record()
        lines.append(sens.line())
        tol = cs.process_force.job_force_tolerance
        spread = np.abs(sens.shift) * (tol / FORCE_STEP) / float(stats.norm.ppf(0.975))  # tol as a 95 % bound, linear
        record["job_force_tolerance"] = tol
        record["interval_sd"] = dict(zip(problem.names, map(float, spread)))
        lines.append(f"  the intervals carry a job force tolerance of {100.0 * tol:g} % ([calibration.process_force] "
                     "job_force_tolerance)" if tol else "  the intervals take the job's force as exact ([calibration.process_force] "
                     "job_force_tolerance = 0); set it to the force's accuracy to carry that into them")
        warn = force_warning(sens, tol, cs.process_force.warning_shift)
        record["warning_shift"] = cs.process_force.warning_shift
        record["warned"] = warn is not None
        if warn:
            warnings.append(warn)
    return record, "\n  ".join(lines), warnings, spread
