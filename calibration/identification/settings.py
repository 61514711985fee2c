"""The [calibration] table of a job file: what to calibrate, Eq. 28's weight, and the optimisers' settings.

Each table is a settings dataclass whose defaults are the cushion-test job's values, with unit and reason
(:data:`SECTIONS`); a job gives ``parameters`` (the key parameters of its press) and what differs.
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass

from press_io.errors import PressDataError
from press_model.jobs import JOB_FORMAT, Job
from press_model.readers import FieldReader
from press_model.settings_fields import read_section, setting

from calibration.identification.aco import AcoSettings
from calibration.identification.methods import METHODS
from calibration.identification.process_force import ProcessForceSettings


def _read_orders(rd: FieldReader, path: tuple, default: tuple) -> tuple[float, ...]:
    """Torque-ripple orders per motor turn: a list of positive numbers ([] tests none); ``default`` when absent."""
    orders = rd.node(path, required=False)
    if orders is None:
        return default
    if not isinstance(orders, list) or not all(isinstance(q, (int, float)) and not isinstance(q, bool) and q > 0 for q in orders):
        rd.fail(path, orders, "must be a list of positive numbers (ripple periods per motor revolution), e.g. [6]; [] tests none")
    return tuple(float(q) for q in orders)


@dataclass(frozen=True)
class CalibrationSection:
    """The plain keys of [calibration] (``parameters``, the press's key parameters, is the job's own: --parameters or it)."""

    weight: float = setting(0.3, "", "Eq. 28's w, the paper's value", ge=0.0, le=1.0)
    default_method: str = setting("aco", "", "the paper's ant colony with its polish: the lowest Eq. 28 of the three "
                                  "methods in 5,500 model cycles, DE needs 18,090 (scripts/bench_calibration.py)", choices=METHODS)
    peak_window_after_contact_s: float = setting(0.15, "s", "peaks (Eq. 23) compared once the die-contact ringing has died "
                                                 "out (5 decay times of ~0.03 s); the rigid-body model has no impact term",
                                                 ge=0.0, unit="s")
    speed_harmonics: int = setting(0, "", "0: the crank speed and acceleration by local polynomial fits of the logged "
                                   "speed samples, each window as wide as the log's own speed noise allows "
                                   "([calibration.speed], calibration/identification/speed_fit.py); N: a Fourier series of N "
                                   "harmonics (a fixed 24 cut off a two-speed motion's changes of speed and called clean logs NOT "
                                   "ADEQUATE; a series, however long, misses the acceleration where a ramp ends)", ge=0)
    interval_level: float = setting(0.95, "", "confidence level of the reported parameter intervals", gt=0.0, lt=1.0)
    correlation_limit: float = setting(0.9, "", "|correlation| above this: the experiment cannot tell two parameters apart",
                                       gt=0.0, lt=1.0)
    interval_width_limit: float = setting(0.5, "fraction of the range", "an interval wider than half the calibration range "
                                          "is poorly identified", gt=0.0)
    peak_filter_window_deg: float = setting(21.0, "deg", "Savitzky-Golay window of the measured peak (calibration/identification/peak.py): "
                                            "cuts the synthetic log's noise-max bias from +67 to -1.5 N m", gt=0.0, lt=180.0,
                                            unit="deg")
    peak_filter_order: int = setting(3, "", "cubic local fit: keeps a smooth peak's height (a moving mean flattens it)", ge=0)
    peak_ringing_fit: bool = setting(True, "", "the die-contact ringing is fitted in the log (a damped oscillation after contact, its "
                                     "frequency and decay read from the log) and removed before the peak filter, whose window "
                                     "reaches into the die-contact window when the peak lies just after it "
                                     "(calibration/identification/peak.py fit_ringing)")
    peak_noise_ratio_warning: float = setting(10.0, "", "a note (no warning: the intervals carry the peak's noise, "
                                              "calibration/identification/peak_noise.py) when |Y_PR,0| x peak < this x the noise left "
                                              "in the filtered peak: the peak term's normalisation then moves by more than a tenth "
                                              "with the noise", ge=0.0)


@dataclass(frozen=True)
class SpeedSection:
    """[calibration.speed]: the crank motion of a log by local polynomial fits of its speed samples
    (calibration/identification/speed_fit.py; ``speed_harmonics`` = 0)."""

    window_min_samples: int = setting(6, "samples", "the narrowest window holds samples at this many distinct angles: twice the local "
                                      "quadratic's three coefficients", ge=3)
    duplicate_step_fraction: float = setting(0.01, "of a sampling step", "samples of two strokes closer than this count as "
                                             "one angle for the narrowest window (strokes of a whole number of sampling "
                                             "periods repeat their angles to 1e-5 of a step; interleaved ones lie a third of "
                                             "a step or more apart)", gt=0.0, lt=1.0, unit="of a sampling step")
    window_ratio: float = setting(1.414, "", "each wider window's half-width over the last's: sqrt(2), the ladder of the "
                                  "intersection-of-confidence-intervals rule (a finer one only tests more windows)", gt=1.0)
    estimate_degree: int = setting(3, "", "degree of the local polynomial whose value and slope are taken at the window the "
                                   "quadratic's test chose: in a symmetric window the cubic holds the speed's third "
                                   "derivative, the leading bias of the quadratic's slope, which that test lets through "
                                   "at some 20-40 standard errors (speed_fit.py); above 5 a local fit of a few samples only follows the noise", ge=2, le=5)
    noise_trim: float = setting(0.01, "", "share of the largest third differences the speed-noise estimate leaves out: the "
                                "few samples where a sharp ramp's jerk jumps (4 ramp ends of a two-speed motion hold "
                                "well under 1 % of a log's samples)", ge=0.0, lt=0.5)


@dataclass(frozen=True)
class BootstrapSection:
    """[calibration.bootstrap]: the parametric bootstrap of the intervals (calibration/identification/bootstrap.py); its optional
    ``allowance`` table (parameter = fraction of its range) is read apart."""

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


@dataclass(frozen=True)
class AdequacySection:
    """[calibration.adequacy]: is the calibrated model adequate for the log (calibration/identification/adequacy.py)."""

    level: float = setting(0.01, "", "chance of a false \"not adequate\" on an adequate log, shared by Bonferroni over "
                           "its tests", gt=0.0, lt=0.5)
    ripple_orders_per_motor_turn: tuple = setting((6.0,), "1/motor turn", "torque ripple orders tested: 6 per period is the "
                                                  "classic ripple of a three-phase drive (put your motor's)", read=_read_orders)


@dataclass(frozen=True)
class RecordingSection:
    """[calibration.recording]: the recording's channel delay, encoder offset and lost motion (calibration/identification/recording.py)."""

    estimate: bool = setting(True, "", "estimate the torque channel's delay, the encoder's zero offset and (where the gear torque reverses) the gear's lost motion with the "
                             "parameters and correct the log; false fits the log as logged")
    iterations: int = setting(3, "", "at most this many corrections of the log", ge=1)
    stop_standard_errors: float = setting(0.25, "standard errors", "corrections stop once the shift still seen is below "
                                          "this many of its standard errors", gt=0.0, lt=1.0, unit="standard errors")
    step_halvings: int = setting(2, "", "a correction whose log fits no better is halved at most this many times before "
                                 "the corrections stop: the parameters absorb a lost motion left in the log better than one "
                                 "corrected twice over, so a step that overshoots along it fits no better although the shift "
                                 "is real; 2 tries a half and a quarter of it", ge=0)


