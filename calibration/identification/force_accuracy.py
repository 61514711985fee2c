"""The logged process force's own accuracy: what its stated scale and offset error do to a calibration that takes it.

A log with the force column (process_force_N) replaces the job's nominal force with the logged one
(:mod:`calibration.identification.process_force`); its noise is accounted in :mod:`calibration.identification.force_noise`.
Its calibration error is not noise: the whole channel reads high or low (scale: a pressure transducer's or a load
cell's sensitivity, the piston area), or off by a constant where the force is on (offset: the transducer's zero), on
every stroke alike. The job states both as 95 % bounds ([calibration.process_force] logged_scale_accuracy,
logged_offset_accuracy). As for the job's force tolerance on a log without the column, each is carried into the
intervals and the joint region by what it moves the estimate (the refits of Eq. 28 with the logged force 1 % higher
and lower, or offset by +-1 % of its peak; :func:`calibration.identification.process_force.force_sensitivity`; the root
mean square of the two moves, :func:`two_sided`), linearly, the two independent; a warning names eta_gear or psi
where the accuracy alone moves them past ``warning_shift``. Where the data can tell the force's scale from the parameters (the scale's column not within their span: its multiple
correlation with them short of 1), the scale is one more suspect of the lack-of-fit score tests
(:func:`scale_candidate`), and its estimate is tested against the stated accuracy alone (:func:`scale_warning`): a
channel reading off by more than the accuracy allows, by as much as the data resolve, is warned about.

**The test's power.** A 3 % error is four standard deviations of a 1.5 % (95 %) accuracy, but the test sees it only
through what the data resolve. On the interpolated stroke mean (the two samples beside each grid point) the scale's
standard error was 1.9-2.2 % on the 3-stroke cushion test (its column's multiple correlation with the parameters' is
0.945: a tenth of its variance is left once they are projected off), so a 3 % error was 1.3 combined standard
deviations away and warned on 1 of 4 SYNTHETIC logs (docs/validation.md). Tested on the log's bin means (every sample,
as the recording's shifts are), its standard error is 0.8 %. And the job's set force is a second reading of the same
force: a cushion holds it to ``job_force_tolerance`` (3 %, 95 %), so the logged force over the job's (least squares,
:attr:`calibration.identification.process_force.LoggedForce.scale`) tells the channel's scale to 1.5 % (one standard
deviation) beside the torque's 0.8 %; the two are independent and weighed by their variances (:func:`channel_scale`).
A cushion whose true force is off the job's, read by an exact channel, moves that estimate by a fifth of its offset.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats

from press_model.batch import with_process

from calibration.identification.adequacy import Candidate
from calibration.identification.bootstrap import refit_batch
from calibration.identification.joint import joint_objective
from calibration.identification.process_force import FORCE_STEP, WARNED_PARAMETERS, ForceSensitivity, force_sensitivity

# the normal quantile of a 95 % bound, once: scipy's ppf costs ~0.1 ms, and the design search calls accuracy_sd per candidate
_Q95 = float(stats.norm.ppf(0.975))

ACCURACY_WARNING = "LOGGED FORCE ACCURACY"  # how the warnings start (the console marks them WARNING)
SCALE_TEST = "logged_force_scale"  # the score test's name


def shifted(process, scale: float = 1.0, offset_N: float = 0.0):
    """A logged process force (:class:`calibration.identification.process_force.LoggedProcess`) times ``scale``, plus
    ``offset_N`` (N) where it is on (a force channel's zero error reads only while the cushion presses)."""
    def moved(f):
        f = np.asarray(f, float)
        return scale * f + np.where(f != 0.0, offset_N, 0.0)

    return dataclasses.replace(process, down_f=moved(process.down_f), up_f=moved(process.up_f))


def scale_candidate(column: np.ndarray) -> Candidate:
    """The score-test candidate of a logged force whose scale is off: ``column`` (n,) N m, the motor torque the model
    gains per unit of relative scale of the logged force at the estimate (its size reported in % of the logged force),
    tested on the log's bin means as the recording's shifts are (module docstring: the interpolated curve's noise left
    its standard error at 2 %)."""
    return Candidate(SCALE_TEST, "the logged process force reading high or low (its channel's scale; size in % of "
                     "the logged force)", np.asarray(column, float)[:, None], "% of the logged force", 100.0, binned=True)


def accuracy_sd(scale_shift: np.ndarray, offset_shift: np.ndarray, st) -> np.ndarray:
    """(k, 2): the standard deviation (signed; the shifts' unit) the logged force's stated scale and offset accuracy
    (``st``: [calibration.process_force], each a 95 % bound) give each parameter, from the parameters' shifts (k,) when the
    logged force is :data:`FORCE_STEP` higher and when it is offset by FORCE_STEP of its peak where on. The two errors
    are independent: a parameter's interval carries the hypot of its row (`calibrate`), a prediction the covariance of
    both columns (calibration/design/information.py)."""
    return np.column_stack([np.asarray(scale_shift, float) * st.logged_scale_accuracy,
                            np.asarray(offset_shift, float) * st.logged_offset_accuracy]) / FORCE_STEP / _Q95


def _moves(sens: ForceSensitivity, bound: float) -> np.ndarray:
    """(k,) fraction of each estimate: how far the error ``bound`` (a 95 % bound in units of :data:`FORCE_STEP`'s) moves it."""
    return np.abs(sens.relative_shift) * bound / FORCE_STEP


def two_sided(up: ForceSensitivity, down: ForceSensitivity) -> ForceSensitivity:
    """The response to a force error of either sign from the refits with the force :data:`FORCE_STEP` higher (``up``)
    and lower (``down``, its shifts turned to the same sign convention): each parameter's root mean square of the two
    one-sided moves, signed as their mean (two-point Gauss-Hermite, as the recording's share): Eq. 28's peak term has a
    kink where the calibrated peak matches the measured one, and one side's move alone was 1.39 against 0.84 % of
    eta_gear per % on a clean SYNTHETIC log (seed 5102), 1.21 against 1.01 on its twin (5101), where the mean square of
    both is 1.15 and 1.12."""
    a, b = np.asarray(up.shift, float), -np.asarray(down.shift, float)
    ra, rb = np.asarray(up.relative_shift, float), -np.asarray(down.relative_shift, float)

    def rms(u, v):
        return np.where(u + v < 0.0, -1.0, 1.0) * np.sqrt(0.5 * (u * u + v * v))

    return dataclasses.replace(up, shift=rms(a, b), relative_shift=rms(ra, rb))


def _shifted_objective(problem, pm, lps, scale: float, offset_of_peak: float):
    """Eq. 28 of the log problems ``lps`` with each logged force times ``scale`` and offset by ``offset_of_peak`` of its
    peak (the logs without one as they are)."""
    parts = [lp.objective if lp.force is None else dataclasses.replace(lp.objective, bm=with_process(
        lp.objective.bm, lp.process, shifted(lp.process, scale, offset_of_peak * float(np.max(np.abs(lp.force.curve)))), pm))
        for lp in lps]
    return joint_objective(problem, parts)


def scale_models(problem, pm, lps):
    """(Eq. 28 of the log problems ``lps`` as calibrated, the same with each logged force 1 % higher): what the score
    test's candidates (:func:`scale_candidates`) and the account (:func:`logged_force_accuracy`) are both read from,
    built once; None when no log has the force logged."""
    if not any(lp.force is not None for lp in lps):
        return None
    return joint_objective(problem, [lp.objective for lp in lps]), _shifted_objective(problem, pm, lps, 1.0 + FORCE_STEP, 0.0)


def scale_candidates(lps, models, x: np.ndarray) -> list:
    """Per log, the logged force's scale as a score-test suspect at the estimate ``x`` (:func:`scale_candidate`), or
    None (no force logged); ``models``: :func:`scale_models`."""
    if models is None:
        return [None] * len(lps)
    obj, obj_scale = models
    col = np.split((obj_scale.torques(np.asarray(x, float)[None])[0] - obj.torques(np.asarray(x, float)[None])[0]) / FORCE_STEP,
                   np.cumsum([lp.objective.bm.n_points for lp in lps])[:-1])
    return [scale_candidate(c) if lp.force is not None else None for c, lp in zip(col, lps)]


def logged_force_accuracy(cs, problem, pm, lps, x: np.ndarray, t_max: float, models):
    """The logged force's accuracy for the log problems ``lps`` (calibration/identification/run.py ``LogProblem``) at the
    estimate ``x``: (calibrated.json's record, the console line, warnings, (k,) SI standard deviation it adds to each
    parameter); (None, "", [], zeros) when no log has the force logged (``models``, :func:`scale_models`, None).
    ``t_max``: the motor's peak torque (N m)."""
    k = len(x)
    st = cs.process_force
    if models is None:
        return None, "", [], np.zeros(k)
    obj, obj_scale = models

    def refit(o, x0):
        return refit_batch([o], x0, cs.bootstrap.iterations)[0][0]

    def sensitivity(scale, offset_of_peak):
        return force_sensitivity(problem, obj, _shifted_objective(problem, pm, lps, scale, offset_of_peak), x, refit, t_max,
                                 cs.correlation_limit)

    scale = two_sided(force_sensitivity(problem, obj, obj_scale, x, refit, t_max, cs.correlation_limit),
                      sensitivity(1.0 - FORCE_STEP, 0.0))
    offset = two_sided(sensitivity(1.0, FORCE_STEP), sensitivity(1.0, -FORCE_STEP))
    spread = np.hypot(*accuracy_sd(scale.shift, offset.shift, st).T)
    moves = np.hypot(_moves(scale, st.logged_scale_accuracy), _moves(offset, st.logged_offset_accuracy))
    warned = {n: float(m) for n, m in zip(problem.names, moves) if n in WARNED_PARAMETERS}
    warnings = []
    if warned and max(warned.values()) > st.warning_shift:
        warnings.append(f"{ACCURACY_WARNING}: the model takes the logged process force, whose stated accuracy (scale +-"
                        f"{100 * st.logged_scale_accuracy:g} %, offset +-{100 * st.logged_offset_accuracy:g} % of its peak, 95 % "
                        "bounds, [calibration.process_force] logged_scale_accuracy and logged_offset_accuracy) alone makes "
                        + " and ".join(f"{n} uncertain by +-{100 * m:.1f} %" for n, m in warned.items())
                        + f", more than the {100 * st.warning_shift:g} % of warning_shift; the intervals and the joint region carry "
                        "it. Calibrate the force channel against a load cell (or state its class) to narrow it")
    record = {"scale_accuracy": st.logged_scale_accuracy, "offset_accuracy_of_peak": st.logged_offset_accuracy,
              "per_percent_scale": {n: float(v) for n, v in zip(problem.names, scale.relative_shift)},
              "per_percent_offset": {n: float(v) for n, v in zip(problem.names, offset.relative_shift)},
              "moves_at_accuracy": {n: float(m) for n, m in zip(problem.names, moves)},
              "interval_sd": {n: float(v) for n, v in zip(problem.names, spread)},
              "scale_separable": bool(scale.separable), "scale_multiple_correlation": float(scale.multiple_correlation),
              "warning_shift": st.warning_shift, "warned": bool(warnings),
              "method": "the refits of Eq. 28 with the logged force 1 % higher and 1 % lower (offset by +-1 % of its peak where "
                        "on), the root mean square of the two moves scaled linearly to each 95 % bound, the two in quadrature "
                        "(calibration/identification/force_accuracy.py)"}
    line = (f"  the intervals carry the logged force's accuracy (scale +-{100 * st.logged_scale_accuracy:g} %, offset +-"
            f"{100 * st.logged_offset_accuracy:g} % of its peak): eta_gear +-{100 * warned.get('eta_gear', 0.0):.2f} %, psi +-"
            f"{100 * warned.get('psi', 0.0):.2f} %; its scale {'is' if scale.separable else 'is not'} told apart from the "
            f"parameters (multiple correlation {scale.multiple_correlation:.3f})")
    return record, line, warnings, spread


def channel_scale(test, st, ratio: float | None = None) -> tuple[float, float]:
    """(%, % standard error): how far the logged force channel reads high (negative: low), from the score test
    ``test`` of its scale (the model asks for the logged force ``test.size`` % higher: the channel reads that much low)
    and, given ``ratio`` (the logged force over the job's set force, least squares), from that ratio, the job's force
    known to ``st.job_force_tolerance`` (a 95 % bound; 0: exact, the ratio alone then says it); the two independent,
    weighed by the inverse of their variances."""
    q = float(stats.norm.ppf(0.975))
    reads = [(-test.size, test.size_std)]
    if ratio is not None and np.isfinite(ratio):
        sd = 100.0 * st.job_force_tolerance / q
        if sd == 0.0:
            return 100.0 * (ratio - 1.0), 0.0
        reads.append((100.0 * (ratio - 1.0), sd))
    w = np.array([1.0 / s ** 2 for _, s in reads])
    return float(np.sum(w * np.array([v for v, _ in reads])) / np.sum(w)), float(1.0 / math.sqrt(np.sum(w)))


def scale_warning(tests, st, source: str = "", ratio: float | None = None) -> str | None:
    """The warning when the logged force channel's scale error (:func:`channel_scale`: the lack-of-fit score test of
    its scale among ``tests``, a log's :class:`calibration.identification.adequacy.ScoreTest` s, and its ``ratio`` to
    the job's set force where given) is off 0 by more than the stated accuracy (``st``: [calibration.process_force])
    allows: its estimate against 0, its standard error and the accuracy's (a 95 % bound) in quadrature, two-sided at
    95 %; None when it is not, or no such test ran. ``source``: the log."""
    t = next((t for t in tests if t.name == SCALE_TEST), None)
    if t is None or not np.isfinite(t.size) or not np.isfinite(t.size_std) or t.size_std <= 0.0:
        return None
    q = float(stats.norm.ppf(0.975))
    high, se = channel_scale(t, st, ratio)
    sd = float(np.hypot(se, 100.0 * st.logged_scale_accuracy / q))
    if sd <= 0.0 or abs(high) <= q * sd:
        return None
    job = ("" if ratio is None or not np.isfinite(ratio) else
           f" and it reads {100.0 * (ratio - 1.0):+.1f} % against the job's set force (known to +-{100 * st.job_force_tolerance:g} %, "
           "[calibration.process_force] job_force_tolerance)")
    return (f"{ACCURACY_WARNING}: the log's torque asks for the logged process force {t.size:+.1f} % (+-{q * t.size_std:.1f} %, "
            f"score test{f' on {source}' if source else ''}){job}: the force channel reads {'high' if high > 0 else 'low'} by "
            f"{abs(high):.1f} % (+-{q * se:.1f} %), beyond its stated accuracy of +-"
            f"{100 * st.logged_scale_accuracy:g} % ([calibration.process_force] logged_scale_accuracy): a transducer or "
            "load cell off its calibration, or the cushion's force not the one on the slide; the parameters have absorbed "
            "it (eta_gear first): check the channel against a load cell before planning from them")
