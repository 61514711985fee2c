"""Calibration runs to design: their parametrisation, the motor's limits on each, and the D-optimal search.

A run (:class:`Run`) is one continuous crank motion, the modulated profile theta_dot = k (1 - depth cos(theta -
phase)) of the job files (``kind = "modulated"``: stroke rate, depth of the speed modulation and the angle of the
slowest speed), and one cushion setting: a constant force F up on the slide while it moves down below H_c (zero
force: no cushion). The job's ``[design]`` table (:class:`DesignSettings`) says what the press and cushion can do.

Limits, on every run and for every parameter draw (worst case): the peak motor torque at most (``peak_torque_margin``
- ``feedback_reserve``) x T_max, the feed-forward limit `plan` keeps (a run is played with its model torque as the
feed-forward and a feedback on top, [design.playback]), the RMS torque of Eq. 24 at most ``thermal_margin`` x the rated
torque, the motor speed at most its maximum. The search checks the peak on the run family's 1-deg grid; the chosen
runs are checked again on the planner's dense points (the grid's knots and 1/4, 1/2, 3/4 of each step: a 0.25-deg
family, :data:`DENSE_STEP_DEG`), and where one breaks the limit there the grid's limit is tightened by its excess and
the search repeated (:func:`search`).

Criterion (robust, pseudo-Bayesian D-optimality): the *mean* of log det C^-1 over a few parameter draws (the theoretical
values and a Latin hypercube over the calibration ranges, seeded), C the covariance a prediction reports
(:func:`calibration.design.information.carried_covariance`: F^-1 of the runs' information, the estimate pinned at the
largest model peak as Eq. 28 pins it, and the logged force's stated scale and offset accuracy, which `calibrate`
carries into its intervals), less penalties on a correlation beyond the job's limit and an interval wider than its
width limit (:func:`criterion`). The mean, not the worst case: the worst draw of log det is a different draw for
different designs and chases the least favourable corner; the limits, which must hold, take the worst case.

Search: every run of a grid of candidates (:meth:`DesignSettings.candidates`) and the job's own run (a coarse grid
may hold no run as informative: the design is then at least as good, by its criterion, as that run repeated) is
evaluated once (its information per draw; candidates that break a limit are dropped), then Fedorov's exchange picks the N runs with the largest
mean log det (the information of runs adds), then Nelder-Mead polishes all runs' continuous variables together
from there (a design that breaks a limit scores -inf). The single cushion test of the job is evaluated the same way
for the comparison.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize
from scipy.stats import qmc

from press_model.batch import evaluate_chunk, features
from press_io.errors import PressDataError
from press_model.forces import ProcessForce
from press_model.jobs import JOB_FORMAT, Job
from press_model.motion import ModulatedSpeed
from press_model.press_data import FieldReader
from press_model.torque_limits import TorqueLimits
from press_model.settings_fields import read_section, setting
from calibration.design.noise import NoiseLevel
from calibration.design.information import (DrawSets, ForceNoise, PeakPin, RunColumns, accuracy_factor, carried_covariance,
                                            contact_angle, draw_columns, draw_curves, draw_sets, filter_gain, filter_gain_key,
                                            fitted_points, force_noise_terms, per_standard_deviation, torque_per_newton)
from calibration.identification.process_force import FORCE_STEP
from calibration.design.run_family import RunFamily, run_family
from calibration.identification.problem import CalibrationProblem
from calibration.responses import y_tl


@dataclass(frozen=True)
class Run:
    """One calibration run: crank motion and cushion setting (units in the names)."""

    strokes_per_min: float
    speed_depth: float  # 0: constant speed
    slow_angle_deg: float  # crank angle of the slowest speed
    cushion_force_N: float  # 0: no cushion
    cushion_stroke_m: float  # the cushion acts below this slide height (m above BDC) while the slide moves down

    def motion(self) -> ModulatedSpeed:
        return ModulatedSpeed.from_spm(self.strokes_per_min, self.speed_depth, math.radians(self.slow_angle_deg))

    def process(self) -> ProcessForce | None:
        """The cushion as a job's process force (Eq. 14), None without one."""
        if self.cushion_force_N <= 0.0:
            return None
        return ProcessForce(self.cushion_stroke_m, (self.cushion_stroke_m, 0.0), (self.cushion_force_N, self.cushion_force_N))

    def vector(self) -> np.ndarray:
        return np.array([self.strokes_per_min, self.speed_depth, self.slow_angle_deg, self.cushion_force_N, self.cushion_stroke_m])

    def record(self) -> dict:
        return {"strokes_per_min": self.strokes_per_min, "speed_depth": self.speed_depth, "slow_angle_deg": self.slow_angle_deg,
                "cushion_force_N": self.cushion_force_N, "cushion_stroke_m": self.cushion_stroke_m}


DEFAULT_FEEDBACK_RESERVE = 0.01  # the planner's (door_panel.toml [planning.limits] feedback_reserve); reason in DesignSection
DENSE_STEP_DEG = 0.25  # deg: the 1-deg grid's knots and 1/4, 1/2, 3/4 of each step, the planner's check points
MAX_TIGHTENINGS = 4  # re-searches with a tightened grid limit before a design is refused


