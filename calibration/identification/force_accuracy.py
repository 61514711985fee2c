"""The logged process force's own accuracy: what its stated scale and offset error do to a calibration that takes it.

A log with the force column (process_force_N) replaces the job's nominal force with the logged one
(:mod:`calibration.identification.process_force`); its noise is accounted in :mod:`calibration.identification.force_noise`.
Its calibration error is not noise: the whole channel reads high or low (scale: a pressure transducer's or a load
cell's sensitivity, the piston area), or off by a constant where the force is on (offset: the transducer's zero), on
every stroke alike. The job states both as 95 % bounds ([calibration.process_force] logged_scale_accuracy,
logged_offset_accuracy). As for the job's force tolerance on a log without the column, each is carried into the
intervals and the joint region by what it moves the estimate (the refit of Eq. 28 with the logged force 1 % higher, or
offset by 1 % of its peak; :func:`calibration.identification.process_force.force_sensitivity`), linearly, the two
independent; a warning names eta_gear or psi where the accuracy alone moves them past ``warning_shift``. Where the
data can tell the force's scale from the parameters (the scale's column not within their span: its multiple
correlation with them short of 1), the scale is one more suspect of the lack-of-fit score tests
(:func:`scale_candidate`), and its estimate is tested against the stated accuracy alone (:func:`scale_warning`): a
channel reading off by more than the accuracy allows, by as much as the data resolve, is warned about.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy import stats

from press_model.batch import with_process

from calibration.identification.adequacy import Candidate
from calibration.identification.bootstrap import refit_batch
from calibration.identification.joint import joint_objective
from calibration.identification.process_force import FORCE_STEP, WARNED_PARAMETERS, ForceSensitivity, force_sensitivity

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
    gains per unit of relative scale of the logged force at the estimate (its size reported in % of the logged force)."""
    return Candidate(SCALE_TEST, "the logged process force reading high or low (its channel's scale; size in % of "
                     "the logged force)", np.asarray(column, float)[:, None], "% of the logged force", 100.0)


def _moves(sens: ForceSensitivity, bound: float) -> np.ndarray:
    """(k,) fraction of each estimate: how far the error ``bound`` (a 95 % bound in units of :data:`FORCE_STEP`'s) moves it."""
    return np.abs(sens.relative_shift) * bound / FORCE_STEP


def logged_force_accuracy(cs, problem, pm, lps, x: np.ndarray, t_max: float):
    """The logged force's accuracy for the log problems ``lps`` (calibration/identification/run.py ``LogProblem``) at the
    estimate ``x``: (calibrated.json's record, the console line, warnings, (k,) SI standard deviation it adds to each
    parameter, per log its score-test candidate or None); (None, "", [], zeros, [None...]) when no log has the force
    logged. ``t_max``: the motor's peak torque (N m)."""
    k = len(x)
    st = cs.process_force
    if not any(lp.force is not None for lp in lps):
        return None, "", [], np.zeros(k), [None] * len(lps)
    obj = joint_objective(problem, [lp.objective for lp in lps])

    def refit(o, x0):
        return refit_batch([o], x0, cs.bootstrap.iterations)[0][0]

    def sensitivity(scale, offset_of_peak):
        parts = [lp.objective if lp.force is None else dataclasses.replace(lp.objective, bm=with_process(
            lp.objective.bm, lp.process, shifted(lp.process, scale, offset_of_peak * float(np.max(np.abs(lp.force.curve)))), pm))
            for lp in lps]
        o = joint_objective(problem, parts)
        return o, force_sensitivity(problem, obj, o, x, refit, t_max, cs.correlation_limit)

    obj_scale, scale = sensitivity(1.0 + FORCE_STEP, 0.0)
    _, offset = sensitivity(1.0, FORCE_STEP)
    q = float(stats.norm.ppf(0.975))
    spread = np.hypot(np.abs(scale.shift) * st.logged_scale_accuracy, np.abs(offset.shift) * st.logged_offset_accuracy) / FORCE_STEP / q
    moves = np.hypot(_moves(scale, st.logged_scale_accuracy), _moves(offset, st.logged_offset_accuracy))
    col = np.split((obj_scale.torques(np.asarray(x, float)[None])[0] - obj.torques(np.asarray(x, float)[None])[0]) / FORCE_STEP,
                   np.cumsum([lp.objective.bm.n_points for lp in lps])[:-1])
    candidates = [scale_candidate(c) if lp.force is not None else None for c, lp in zip(col, lps)]
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
              "method": "the refit of Eq. 28 with the logged force 1 % higher (offset by 1 % of its peak where on), scaled "
                        "linearly to each 95 % bound, the two in quadrature (calibration/identification/force_accuracy.py)"}
    line = (f"  the intervals carry the logged force's accuracy (scale +-{100 * st.logged_scale_accuracy:g} %, offset +-"
            f"{100 * st.logged_offset_accuracy:g} % of its peak): eta_gear +-{100 * warned.get('eta_gear', 0.0):.2f} %, psi +-"
            f"{100 * warned.get('psi', 0.0):.2f} %; its scale {'is' if scale.separable else 'is not'} told apart from the "
            f"parameters (multiple correlation {scale.multiple_correlation:.3f})")
    return record, line, warnings, spread, candidates


def scale_warning(tests, st, source: str = "") -> str | None:
    """The warning when the lack-of-fit score test of the logged force's scale (``tests``: a log's
    :class:`calibration.identification.adequacy.ScoreTest` s) puts the scale off 1 by more than its stated accuracy
    (``st``: [calibration.process_force]) allows: the test's estimate against 0, its standard error and the accuracy's
    (a 95 % bound) in quadrature, two-sided at 95 %; None when it does not, or no such test ran. ``source``: the log."""
    t = next((t for t in tests if t.name == SCALE_TEST), None)
    if t is None or not np.isfinite(t.size) or not np.isfinite(t.size_std):
        return None
    q = float(stats.norm.ppf(0.975))
    sd = float(np.hypot(t.size_std, 100.0 * st.logged_scale_accuracy / q))
    if sd <= 0.0 or abs(t.size) <= q * sd:
        return None
    # the model asks for its force t.size % higher: the channel reads that much low (negative: high)
    return (f"{ACCURACY_WARNING}: the log's torque asks for the logged process force {t.size:+.1f} % (+-{q * t.size_std:.1f} %, "
            f"score test{f' on {source}' if source else ''}), beyond its stated accuracy of +-{100 * st.logged_scale_accuracy:g} % "
            f"([calibration.process_force] logged_scale_accuracy): the force channel reads {'high' if t.size < 0 else 'low'} "
            "(a transducer or load cell off its calibration) or the cushion's force is not the one on the slide; the "
            "parameters have absorbed it (eta_gear first): check the channel against a load cell before planning from them")
