"""The [calibration] table of a job file: what to calibrate, Eq. 28's weight, and the optimisers' settings.

:class:`CalibrationSettings` is the table, read once; each inner table is a settings dataclass of its own, held
by the field of its name ([calibration.bootstrap] is ``.bootstrap``); a table the module that uses it declares
([calibration.aco] :class:`calibration.identification.aco.AcoSettings`, [calibration.bootstrap]
:class:`calibration.identification.bootstrap.BootstrapSection`, [calibration.process_force]
:class:`calibration.identification.process_force.ProcessForceSection`) is imported here. The defaults are the cushion-test job's
values, with unit and reason (:data:`SECTIONS`); a job gives ``parameters`` (the key parameters of its press) and
what differs.
"""
from __future__ import annotations

from dataclasses import dataclass

from press_model.jobs import JOB_FORMAT, Job
from press_model.readers import FieldReader
from press_model.settings_fields import own, read_section, section, sections, setting

from calibration.identification.aco import AcoSettings
from calibration.identification.bootstrap import BootstrapSection
from calibration.identification.methods import METHODS
from calibration.identification.process_force import ProcessForceSection


def _read_orders(rd: FieldReader, path: tuple, default: tuple) -> tuple[float, ...]:
    """Torque-ripple orders per motor turn: a list of positive numbers ([] tests none); ``default`` when absent."""
    orders = rd.node(path, required=False)
    if orders is None:
        return default
    if not isinstance(orders, list) or not all(isinstance(q, (int, float)) and not isinstance(q, bool) and q > 0 for q in orders):
        rd.fail(path, orders, "must be a list of positive numbers (ripple periods per motor revolution), e.g. [6]; [] tests none")
    return tuple(float(q) for q in orders)


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
class AdequacySection:
    """[calibration.adequacy]: is the calibrated model adequate for the log (calibration/identification/adequacy.py)."""

    level: float = setting(0.01, "", "chance of a false \"not adequate\" on an adequate log, shared by Bonferroni over "
                           "its tests", gt=0.0, lt=0.5)
    ripple_orders_per_motor_turn: tuple = setting((6.0,), "1/motor turn", "torque ripple orders tested: 6 per period is the "
                                                  "classic ripple of a three-phase drive (put your motor's)", read=_read_orders)
    free_held: bool = setting(True, "", "a parameter of the job's list that --parameters leaves out (held at the press file's "
                              "value) and the log disagrees with (its score test, at level) is freed and the fit repeated; "
                              "false only warns (calibration/identification/held.py)")


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


def _read_parameters(rd: FieldReader, path: tuple) -> tuple[str, ...]:
    """The key parameters the job calibrates: a non-empty list of names, or ``()`` where the job names none (the
    command's --parameters names them, else the calibration is refused asking for them:
    :meth:`calibration.identification.problem.CalibrationProblem.from_press`)."""
    names = rd.node(path, required=False)
    if names is None:
        return ()
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        rd.fail(path, names, 'must be a list of parameter names, e.g. ["eta_gear", "psi"]')
    return tuple(names)


def _read_aco(rd: FieldReader, path: tuple) -> AcoSettings:
    """[calibration.aco] by its own reader (:meth:`AcoSettings.from_mapping`: evaporation_max is checked against
    evaporation_min), its messages naming ``aco.<key>`` of ``<job> [calibration.aco]``."""
    table = rd.node(path, required=False)
    rd.delegate(path)
    return AcoSettings.from_mapping(table if table is not None else {}, f"{rd.source} [calibration.aco]")


@dataclass(frozen=True)
class CalibrationSettings:
    """A job's [calibration] table, read once (:meth:`from_job`): ``parameters`` (the press's key parameters, the
    job's own and required), the plain keys, and each inner table as its own settings section."""

    parameters: tuple[str, ...] = own(_read_parameters, default_factory=tuple)
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
    bootstrap: BootstrapSection = section(BootstrapSection)
    adequacy: AdequacySection = section(AdequacySection)
    recording: RecordingSection = section(RecordingSection)
    process_force: ProcessForceSection = section(ProcessForceSection)
    speed: SpeedSection = section(SpeedSection)
    least_squares: LeastSquaresSection = section(LeastSquaresSection)
    differential_evolution: DifferentialEvolutionSection = section(DifferentialEvolutionSection)
    aco: AcoSettings = section(AcoSettings, read=_read_aco)

    @classmethod
    def from_job(cls, job: Job) -> "CalibrationSettings":
        """The job's [calibration] settings; absent keys take their defaults (:data:`SECTIONS`), and so does an absent
        table (a job file written before [calibration] existed); without ``parameters`` the job names none (``()``)."""
        rd = FieldReader(job.source, {"calibration": job.raw.get("calibration", {})})
        s = read_section(rd, ("calibration",), cls)
        rd.reject_unread(JOB_FORMAT)
        return s


# the tables of [calibration], path -> settings dataclass (the README's defaults table, the history test)
SECTIONS = sections(("calibration",), CalibrationSettings)


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