def _read_rates(rd: FieldReader, path: tuple, default: tuple) -> tuple[float, float]:
    """[lowest, highest] strokes per minute of a run; ``default`` when absent."""
    spm = rd.node(path, required=False)
    if spm is None:
        return default
    if not isinstance(spm, list) or len(spm) != 2:
        rd.fail(path, spm, "must be [lowest, highest] strokes per minute of a run, e.g. [4.0, 16.0]")
    lo = rd.number((*path, 0), gt=0.0, unit="1/min", limit="max_strokes_per_min")
    hi = rd.number((*path, 1), gt=0.0, unit="1/min", limit="max_strokes_per_min")
    if hi < lo:
        rd.fail(path, spm, "must list the lowest rate first")
    return (lo, hi)


_PERIOD = dict(unit="s", limit="min_sample_time_s", what="any press controller's period")


@dataclass(frozen=True)
class DesignSection:
    """The choices of a job's [design] table (what the cushion can do and what the calibration measured are the job's
    own: :meth:`DesignSettings.from_job`); [design.playback] is planning.settings.PlaybackSection."""

    runs: int = setting(2, "", "two runs (--runs overrides)", ge=1, limit="max_runs", what="what a calibration experiment needs")
    strokes_per_min: tuple = setting((4.0, 16.0), "1/min", "stroke-rate range of a run (continuous rotation)", read=_read_rates)
    max_speed_depth: float = setting(0.7, "", "deepest speed modulation k (1 - depth cos(theta - slow angle)); 0 is "
                                     "constant speed", ge=0.0, lt=1.0)
    cushion_min_stroke_m: float = setting(0.05, "m", "the shortest cushion stroke a run may use", gt=0.0, unit="m",
                                          limit="max_length_m")
    peak_torque_margin: float = setting(0.9, "fraction of T_max", "as the planner (paper Section 4.3), for every "
                                        "parameter draw", gt=0.0, le=1.0)
    feedback_reserve: float = setting(DEFAULT_FEEDBACK_RESERVE, "fraction of T_max", "as the planner: a designed run is played "
                                      "as a plan is, its model torque the feed-forward and a PD on top ([design.playback]), so "
                                      "its model torque leaves the feedback the same share below the margin", ge=0.0, lt=0.5)
    thermal_margin: float = setting(1.0, "fraction of T_rated", "RMS torque of a run (Eq. 24) at most this share of the "
                                    "rated torque, for every draw", gt=0.0, le=1.0)
    speed_margin: float = setting(1.0, "fraction of the top speed", "motor speed at most this share of its maximum",
                                  gt=0.0, le=1.0)
    draws: int = setting(4, "", "parameter sets the criterion is averaged over (the theoretical values and 3 "
                         "Latin-hypercube points of the ranges); the limits hold for all", ge=1)
    seed: int = setting(0, "", "seed of those draws", ge=0, limit=None)
    grid_levels: int = setting(3, "", "candidate values of rate, depth, force and stroke (lowest, middle, highest)", ge=2)
    grid_phases: int = setting(6, "", "candidate slow angles, every 60 deg", ge=1)
    polish_evaluations: int = setting(300, "", "Nelder-Mead evaluations of the designs' continuous variables after the "
                                      "exchange", ge=0)
    sample_time_s: float = setting(0.002, "s", "profile.csv sample time (as the door-panel plan)", gt=0.0, le=0.05, **_PERIOD)
    controller_period_s: float = setting(0.002, "s", "cam_table.csv sample time (as the door-panel plan)", gt=0.0,
                                         le=0.05, **_PERIOD)