@dataclass(frozen=True)
class ProcessForceSection:
    """[calibration.process_force]: a logged process force (column process_force_N) in place of the job's
    (calibration/identification/process_force.py)."""

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
    warning_shift: float = setting(0.02, "fraction of the estimate", "a log without the force column: a warning when the "
                                   "force tolerance moves eta_gear or psi by more than this: 2 % of eta_gear is 2 % of "
                                   "every driving torque the plan predicts, a fifth of the 10 % torque margin",
                                   gt=0.0, lt=1.0)


@dataclass(frozen=True)
class LeastSquaresSection:
    """[calibration.least_squares]."""

    starts: int = setting(4, "", "scipy least_squares from the theoretical values plus 3 seeded random starts (a guard "
                          "against a local minimum)", ge=1)


@dataclass(frozen=True)
class DifferentialEvolutionSection:
    """[calibration.differential_evolution]."""

    population: int = setting(15, "x number of parameters", "scipy's default popsize", ge=5)
    max_generations: int = setting(200, "", "far beyond the convergence seen on the synthetic benchmark", ge=1)
    tolerance: float = setting(1e-8, "", "relative spread of the population's objective at which it stops", gt=0.0)


# the tables this module reads (with [calibration.aco], calibration.aco.AcoSettings), path -> settings dataclass
SECTIONS = {("calibration",): CalibrationSection, ("calibration", "bootstrap"): BootstrapSection,
            ("calibration", "adequacy"): AdequacySection, ("calibration", "recording"): RecordingSection,
            ("calibration", "process_force"): ProcessForceSection, ("calibration", "speed"): SpeedSection,
            ("calibration", "least_squares"): LeastSquaresSection,
            ("calibration", "differential_evolution"): DifferentialEvolutionSection, ("calibration", "aco"): AcoSettings}


