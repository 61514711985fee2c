"""The 'design-experiment' command: read the inputs, design the calibration runs (:mod:`calibration.design`), play
every run back as `plan --verify` does (:mod:`planning.playback`), write the folder, and the lines it prints."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from calibration.design.noise import NoiseLevel, noise_from_calibrated
from calibration.design.report import Design, aim_next_steps, design_experiment, ratio_words, write_design
from planning.playback import verify_runs
from press_model.jobs import Job
from press_model.limits import check_design_runs
from press_model.press_data import PressData
from press_io.progress import Progress


@dataclass(frozen=True)
class DesignChoice:
    """What a design takes beside the job's [calibration] and [design] tables (None: the job's): the parameters to
    identify, the number of runs, the polish's model cycles (0: unpolished, `reproduce --quick`) and a first
    calibration's noise level (:func:`calibration.design.noise.noise_from_calibrated`)."""

    names: tuple[str, ...] | None = None
    runs: int | None = None
    polish_evaluations: int | None = None
    noise: NoiseLevel | None = None


def design_and_verify(press: PressData, job: Job, out: Path, choice: DesignChoice = DesignChoice(), verify: bool = True,
                      progress: Progress | None = None) -> tuple[Design, dict]:
    """The 'design-experiment' command: design as ``choice`` says, play every run back (unless ``verify`` is off),
    write the folder. Returns the design and the prediction.json record. ``progress``: a line per phase and per run's
    playback (None: silent)."""
    progress = progress or Progress("design-experiment", enabled=False)
    count = "the job's [design]" if choice.runs is None else str(choice.runs)
    with progress.phase(f"design of {count} runs (exchange over the candidate grid, then the polish)"):
        design = design_experiment(press, job, choice.names, choice.runs, polish_evaluations=choice.polish_evaluations,
                                   noise=choice.noise)
    playbacks = verify_runs(design, out, progress) if verify else None
    with progress.phase("outputs (run folders, prediction.json, report.md, design.png)"):
        rec = write_design(design, out, playbacks)
    return design, rec


def design_job(press: str | None, job: str, parameters: str | None, runs: int | None, out: str, verify: bool = True,
               calibrated: str | None = None) -> dict:
    """The 'design-experiment' command: read the press (file or built-in name), the job and the parameters (a comma list
    or a key_parameters.json; default the job's [calibration] list), the noise level (``calibrated``: a first
    calibration's calibrated.json, else the job's [design] keys), design, verify and write the folder ``out`` whole at
    the end. Returns the prediction.json record."""
    from calibration.design.runs import DesignSettings
    from calibration.identification.inputs import calibration_parameters
    from calibration.identification.settings import CalibrationSettings
    from press_model.jobs import load_job
    from press_io.outputs import output_folder
    from press_model.press_data import load_press

    if runs is not None:
        check_design_runs(runs)  # before anything is read or run: a million runs ran for minutes without a word
    press_ = load_press(press)
    job_ = load_job(job)
    names = calibration_parameters(parameters, press_, job_, CalibrationSettings.from_job(job_))
    ds = DesignSettings.from_job(job_)  # the [design] table checked before the output folder is made and the design announced
    noise = noise_from_calibrated(calibrated, press_) if calibrated is not None else ds.noise(job_.source)
    with output_folder(out, [press, job, parameters, calibrated], "design-experiment") as tmp:
        _, rec = design_and_verify(press_, job_, tmp, DesignChoice(names, runs, noise=noise), verify,
                                   Progress("design-experiment", announce=True))
    return rec


def design_lines(rec: dict, out: Path) -> list[str]:
    """What the command prints: each run, its playback verdict, the predicted intervals beside the cushion test's, the aim."""
    d, c, a = rec["design"], rec["cushion_test"], rec["aim"]
    lines = []
    for r in d["runs"]:
        pb = r.get("playback")
        lines.append(f"{r['folder']}: {r['strokes_per_min']:.2f} spm, speed depth {r['speed_depth']:.2f} slowest at {r['slow_angle_deg'] % 360:.0f} deg, "
                     f"cushion {r['cushion_force_N'] / 1e3:.0f} kN below {1e3 * r['cushion_stroke_m']:.0f} mm; peak {r['peak_motor_torque_Nm']:.0f} N m, "
                     f"RMS {r['rms_motor_torque_Nm']:.0f} N m" + (f"; {pb['verdict']['line']}" if pb else "; not played back"))
    lines.append("predicted 95 % interval width / range, design vs single cushion test:")
    for n in rec["parameters"]:
        lines.append(f"  {n:>9}: {100 * d['width_share_of_range'][n]:5.1f} % vs {100 * c['width_share_of_range'][n]:5.1f} %")
    lines.append(f"largest |correlation| {a['design_max_abs_correlation']['value']:.2f} ({' and '.join(a['design_max_abs_correlation']['pair'])}) vs "
                 f"{a['cushion_test_max_abs_correlation']['value']:.2f}; widest interval {ratio_words(a['widest_interval_ratio']).removesuffix(' than')} "
                 f"-> {out}/prediction.json, report.md, design.png, run_1..run_{len(d['runs'])}/")
    lines += [f"aim {line}" for line in aim_next_steps(a, len(d["runs"]))]
    return lines