@dataclass(frozen=True)
class DesignSettings:
    """The job's [design] table (SI units except as named)."""

    runs: int
    spm_low: float
    spm_high: float
    max_depth: float
    max_force: float  # N
    min_stroke: float  # m
    max_stroke: float  # m
    peak_torque_margin: float
    thermal_margin: float
    speed_margin: float
    noise_rms: float | None  # N m, the noise of the stroke-averaged curve; None: not in the job (then --calibrated gives it)
    noise_inflation: float | None  # the AR(1) factor of that noise (>= 1)
    draws: int
    seed: int
    grid_levels: int
    grid_phases: int
    polish_evaluations: int
    sample_time: float  # s
    controller_period: float  # s
    feedback_reserve: float = DEFAULT_FEEDBACK_RESERVE  # fraction of T_max left free below the margin for the feedback
    # N: the noise of one grid point of a run's stroke-averaged logged process force (the job's own measured figure,
    # calibrated.json process_force.logs[].noise_of_binned_point_N, as noise_rms_Nm is); 0: not given
    force_noise: float = 0.0

    def torque_limits(self, peak_torque: float) -> TorqueLimits:
        """The runs' peak-torque limits on a motor of T_max = ``peak_torque`` (N m): ``.feedforward`` = (peak_torque_margin
        - feedback_reserve) x T_max, what a run's model torque is held to, ``.verdict`` = peak_torque_margin x T_max."""
        return TorqueLimits(peak_torque, self.peak_torque_margin, self.feedback_reserve)

    @classmethod
    def from_job(cls, job: Job) -> "DesignSettings":
        """The job's [design] table: absent choices take :class:`DesignSection`'s defaults; what the cushion can do
        (cushion_max_force_N, cushion_max_stroke_m) are the job's own and required; what the job's calibration measured
        (noise_rms_Nm, noise_inflation) is the job's own too, None when absent (:meth:`noise` then needs a
        calibrated.json). The residual's keys of schema 2 (residual_rms_Nm, covariance_inflation) are refused with the
        fix: a schema-2 file has them dropped with a note (press_model/schema.py)."""
        if job.raw.get("design") is None:
            raise PressDataError(job.source, "design", None, "is missing: a job needs a [design] table to design calibration runs "
                                 "(see press_model/data/cushion_test.toml)")
        rd = FieldReader(job.source, {"design": job.raw["design"]})
        d = ("design",)
        if rd.node((*d, "playback"), required=False) is not None:
            rd.delegate((*d, "playback"))  # read by planning.playback
        for old, new in (("residual_rms_Nm", "noise_rms_Nm"), ("covariance_inflation", "noise_inflation")):
            if rd.node((*d, old), required=False) is not None:
                rd.fail((*d, old), job.raw["design"][old], f"is no longer read: it was a first calibration's residual (mostly "
                        f"model misfit), and the design needs the noise of the stroke-averaged curve: set [design] {new} "
                        "from calibrated.json's adequacy.pure_error_rms_Nm and pure_error_lag1 (press_model/README.md "
                        "\"Schema\"), or give design-experiment --calibrated calibrated.json")
        x = read_section(rd, d, DesignSection)
        s = cls(
            runs=x.runs,
            spm_low=x.strokes_per_min[0], spm_high=x.strokes_per_min[1],
            max_depth=x.max_speed_depth,
            max_force=rd.number((*d, "cushion_max_force_N"), ge=0.0, unit="N", limit="max_process_force_N"),
            min_stroke=x.cushion_min_stroke_m,
            max_stroke=rd.number((*d, "cushion_max_stroke_m"), gt=0.0, unit="m", limit="max_length_m"),
            peak_torque_margin=x.peak_torque_margin,
            thermal_margin=x.thermal_margin,
            speed_margin=x.speed_margin,
            noise_rms=(rd.number((*d, "noise_rms_Nm"), gt=0.0, unit="N m")
                       if rd.node((*d, "noise_rms_Nm"), required=False) is not None else None),
            noise_inflation=(rd.number((*d, "noise_inflation"), ge=1.0)
                             if rd.node((*d, "noise_inflation"), required=False) is not None else None),
            force_noise=(rd.number((*d, "force_noise_N"), ge=0.0, unit="N", limit="max_process_force_N")
                         if rd.node((*d, "force_noise_N"), required=False) is not None else 0.0),
            draws=x.draws,
            seed=x.seed,
            grid_levels=x.grid_levels,
            grid_phases=x.grid_phases,
            polish_evaluations=x.polish_evaluations,
            sample_time=x.sample_time_s,
            controller_period=x.controller_period_s,
            feedback_reserve=x.feedback_reserve,
        )
        if s.feedback_reserve >= s.peak_torque_margin:
            rd.fail((*d, "feedback_reserve"), s.feedback_reserve, f"must be below peak_torque_margin = {s.peak_torque_margin:g}: "
                    "the runs' feed-forward is held to (peak_torque_margin - feedback_reserve) x T_max")
        if s.max_stroke < s.min_stroke:
            rd.fail((*d, "cushion_max_stroke_m"), s.max_stroke, f"must be at least cushion_min_stroke_m = {s.min_stroke}")
        rd.reject_unread(JOB_FORMAT)
        return s

    def noise(self, source: str) -> NoiseLevel:
        """The job's noise level (:class:`calibration.design.noise.NoiseLevel`); a one-line error naming the missing key
        when the job (``source``) lacks one."""
        for key, v in (("noise_rms_Nm", self.noise_rms), ("noise_inflation", self.noise_inflation)):
            if v is None:
                raise PressDataError(source, f"design.{key}", None, "is missing: the design predicts intervals for the noise a "
                                     "first calibration measured: give design-experiment --calibrated calibrated.json, or "
                                     "set [design] noise_rms_Nm and noise_inflation from its adequacy.pure_error_rms_Nm "
                                     "and pure_error_lag1")
        return NoiseLevel(self.noise_rms, self.noise_inflation, f"{source} [design] noise_rms_Nm, noise_inflation and "
                          f"force_noise_N{' (not given: 0)' if not self.force_noise else ''}", force_noise_N=self.force_noise)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of a run's vector (:meth:`Run.vector`); the phase is periodic, bounded for the search only."""
        return (np.array([self.spm_low, 0.0, 0.0, 0.0, self.min_stroke]),
                np.array([self.spm_high, self.max_depth, 360.0, self.max_force, self.max_stroke]))

    def candidates(self) -> list[Run]:
        """The grid of candidate runs: grid_levels values of rate, depth, force and stroke, grid_phases slow angles
        (one phase at zero depth, one stroke at zero force)."""
        g = self.grid_levels
        spms = np.linspace(self.spm_low, self.spm_high, g)
        depths = np.linspace(0.0, self.max_depth, g)
        phases = np.arange(self.grid_phases) * 360.0 / self.grid_phases
        forces = np.linspace(0.0, self.max_force, g)
        strokes = np.linspace(self.min_stroke, self.max_stroke, g)
        out = []
        for s in spms:
            for d in depths:
                for ph in (phases if d > 0 else phases[:1]):
                    for f in forces:
                        for h in (strokes if f > 0 else strokes[-1:]):
                            out.append(Run(float(s), float(d), float(ph), float(f), float(h)))
        return out