@dataclass(frozen=True)
class CalibrationSettings:
    parameters: tuple[str, ...]
    weight: float
    default_method: str
    peak_window: float  # s after die contact
    speed_harmonics: int
    interval_level: float
    correlation_limit: float
    interval_width_limit: float
    ls_starts: int
    de_population: int
    de_generations: int
    de_tolerance: float
    aco: AcoSettings
    peak_filter_window_deg: float
    peak_filter_order: int
    peak_noise_ratio_warning: float
    bootstrap_refits: int
    bootstrap_block_deg: float
    bootstrap_step_guard_deg: float
    bootstrap_iterations: int
    bootstrap_block_noise_lengths: float  # under coloured noise a block holds at least this many correlation lengths
    bootstrap_allowance: dict  # parameter name -> widening of its interval on each side, fraction of its range (0 if absent)
    adequacy_level: float  # false-alarm probability of the adequacy verdict (calibration/identification/adequacy.py)
    ripple_orders: tuple[float, ...]  # candidate torque-ripple orders per motor turn
    recording_estimate: bool  # estimate and correct the channel delay and encoder offset (calibration/identification/recording.py)
    recording_iterations: int  # at most this many corrections of the log
    recording_stop_standard_errors: float  # corrections stop once the shift still seen is below this many standard errors
    recording_step_halvings: int  # a correction that fits no better is halved at most this many times
    process_force: ProcessForceSettings = None  # [calibration.process_force]: a logged process force
    speed: SpeedSection = SpeedSection()  # [calibration.speed]: the local fit of the crank speed
    peak_ringing_fit: bool = True  # fit the die-contact ringing in the log and remove it before the peak filter (peak.py)

    @classmethod
    def from_job(cls, job: Job) -> "CalibrationSettings":
        """The job's [calibration] settings; absent keys take their defaults (:data:`SECTIONS`), and so does an absent
        table (a job file written before [calibration] existed). Without ``parameters`` the job names none (``()``): the
        command's --parameters names them, else the calibration is refused asking for them
        (:meth:`calibration.identification.problem.CalibrationProblem.from_press`)."""
        table = job.raw.get("calibration", {})
        aco_table = table.get("aco") if isinstance(table, dict) else None
        rest = {k: v for k, v in table.items() if k != "aco"} if isinstance(table, dict) else table
        rd = FieldReader(job.source, {"calibration": rest})
        c = ("calibration",)
        names = rd.node((*c, "parameters"), required=False) if isinstance(rest, dict) else rd.table(c)
        if names is None:
            names = []
        elif not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
            rd.fail((*c, "parameters"), names, 'must be a list of parameter names, e.g. ["eta_gear", "psi"]')
        top = read_section(rd, c, CalibrationSection)
        ls = read_section(rd, (*c, "least_squares"), LeastSquaresSection)
        de = read_section(rd, (*c, "differential_evolution"), DifferentialEvolutionSection)
        boot = read_section(rd, (*c, "bootstrap"), BootstrapSection)
        allowance = cls._allowance(rd, (*c, "bootstrap", "allowance"), names)
        aco = AcoSettings.from_mapping(aco_table if aco_table is not None else {}, f"{job.source} [calibration.aco]")
        adequacy = read_section(rd, (*c, "adequacy"), AdequacySection)
        rec = read_section(rd, (*c, "recording"), RecordingSection)
        pf = read_section(rd, (*c, "process_force"), ProcessForceSection)
        speed = read_section(rd, (*c, "speed"), SpeedSection)
        s = cls(
            parameters=tuple(names),
            weight=top.weight,
            default_method=top.default_method,
            peak_window=top.peak_window_after_contact_s,
            speed_harmonics=top.speed_harmonics,
            interval_level=top.interval_level,
            correlation_limit=top.correlation_limit,
            interval_width_limit=top.interval_width_limit,
            ls_starts=ls.starts,
            de_population=de.population,
            de_generations=de.max_generations,
            de_tolerance=de.tolerance,
            peak_filter_window_deg=top.peak_filter_window_deg,
            peak_filter_order=top.peak_filter_order,
            peak_ringing_fit=top.peak_ringing_fit,
            peak_noise_ratio_warning=top.peak_noise_ratio_warning,
            bootstrap_refits=boot.refits,
            bootstrap_block_deg=boot.block_deg,
            bootstrap_step_guard_deg=boot.step_guard_deg,
            bootstrap_iterations=boot.iterations,
            bootstrap_block_noise_lengths=boot.block_noise_lengths,
            bootstrap_allowance=allowance,
            aco=aco,
            adequacy_level=adequacy.level,
            ripple_orders=adequacy.ripple_orders_per_motor_turn,
            recording_estimate=rec.estimate,
            recording_iterations=rec.iterations,
            recording_stop_standard_errors=rec.stop_standard_errors,
            recording_step_halvings=rec.step_halvings,
            process_force=ProcessForceSettings(pf.filter_window_deg, pf.filter_order, pf.step_fraction, pf.contact_warning_deg,
                                               pf.contact_limit_deg, pf.unloaded_standard_errors, pf.job_force_tolerance,
                                               pf.warning_shift),
            speed=speed,
        )
        rd.reject_unread(JOB_FORMAT)
        return s

    @staticmethod
    def _allowance(rd: FieldReader, path: tuple, names: list[str]) -> dict:
        """The optional [calibration.bootstrap.allowance] table: parameter name -> fraction of its range (>= 0).

        A name the job does not calibrate is kept and unused (a copied job may calibrate fewer parameters, and
        --parameters may choose others); one that looks like a misspelling of a calibrated name is refused."""
        table = rd.table(path, required=False)
        out = {}
        for key in table:
            close = difflib.get_close_matches(key, names, n=1, cutoff=0.8)
            if key not in names and close:
                rd.fail((*path, key), table[key], f"names no key parameter (misspelled? did you mean '{close[0]}'?)")
            out[key] = rd.number((*path, key), ge=0.0, lt=1.0, unit="fraction of the parameter's range")
        return out