def parameter_draws(problem: CalibrationProblem, draws: int, seed: int) -> np.ndarray:
    """(draws, k): the theoretical values, then draws - 1 points of a scrambled Latin hypercube over the calibration ranges."""
    if draws == 1:
        return problem.theoretical[None].copy()
    u = qmc.LatinHypercube(d=len(problem.names), seed=seed).random(draws - 1)
    return np.vstack([problem.theoretical, problem.low + u * (problem.high - problem.low)])


@dataclass(frozen=True)
class RunCheck:
    """A run under every draw: its information per draw and the motor's figures (worst over the draws)."""

    run: Run
    info: np.ndarray | None  # (draws, k + 2, k + 2); None: screened out (:meth:`Evaluator.check`), not computed
    peak_torque: float  # N m per motor
    rms_torque: float  # N m, Eq. 24
    max_motor_speed: float  # rad/s
    feasible: bool
    points: int  # grid points the fit compares (outside the die-contact window)
    columns: RunColumns | None  # at the theoretical values (draw 0); None: screened out
    dense_peak_torque: float | None = None  # N m per motor, worst draw on the dense points (chosen runs only)
    # E (draws, k + 2, 2) and peak (draws, 2): what the normal equations and the run's model peak gain per standard
    # deviation of the logged force's stated scale and offset error (:func:`accuracy_terms`), one error of all runs'
    # logs; None: no logged force (or its accuracy not carried)
    accuracy: ForceNoise | None = None
    # per draw the model's peak |torque| (N m) over the fitted points and its pin (rows (draws, k + 2), sigma (draws,)):
    # the run with the largest pins Eq. 28's estimate (calibration/design/report.py peak_pin); None: not pinned
    peak: tuple[np.ndarray, PeakPin] | None = None


@dataclass
class Evaluator:
    """Evaluates runs of one press, job settings and calibrated parameters; counts model cycles."""

    family: RunFamily
    problem: CalibrationProblem
    settings: DesignSettings
    draws: np.ndarray
    correlation_limit: float = 0.9
    nuisance: bool = True
    cycles: int = 0
    dense_family: RunFamily | None = None  # the 0.25-deg family the chosen runs are checked on (built on first use)
    grid_limit: float | None = None  # N m: the peak limit on the family's grid (None: the feed-forward limit)
    _memo: dict = field(default_factory=dict)
    _draw_sets: DrawSets | None = None
    noise: NoiseLevel | None = None  # what the information is weighed with (None: the job's [design] keys)
    window_s: float = 0.0  # s after die contact whose points the fit leaves out (`calibrate`'s peak window; 0: none)
    # [calibration.process_force]: the logged force's stated accuracy the criterion carries, as `calibrate` carries it
    # (None: the force taken as exact)
    force_accuracy: object | None = None
    # ([calibration] peak_filter_window_deg, peak_filter_order): the criterion pins the estimate at the largest model
    # peak as Eq. 28 does, with the noise that filter leaves in the measured peak (None: not pinned)
    peak_filter: tuple | None = None
    # (the job's [calibration] interval_width_limit, the interval's quantile): the criterion penalises a predicted
    # interval wider than the limit, as it does a correlation beyond its limit (None: not)
    width_limit: tuple | None = None
    _gains: dict = field(default_factory=dict)

    @property
    def variance(self) -> float:
        """s^2 c of one grid point (:class:`calibration.design.noise.NoiseLevel`), N^2 m^2."""
        return (self.noise or self.settings.noise("the job")).variance

    def _sets(self, bm) -> DrawSets:
        """The draws' parameter sets with their features, made once for the press of ``bm``."""
        if self._draw_sets is None or self._draw_sets.bodies is not bm.bodies:
            self._draw_sets = draw_sets(bm, self.problem, self.draws)
        return self._draw_sets

    @property
    def peak_limit(self) -> float:
        """The peak limit (N m per motor) the runs are checked against on the family's grid: the feed-forward limit,
        or less once a chosen run broke it on the dense points (:func:`search`)."""
        lim = self.settings.torque_limits(self.family.press.motor.peak_torque).feedforward
        return lim if self.grid_limit is None else min(lim, self.grid_limit)

    def _feasible(self, rc: RunCheck) -> bool:
        s, motor = self.settings, self.family.press.motor
        return (rc.peak_torque <= self.peak_limit and rc.rms_torque <= s.thermal_margin * motor.rated_torque
                and rc.max_motor_speed <= s.speed_margin * motor.max_speed)

    def check(self, run: Run, screen: bool = False) -> RunCheck:
        """The :class:`RunCheck` of ``run`` (remembered), feasible against the limits as they are now. With ``screen`` (the
        search's candidates), a run first seen breaking a limit on its draws' curves is screened out: its information is
        not computed (``info`` None; the criterion never reads an infeasible run's) until a caller without ``screen``
        asks for it or a later, looser limit makes the run feasible."""
        key = tuple(np.round(run.vector(), 9))
        rc = self._memo.get(key)
        if rc is None or (rc.info is None and (not screen or self._feasible(rc))):
            forces = [run.cushion_force_N]
            if run.cushion_force_N > 0.0 and self.force_accuracy is not None:  # and the force a step higher (check_model)
                forces.append(run.cushion_force_N * (1.0 + FORCE_STEP))
            bm, *more = self.family.models(run.motion(), forces, run.cushion_stroke_m)
            first = self._screen(run, bm)
            if screen and rc is None and not first[0].feasible:
                rc = first[0]
            else:
                rc = self.check_model(run, bm, more=more[0] if more else None, screen=first)
            self._memo[key] = rc
        ok = self._feasible(rc)
        return rc if rc.feasible == ok else dataclasses.replace(rc, feasible=ok)

    def dense_peak(self, run: Run) -> float:
        """Peak |motor torque| (N m per motor) of ``run`` over every draw on the dense points (:data:`DENSE_STEP_DEG`):
        the grid's knots and 1/4, 1/2, 3/4 of each of its steps, where `plan` checks its limits."""
        if self.dense_family is None:
            self.dense_family = run_family(self.family.press, self.family.pm, DENSE_STEP_DEG)
        bm = self.dense_family.model(run.motion(), run.cushion_force_N, run.cushion_stroke_m)
        X = self.problem.full_sets(bm, self.draws)
        self.cycles += len(X)
        return float(np.max(np.abs(evaluate_chunk(bm, X, feats=features(bm, X)).motor_torque)))

    def _screen(self, run: Run, bm) -> tuple[RunCheck, dict]:
        """``run`` on its batch model ``bm`` with the draws' curves alone: its :class:`RunCheck` with the motor's figures
        (worst over the draws) and no information (``info`` None), and the draws' crank torques for :meth:`check_model`
        (:func:`calibration.design.information.draw_cranks`' ``known``)."""
        sets = self._sets(bm)
        known: dict = {}
        curves = np.ascontiguousarray(draw_curves(bm, sets, known))  # rows contiguous: y_tl sums each as it sums one curve
        self.cycles += len(curves)
        peak = float(np.max(np.abs(curves)))
        rms = float(np.max(y_tl(curves, bm.theta_dot)))
        speed = float(np.max(bm.theta_dot)) * bm.gear_ratio
        rc = RunCheck(run, None, peak, rms, speed, False, 0, None)
        return dataclasses.replace(rc, feasible=self._feasible(rc)), known

    def check_model(self, run: Run, bm, motion=None, more=None, screen: tuple[RunCheck, dict] | None = None) -> RunCheck:
        """The :class:`RunCheck` of ``run`` on its batch model ``bm`` (from the family, or built directly on ``motion``,
        default the run's); its information over the points `calibrate` fits (outside the die-contact window). ``more``:
        the model with the run's process force :data:`FORCE_STEP` higher, of a run whose force is logged, for the stated
        accuracy's terms (:func:`accuracy_terms`); None: none. ``screen``: :meth:`_screen`'s of ``run`` on ``bm``, whose
        draws' curves this reuses (None: computed here)."""
        contact = contact_angle(bm.theta, bm.height, bm.height_dot, run.cushion_stroke_m) if run.cushion_force_N > 0.0 else None
        fitted = fitted_points(bm.theta, run.motion() if motion is None else motion, contact, self.window_s)
        sets = self._sets(bm)
        screen, known = screen or self._screen(run, bm)
        columns = draw_columns(bm, sets, known)
        self.cycles += len(columns) * 2 * len(self.problem.names)  # the Jacobian sets (the draws counted by the screen)
        variance = self.variance
        infos = np.array([cols.information(variance, self.nuisance, fitted) for cols in columns])
        curve = np.asarray(run.process()(bm.height, bm.height_dot), float) if run.cushion_force_N > 0.0 else np.zeros(bm.n_points)
        pins = self._peaks(columns, fitted, bm.theta, curve)
        accuracy = None
        if more is not None:
            more_T = draw_curves(more, sets)
            self.cycles += len(more_T)
            terms = [accuracy_terms(cols, fitted, variance, torque_per_newton(cols.torque, T, curve, FORCE_STEP), curve,
                                    self.force_accuracy, self.nuisance, None if pins is None else int(i))
                     for cols, T, i in zip(columns, more_T, np.zeros(len(columns), int) if pins is None else pins[2])]
            accuracy = ForceNoise(np.array([t.E for t in terms]), np.array([t.peak for t in terms]))
        rc = RunCheck(run, infos, screen.peak_torque, screen.rms_torque, screen.max_motor_speed, False, int(fitted.sum()),
                      columns[0], accuracy=accuracy, peak=None if pins is None else pins[:2])
        return dataclasses.replace(rc, feasible=self._feasible(rc))

    def _peaks(self, columns, fitted: np.ndarray, theta: np.ndarray, curve: np.ndarray):
        """Per draw the model's peak |torque| over the ``fitted`` points (N m), its :class:`PeakPin` (the signed [J Z] row
        there, the measured peak's noise: the grid point's times the peak filter's gain between the force ``curve``'s
        steps on the grid) and its grid index; None without :attr:`peak_filter`."""
        if self.peak_filter is None:
            return None
        loaded = curve != 0.0
        edges = np.flatnonzero(loaded != np.roll(loaded, 1))  # the force's steps, half a grid step before these points
        steps = sorted(float((theta[i] - 0.5 * (theta[1] - theta[0])) % (2.0 * math.pi)) for i in edges)
        values, rows, sigmas, idx = [], [], [], []
        for cols in columns:
            i = int(np.argmax(np.where(fitted, np.abs(cols.torque), -np.inf)))
            key = filter_gain_key(theta, steps, i, *self.peak_filter)
            if key not in self._gains:
                self._gains[key] = filter_gain(theta, steps, i, *self.peak_filter)
            values.append(abs(float(cols.torque[i])))
            rows.append(math.copysign(1.0, float(cols.torque[i])) * np.concatenate([cols.J[i], cols.Z[i]]))
            sigmas.append(math.sqrt(self.variance) * self._gains[key])
            idx.append(i)
        return np.array(values), PeakPin(np.array(rows), np.array(sigmas)), np.array(idx)

    def score(self, checks: list[RunCheck]) -> float:
        """:func:`criterion` of the runs together (:class:`RunStack`); -inf if a run breaks a limit."""
        if not all(c.feasible for c in checks):
            return -math.inf
        F, pin, acc = RunStack.of(checks).together(range(len(checks)))
        return float(criterion(F[None], len(self.problem.names), self.correlation_limit, _first(pin), _first(acc),
                               self.width_limit)[0])