def joint_settings_warning(jobs) -> str | None:
    """For logs fitted jointly with several jobs: one warning naming the [calibration] keys (dotted) that a later job
    sets to another value than the first, whose settings the joint fit uses; None when none does (a job without a
    [calibration] table, or one job serving all)."""
    def flat(node, prefix=""):
        if isinstance(node, dict):
            out = {}
            for k, v in node.items():
                out.update(flat(v, f"{prefix}{k}."))
            return out
        return {prefix[:-1]: node}

    first = flat(jobs[0].raw.get("calibration") or {}, "calibration.")
    differ = {}
    for jb in jobs[1:]:
        other = flat(jb.raw.get("calibration") or {}, "calibration.")
        keys = sorted(k for k in other if first.get(k, "<absent>") != other[k])  # a key the job leaves out ignores nothing
        if keys and jb.source not in differ:
            differ[jb.source] = keys
    if not differ:
        return None
    listed = "; ".join(f"{src}: {', '.join(keys[:8])}{f' and {len(keys) - 8} more' if len(keys) > 8 else ''}"
                       for src, keys in differ.items())
    return (f"the jobs' [calibration] settings differ ({listed}): a joint fit has one set of settings, the first job's "
            f"({jobs[0].source}); the others' [calibration] tables are not used (their [process] is). Give the jobs the "
            "same [calibration] table to silence this")