def _first(x):
    """A pin or force error with a leading axis of one (``x`` None: None)."""
    if x is None:
        return None
    return dataclasses.replace(x, **{f.name: np.asarray(getattr(x, f.name))[None] for f in dataclasses.fields(x)})


def accuracy_terms(cols: RunColumns, fitted: np.ndarray, variance_Nm2: float, per_newton: np.ndarray, curve: np.ndarray,
                   st, nuisance: bool, peak_point: int | None) -> ForceNoise:
    """What the least-squares normal equations of a run (its scaled ``cols`` on the ``fitted`` points, noise variance
    s^2 c; E (m, 2)) and its model peak at grid point ``peak_point`` (peak (2,); None: zeros) gain per standard deviation
    of the logged force's stated scale and offset error (``st``: [calibration.process_force]), the model torque gaining
    ``per_newton`` (n,) N m / N of its force ``curve`` (n,) N: the steps of
    :func:`calibration.design.information.accuracy_factor` made standard deviations by the rule `calibrate` widens with
    (:func:`calibration.design.information.per_standard_deviation`)."""
    factor = accuracy_factor(curve)
    E = force_noise_terms(cols, fitted, variance_Nm2, per_newton, factor, nuisance)
    peak = np.zeros(2) if peak_point is None else per_newton[peak_point] * factor[peak_point]
    return per_standard_deviation(ForceNoise(E, peak), st)


@dataclass(frozen=True)
class RunStack:
    """Candidate runs' terms of the criterion, stacked: ``info`` (C, D, m, m), the logged force's accuracy ``E`` (C, D, m, W)
    and ``acc_peak`` (C, D, W) (zeros for a run without it), each run's model ``peak`` (C, D) N m (-inf: not pinned),
    its pin's ``rows`` (C, D, m) and ``sigma`` (C, D)."""

    info: np.ndarray
    E: np.ndarray
    acc_peak: np.ndarray
    peak: np.ndarray
    rows: np.ndarray
    sigma: np.ndarray

    @classmethod
    def plain(cls, infos: np.ndarray) -> "RunStack":
        """Candidates of information ``infos`` (C, D, m, m) alone: no logged force, not pinned."""
        C, D, m, _ = infos.shape
        return cls(infos, np.zeros((C, D, m, 2)), np.zeros((C, D, 2)), np.full((C, D), -np.inf), np.zeros((C, D, m)),
                   np.zeros((C, D)))

    @classmethod
    def of(cls, checks) -> "RunStack":
        """The terms of the :class:`RunCheck` s ``checks`` (their draws alike)."""
        D, m = checks[0].info.shape[:2]
        acc = [c.accuracy for c in checks]
        pinned = [c.peak for c in checks]
        return cls(np.array([c.info for c in checks]),
                   np.array([a.E if a is not None else np.zeros((D, m, 2)) for a in acc]),
                   np.array([a.peak if a is not None else np.zeros((D, 2)) for a in acc]),
                   np.array([p[0] if p is not None else np.full(D, -np.inf) for p in pinned]),
                   np.array([p[1].row if p is not None else np.zeros((D, m)) for p in pinned]),
                   np.array([p[1].sigma_Nm if p is not None else np.zeros(D) for p in pinned]))

    def together(self, idx, extra: "RunStack | None" = None):
        """(F (..., D, m, m), :class:`PeakPin` or None, :class:`ForceNoise`) of the runs ``idx`` fitted together: the
        information and accuracy terms add, the run with the largest model peak pins (per draw); with ``extra``, of
        those runs and each of ``extra``'s candidates in turn (a leading axis of len(extra))."""
        idx = list(idx)
        D, m = self.info.shape[1:3]
        F = sum((self.info[i] for i in idx), np.zeros((D, m, m)))
        E = sum((self.E[i] for i in idx), np.zeros(self.E.shape[1:]))
        top = np.full(D, -np.inf)
        rows, sigma, ap = np.zeros((D, m)), np.zeros(D), np.zeros(self.acc_peak.shape[1:])
        for i in idx:
            win = self.peak[i] > top
            top = np.where(win, self.peak[i], top)
            rows, sigma = np.where(win[:, None], self.rows[i], rows), np.where(win, self.sigma[i], sigma)
            ap = np.where(win[:, None], self.acc_peak[i], ap)
        if extra is not None:
            win = extra.peak > top[None]
            F, E = F[None] + extra.info, E[None] + extra.E
            rows, sigma = np.where(win[..., None], extra.rows, rows[None]), np.where(win, extra.sigma, sigma[None])
            ap, top = np.where(win[..., None], extra.acc_peak, ap[None]), np.maximum(top[None], extra.peak)
        pin = PeakPin(rows, sigma) if np.all(np.isfinite(top)) else None
        return F, pin, ForceNoise(E, ap)


def exchange(stack: RunStack, n_runs: int, k: int, correlation_limit: float, max_passes: int = 20,
             width_limit: tuple | None = None) -> list[int]:
    """Fedorov's exchange on the candidates ``stack`` (:class:`RunStack`): the indices (repeats allowed) of ``n_runs``
    candidates with the largest :func:`criterion` (``width_limit`` its) together. Starts greedily (a small ridge makes
    the first sums invertible), then replaces one run at a time by the best candidate until no exchange improves."""
    infos = stack.info
    C, D, m, _ = infos.shape
    ridge = 1e-9 * np.trace(infos.mean(axis=(0, 1))) / m * np.eye(m)

    def crit(rest, ridged=False):  # the runs ``rest`` with each candidate -> (C,)
        F, pin, acc = stack.together(rest, stack)
        return criterion(F + (ridge if ridged else 0.0), k, correlation_limit, pin, acc, width_limit)

    chosen: list[int] = []
    for _ in range(n_runs):
        chosen.append(int(np.argmax(crit(chosen, ridged=True))))
    F0, pin0, acc0 = stack.together(chosen)
    best = float(criterion(F0[None], k, correlation_limit, _first(pin0), _first(acc0), width_limit)[0])
    for _ in range(max_passes):
        improved = False
        for pos in range(n_runs):
            vals = crit([i for j, i in enumerate(chosen) if j != pos])
            i = int(np.argmax(vals))
            if vals[i] > best + 1e-9:
                chosen[pos], best, improved = i, float(vals[i]), True
        if not improved:
            break
    return chosen


CORRELATION_PENALTY = 1000.0  # log det units per unit of |correlation| above the limit: any excess outweighs any volume
WIDTH_PENALTY = 1000.0  # log det units per calibration range of the widest interval above the width limit: likewise


def criterion(F: np.ndarray, k: int, correlation_limit: float, pin: PeakPin | None = None,
              accuracy: ForceNoise | None = None, width_limit: tuple | None = None) -> np.ndarray:
    """The design criterion of information stacks F (C, draws, m, m) -> (C,): the mean over the draws of log det C^-1,
    less CORRELATION_PENALTY x the mean excess of the largest |correlation| of the k parameters' estimates over
    ``correlation_limit`` (the job's [calibration] correlation_limit). C is the covariance the prediction reports
    (:func:`calibration.design.information.carried_covariance`): F^-1, its model peak pinned (``pin``, rows (C, draws, m)),
    plus what the logged force's stated accuracy adds (``accuracy``, E (C, draws, m, W) and peak (C, draws, W) per
    standard deviation of each error: a nuisance with its prior that the fit does not estimate). Without the accuracy
    the search preferred runs whose force sets a parameter the force's scale moves as much (mu_s on a crank-slider).
    D-optimality alone shrinks the joint confidence region and can leave two parameters as correlated as before (psi
    and m8 on the reference press); the penalty makes every pair separable where a design can, and the largest volume
    among those. ``width_limit`` (the job's interval_width_limit, a share of the calibration range, and the interval's
    quantile): likewise less WIDTH_PENALTY x the mean excess of the widest predicted interval over that share. The
    volume alone trades one parameter's interval for the others' (on the edited crank-slider it chose runs that left
    mu_s over its whole range and every other interval a few per cent wide); the penalty narrows the widest first where
    no design keeps every interval within the limit."""
    ok = np.linalg.slogdet(F)[0] > 0
    cov = carried_covariance(F, k, pin, accuracy)
    sign, val = np.linalg.slogdet(cov)
    ld = np.where(ok & (sign > 0), -val, -np.inf)
    d = np.sqrt(np.clip(np.diagonal(cov, axis1=-2, axis2=-1)[..., :k], 1e-300, None))
    corr = cov[..., :k, :k] / (d[..., :, None] * d[..., None, :])
    off = np.abs(corr) * (1.0 - np.eye(k))
    excess = np.clip(off.max(axis=(-2, -1)) - correlation_limit, 0.0, None) if k > 1 else np.zeros(ld.shape)
    wide = np.zeros(ld.shape)
    if width_limit is not None:
        limit, q = width_limit
        wide = np.clip(2.0 * q * d.max(axis=-1) - limit, 0.0, None)  # d: standard errors as shares of the ranges
    return np.mean(ld - CORRELATION_PENALTY * excess - WIDTH_PENALTY * wide, axis=-1)


@dataclass(frozen=True)
class DesignResult:
    runs: tuple[RunCheck, ...]
    score: float  # mean log det
    candidates: int
    feasible_candidates: int
    cycles: int


def search(ev: Evaluator, n_runs: int, also: tuple[Run, ...] = ()) -> DesignResult:
    """The design of ``n_runs`` runs (:func:`search_grid`, ``also`` candidates beside the grid's) whose every run keeps
    the feed-forward limit on the dense points too: where a chosen run's dense peak breaks it, the grid's limit is
    lowered by that excess (the ratio of the limit to the dense peak) and the search repeated, at most
    :data:`MAX_TIGHTENINGS` times, then refused."""
    limit = ev.settings.torque_limits(ev.family.press.motor.peak_torque).feedforward
    try:
        for _ in range(MAX_TIGHTENINGS + 1):
            res = search_grid(ev, n_runs, also)
            dense = [ev.dense_peak(c.run) for c in res.runs]
            runs = tuple(dataclasses.replace(c, dense_peak_torque=d) for c, d in zip(res.runs, dense))
            res = dataclasses.replace(res, runs=runs, cycles=ev.cycles)
            worst = max(dense)
            if worst <= limit:
                return res
            ev.grid_limit = ev.peak_limit * limit / worst
    finally:
        ev.grid_limit = None  # later checks (the job's own run) are against the feed-forward limit itself
    raise PressDataError("[design]", "peak_torque_margin", ev.settings.peak_torque_margin,
                         f"no design keeps the runs' feed-forward within {limit:,.0f} N m per motor on the dense check points "
                         f"after {MAX_TIGHTENINGS} tightenings (worst {worst:,.0f} N m): lower [design] cushion_max_force_N or the "
                         "stroke-rate range")


def search_grid(ev: Evaluator, n_runs: int, also: tuple[Run, ...] = ()) -> DesignResult:
    """The exchange over the candidate grid and the runs ``also`` that lie within the [design] bounds (the job's own run:
    so the design is at least as informative, by the criterion, as that run repeated), then the Nelder-Mead polish
    (module docstring), the limits checked on the family's grid against :attr:`Evaluator.peak_limit`."""
    s = ev.settings
    lo, hi = s.bounds()
    inside = [r for r in also if np.all((r.vector() >= lo - 1e-9) & (r.vector() <= hi + 1e-9))]
    checks = [ev.check(r, screen=True) for r in (*s.candidates(), *inside)]
    ok = [c for c in checks if c.feasible]
    if not ok:
        raise PressDataError("[design]", "candidate runs", len(checks),
                             "none of the candidate runs keeps the motor within its limits for every parameter draw: "
                             "lower [design] cushion_max_force_N or the stroke-rate range, or raise the margins")
    idx = exchange(RunStack.of(ok), n_runs, len(ev.problem.names), ev.correlation_limit, width_limit=ev.width_limit)
    start = [ok[i] for i in idx]
    span = np.where(hi > lo, hi - lo, 1.0)

    def runs_of(z):
        v = np.clip(lo + z.reshape(n_runs, -1) * span, lo, hi)
        return [Run(*map(float, row)) for row in v]

    def f(z):
        if np.any(z < -1e-9) or np.any(z > 1.0 + 1e-9):
            return math.inf
        sc = ev.score([ev.check(r, screen=True) for r in runs_of(z)])
        return -sc if np.isfinite(sc) else math.inf

    z0 = np.concatenate([(c.run.vector() - lo) / span for c in start])
    best = [ev.check(r) for r in runs_of(z0)]
    if s.polish_evaluations > 0:
        res = minimize(f, z0, method="Nelder-Mead", options={"maxfev": s.polish_evaluations, "xatol": 1e-3, "fatol": 1e-4,
                                                             "initial_simplex": _simplex(z0, 0.05)})
        if np.isfinite(res.fun) and -res.fun > ev.score(best):
            best = [ev.check(r) for r in runs_of(res.x)]
    return DesignResult(tuple(best), ev.score(best), len(checks), len(ok), ev.cycles)


def _simplex(z0: np.ndarray, step: float) -> np.ndarray:
    """A starting simplex of steps ``step`` (a share of each bound range) inward from z0."""
    S = np.tile(z0, (len(z0) + 1, 1))
    for i in range(len(z0)):
        S[i + 1, i] += step if z0[i] + step <= 1.0 else -step
    return S
