"""The 'reproduce' command: the whole paper on the embedded reference press, in one folder with a report.

Like :mod:`servo_press.cli` this is a composition root: it runs, in order, the URDF, the cushion-test
cycle, the Sobol analysis (under the cushion test and under the no-load cycle), the synthetic experiment and its calibration, both door-panel plans with their
comparison and the playback verification, then writes ``report.md`` with every table and figure of the
paper beside ours. Each step writes into its own subfolder with the files of the matching command.

The theoretical door-panel plan, the two Sobol analyses and the calibration experiment design depend on no other step:
a second process (:func:`press_io.forked.beside`) takes them one at a time while this one runs the experiment, the
calibration and the calibrated plans, and this one takes any left when its own steps are done (:class:`SharedSteps`), so
on two cores the two processes end together; the theoretical plan is handed over as soon as it is planned (the
comparison needs it), the others' results at the end. The comparison's figures are drawn in a figure worker
(:func:`planning.figures.figure_worker`) beside the playback. Each step writes the same files whichever process runs it
(the kernel's parameter sets do not mix, whatever the threads; each plan starts from no IPOPT solver built before it).
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
import multiprocessing
import os
import queue
import sys
import time
from pathlib import Path

from press_model.calibration_verdict import calibration_verdict, verdict_warning
from press_io.forked import SECOND_PROCESS, beside
from press_model.jobs import load_job
from press_model.model import PressModel
from press_io.outputs import atomic_write_text, output_folder, versions, write_json
from press_io.progress import Progress
from press_model.plots import linkage_figure, pyplot, save
from press_model.press_data import load_press
from calibration.sensitivity.report import paper_figures
from press_model.urdf import write_urdf

FULL = {"sobol_n": 2048, "methods": ("differential-evolution", "aco", "least-squares")}
QUICK = {"sobol_n": 256, "methods": ("aco",)}


def run_reproduce(out: Path, quick: bool = False, seed: int = 0) -> dict:
    """Run every step into ``out``; returns the run record (also in ``out/run.json``)."""
    from calibration.synthetic.experiment import ExperimentSettings, truth_path, write_experiment
    from calibration.identification.run import calibrate

    from .calibrate import write_outputs
    from planning.compare import Calibrated, plan_theoretical, run_compare, theoretical_modes
    from planning.figures import figure_worker
    from planning.settings import read_planning

    from .simulate import SimulateCase, run_simulate
    from planning.optimal import clear_solvers

    clear_solvers()  # the same bytes whatever this process planned before (tests run it twice in one process)

    t0 = time.perf_counter()
    cfg = QUICK if quick else FULL
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}
    steps = Progress("reproduce", sys.stdout, announce=True, timings=timings)
    press = load_press(None)
    pm = PressModel(press)
    cushion_job = load_job("cushion-test")  # read once: the cycle, the kernel's load case and the experiment take it
    door = load_job("door-panel")
    # mode "auto": every mode the door panel allows, each plan the fastest of them (planning/modes.py)
    door_spec = dataclasses.replace(read_planning(door), mode="auto")
    # three steps need nothing the others make: the theoretical door-panel plan, the two Sobol analyses (one step) and the
    # experiment design. A second process takes them one by one while this one runs the URDF, the cushion-test cycle, the synthetic
    # experiment, the calibration and the calibrated plans, and this one takes what is left once its own steps are done,
    # so the two end together whatever each step costs. Forked as early as it can be: after the kernel is loaded (a first
    # run compiles it once, here) and matplotlib (both processes and their figure workers draw with it)
    _load_kernel(pm, cushion_job)
    pyplot()
    shared = SharedSteps(_shared_steps(cfg, quick), handed=(THEORETICAL,))
    run = _Run(pm, cfg, seed, quick, out, cushion_job, door, door_spec)
    # the comparison's figures are drawn in a figure worker, forked now with the second process: before this process
    # could have run the kernel on threads (GNU OpenMP, once used, ends a process that forks)
    with (figure_worker() as figures,
          beside(functools.partial(_second_process, run, os.getpid(), shared)) as second):
        if second.forked:
            print(f"[reproduce] shared with a second process: {', '.join(shared.names)} ...", flush=True)
        with steps.phase("URDF"):
            urdf_path, loops_path = write_urdf(press, out / "urdf" / "eight_bar.urdf")
            save(linkage_figure(pm, [0.0, math.degrees(pm.assembly.theta_tdc), 71.07, math.degrees(pm.assembly.theta_bdc)],
                                f"{press.name}: linkage at four crank angles (from the URDF model)"), out / "figure2_linkage.png")
        with steps.phase("cushion-test cycle"):
            cushion = run_simulate(pm, SimulateCase("cushion-test", "cushion", 11.4, 1.0), out / "cushion", {},
                                   jobs={"cushion-test": cushion_job})
        truth = ExperimentSettings.from_job(cushion_job).truth
        log_path = out / "experiment" / "cushion_log.csv"
        validation_job = load_job("cushion-validation")
        validation_path = out / "experiment" / "validation_log.csv"
        with steps.phase("synthetic experiment and validation run"):
            write_experiment(press, cushion_job, truth, seed, log_path)
            write_experiment(press, validation_job, ExperimentSettings.from_job(validation_job).truth, seed + 1, validation_path)
        _raise_if_failed(second)
        with (steps.phase(f"calibration ({', '.join(cfg['methods'])}), bootstrap and validation"),
              kernel_threads(1 if second.running() else None)):
            cal = calibrate(press, cushion_job, log_path, list(cfg["methods"]), seed, progress=False, validate=validation_path)
            # the logs as the report names them, relative to the run folder (``out`` is the temporary folder of the run)
            cal = dataclasses.replace(cal, log=dataclasses.replace(cal.log, source=log_path.relative_to(out).as_posix()),
                                      validation={**cal.validation, "log": validation_path.relative_to(out).as_posix()})
            cal_rec = write_outputs(cal, press, cushion_job, seed, out / "calibration")
            verdict = calibration_verdict(cal_rec, "calibration/calibrated.json")
        _raise_if_failed(second)
        theoretical = _Handed(shared, THEORETICAL, second, lambda: plan_theoretical(pm, door, door_spec, modes=theoretical_modes(THEORETICAL_HERE)))
        # the figures drawn beside the plans' outputs and the playback
        with steps.phase("plans, comparison and playback"):
            calibrated = Calibrated(cal_rec["parameters"], {n: tuple(v) for n, v in cal_rec["joint_region"]["box"].items()},
                                    "joint region", verdict)
            cmp_rec = run_compare(press, door, door_spec, calibrated, out / "planning", verify=True, figures=figures,
                                  theoretical=theoretical, theoretical_here=THEORETICAL_HERE)
        done = _run_shared(run, shared, steps, "", lambda: 1 if second.running() else None)
        with steps.phase("waiting for the second process"):
            second_timings, second_done = second.result()
    timings.update(second_timings)
    done.update(second_done)
    design_rec, (sobol_no_load, sobol) = (done[name] for name in shared.names if name != THEORETICAL)
    record = {
        "what": "servo-press reproduce: the paper's pipeline on the embedded reference press",
        "quick": quick, "seed": seed, "sobol_n": cfg["sobol_n"], "calibration_methods": list(cfg["methods"]),
        "synthetic_inputs": {"drive_log": str(log_path.relative_to(out)), "truth_sidecar": str(truth_path(log_path).relative_to(out)),
                             "validation_log": str(validation_path.relative_to(out)), "validation_seed": seed + 1,
                             "truth": truth, "note": "the calibration experiment's drive log and the validation log (another motion) are SYNTHETIC (made by the model from the truth)"},
        "key_parameters_by_load_case": {"cushion-test": sobol["key_parameters"], "no-load": sobol_no_load["key_parameters"],
                                        "paper (load case not stated)": paper_figures()["key_parameters"]["paper"]},
        **press.identity(),
        "parameters_theoretical": press.parameter_values(),
        "parameters_calibrated": cal_rec["parameters"], "versions": versions(),
    }
    if verdict is not None:
        record["calibration_verdict"] = verdict
    write_json(out / "run.json", record)
    results = _Results(cushion, sobol, cal, cal_rec, cmp_rec, truth, design_rec)
    report = report_markdown(out, record, pm, results, timings, wall=time.perf_counter() - t0)
    atomic_write_text(out / "report.md", report)
    return {**record, "timing_s": timings}




# the theoretical door-panel row's modes the comparison plans itself, after the calibrated rows: without them the second
# process's steps took ~3 s longer than this one's (AVX2 stand-in), and continuous (~1.4 s) evens them out
THEORETICAL_HERE = ("continuous",)
THEORETICAL = f"theoretical door-panel plan (every mode but {', '.join(THEORETICAL_HERE)})"  # the shared step the comparison needs: handed over when done


def _shared_steps(cfg: dict, quick: bool) -> tuple[str, ...]:
    """The names of the steps the two processes share, in the order they are taken: the theoretical plan first (the
    comparison waits for it), then the longest first. The two Sobol analyses are one step: one design under both load
    cases, whose model cycles share the kernel's work away from the cushion's stroke (calibration.sensitivity.load_cases)."""
    return (THEORETICAL, "calibration experiment design (D-optimal runs" + (", unpolished, no playback)" if quick else ", playback)"),
            f"Sobol analyses N = {cfg['sobol_n']}, no-load cycle and cushion test")


class SharedSteps:
    """Steps two processes share: each takes the first one no process has taken yet (flags in memory both see). The
    result of a step in ``handed`` goes to the other process as soon as it is done (:meth:`hand`, :class:`_Handed`),
    the others' with the second process's result."""

    def __init__(self, names: tuple[str, ...], handed: tuple[str, ...] = ()):
        self.names = names
        fork = "fork" in multiprocessing.get_all_start_methods()
        ctx = multiprocessing.get_context("fork") if fork else None
        self._taken = ctx.Array("b", len(names)) if fork else [0] * len(names)
        self._lock = self._taken.get_lock() if fork else contextlib.nullcontext()
        self.handed = handed
        self._queue = ctx.Queue() if fork and handed else None  # written by a feeder thread: the step's process goes on at once

    def take(self) -> str | None:
        """The first step's name no process has taken, now taken; None when every step is."""
        with self._lock:
            for i, name in enumerate(self.names):
                if not self._taken[i]:
                    self._taken[i] = 1
                    return name
        return None

    def claim(self, name: str) -> bool:
        """Take the step ``name`` now if no process has (True), else False."""
        i = self.names.index(name)
        with self._lock:
            if self._taken[i]:
                return False
            self._taken[i] = 1
            return True

    def hand(self, name: str, value) -> None:
        """Hand the result of the step ``name`` (one of ``handed``) to the other process."""
        self._queue.put((name, value))

    def receive(self, name: str, second):
        """The result of the step ``name`` that the process ``second`` (:class:`press_io.forked.Beside`) has taken:
        waits for it; raises what the second process raised if it fails first."""
        while True:
            try:
                got, value = self._queue.get(timeout=0.5)
            except queue.Empty:
                if second.running():
                    continue
                try:  # it ended: what it handed over before is in the queue's pipe
                    got, value = self._queue.get(timeout=1.0)
                except queue.Empty:
                    second.result()  # raises what it raised
                    raise RuntimeError(f"the second process ended without handing over the {name}") from None
            if got == name:
                return value


class _Handed:
    """The result of the shared step ``name`` for the process that needs it (:meth:`result`): from the second process,
    which took it, or run here by ``run()`` when no process has taken it yet (its time is then the calling step's)."""

    def __init__(self, shared: SharedSteps, name: str, second, run):
        self.shared, self.name, self.second, self.run = shared, name, second, run

    def result(self):
        return self.run() if self.shared.claim(self.name) else self.shared.receive(self.name, self.second)


def _load_kernel(pm, job) -> None:
    """Compile the batch kernel, or load it from the disk cache, with one parameter set (one block: no threads): the
    processes forked after this use it as it is (every batch model of a press shares one kernel). The batch model is
    the cushion test's, which the Sobol analysis builds again from the disk cache."""
    from calibration.sensitivity.report import load_case
    from press_model.batch import build_batch_model, motor_torques

    case = load_case(job)
    bm = build_batch_model(pm.press, case.motion, case.job.process, pm=pm)
    motor_torques(bm, bm.nominal[None])


@dataclasses.dataclass(frozen=True)
class _Run:
    """What both processes of a reproduce run share, read once by the parent: the model, the mode's settings
    (:data:`FULL` or :data:`QUICK`), the seed, the mode, the run folder, the cushion test's job, the door panel's job
    and its planning settings of the comparison."""

    pm: object
    cfg: dict
    seed: int
    quick: bool
    out: Path
    job: object
    door: object
    door_spec: object


@dataclasses.dataclass(frozen=True)
class _Results:
    """The steps' results the report reads: the cushion-test cycle's summary, the cushion test's Sobol run record, the
    calibration and its calibrated.json record, the comparison's record, the synthetic truth and the design's record
    (None: no design)."""

    cushion: dict
    sobol: dict
    cal: object
    cal_rec: dict
    cmp_rec: dict
    truth: dict
    design_rec: dict | None = None


def _second_process(run: _Run, parent: int, shared: SharedSteps) -> tuple[dict, dict]:
    """The second process (see run_reproduce): the shared steps it takes, on one kernel thread; returns their wall times
    (s) and their results by name (a handed step's went over at once: None here). Where the system cannot fork, the
    process ``parent`` calls this after taking every step itself: nothing is left."""
    timings: dict[str, float] = {}
    steps = Progress("reproduce", sys.stdout, announce=os.getpid() == parent, timings=timings)
    forked = os.getpid() != parent
    done = _run_shared(run, shared, steps, SECOND_PROCESS if forked else "", lambda: 1 if forked else None, hand=forked)
    return timings, done


def _run_shared(run: _Run, shared: SharedSteps, steps: Progress, mark: str, threads, hand: bool = False) -> dict:
    """Take and run the shared steps of ``run`` until none is left; returns their results by name: the theoretical
    door-panel plan (:func:`planning.compare.plan_theoretical`; with ``hand`` handed to the parent at once and None
    here), the Sobol run records (no-load, cushion test) and the design's prediction record. ``threads()``: the kernel threads for the next
    step (None: all); ``mark``: what the progress lines add to each step's name."""
    from calibration.sensitivity.report import load_case, run_sensitivities
    from planning.compare import plan_theoretical, theoretical_modes
    from .design_experiment import DesignChoice, design_and_verify

    pm, cfg, seed, quick, out, job, door, door_spec = (run.pm, run.cfg, run.seed, run.quick, run.out, run.job, run.door,
                                                       run.door_spec)
    _, design_name, sobol_name = shared.names
    done = {}
    while (name := shared.take()) is not None:
        with kernel_threads(threads()), steps.phase(name + mark):
            if name == THEORETICAL:
                done[name] = plan_theoretical(pm, door, door_spec, modes=theoretical_modes(THEORETICAL_HERE))
                if hand:
                    shared.hand(name, done.pop(name))
            elif name == design_name:
                done[name] = design_and_verify(pm.press, job, out / "design", DesignChoice(polish_evaluations=0 if quick else None),
                                               verify=not quick)[1]
            elif name == sobol_name:  # (no-load, cushion test) records
                done[name] = tuple(run_sensitivities(pm, cfg["sobol_n"], seed, False, [(load_case("no-load"), out / "sensitivity_no_load"),
                                                                                    (load_case(job), out / "sensitivity")], progress=False))
    return done


@contextlib.contextmanager
def kernel_threads(n: int | None):
    """Run the batch kernel on ``n`` threads inside the block (None: as it is). Two processes on two cores, each with a
    parallel kernel, make three or four threads for two cores: a thread that waits for its partner at the end of a call
    then spins on a core the other process wants (a batch call took twice the CPU under such load). The results do not
    depend on the threads."""
    try:
        import numba
    except ImportError:  # pragma: no cover
        numba = None
    if n is None or numba is None:
        yield
        return
    before = numba.get_num_threads()
    numba.set_num_threads(min(n, before))
    try:
        yield
    finally:
        numba.set_num_threads(before)


def _raise_if_failed(second) -> None:
    """Stop at once when the second process has failed, rather than after the steps still to come."""
    if second.failed():
        second.result()


def _json(path: Path) -> dict:
    import json

    return json.loads(path.read_text(encoding="utf-8"))


def _rel(a: float, b: float) -> str:
    return f"{100.0 * (a - b) / b:+.2f} %"


def report_markdown(out: Path, record: dict, pm, results: _Results, timings: dict, wall: float | None = None) -> str:
    """report.md of the run: every step's figures beside the paper's; ``wall``: the run's wall time, s."""
    from calibration.identification.report import validation_rows

    cushion, cal_rec, cmp_rec, truth, design_rec = results.cushion, results.cal_rec, results.cmp_rec, results.truth, results.design_rec

    press = pm.press
    paper = paper_figures()
    pc = paper["calibration"]
    m = cal_rec["metrics"]
    L = [
        "# servo-press-twin: the paper reproduced on the embedded reference press",
        "",
        "Article: *Dynamics Parameter Calibration for Performance Enhancement of Heavy-Duty Servo Press* (25,000 kN servo press).",
        f"Mode: {'QUICK (N = 256, one calibration method)' if record['quick'] else 'full'}; seed {record['seed']}. "
        "Every number below was produced by this run; the paper's figures stand beside ours.",
        "",
        "> **Synthetic input.** The paper's measured motor torque is not published. The calibration runs against a "
        "**SYNTHETIC** drive log (`experiment/cushion_log.csv`) that the model made from a chosen truth "
        f"({', '.join(f'{k} = {v:g}' for k, v in truth.items())}; the paper's Table 4) plus unmodelled effects "
        "(die-contact ringing, noise). Truth and seed: `experiment/cushion_log.truth.json`. Calibration never reads it; this report does, to score the result.",
        "",
        "## Figures 1, 2 and 4 and Tables 1-3: the press",
        "",
        "Figures 1 and 4 are photographs and CAD renderings of the real press; nothing to compute. Figure 2 (the eight-bar "
        "schematic) is drawn here from the generated URDF model: `figure2_linkage.png` (at theta_c = 0 deg, TDC, die contact and BDC).",
        "",
        "![Figure 2 analogue](figure2_linkage.png)",
        "",
        "Tables 1-3 (gear system, link geometry and inertia, friction and bearing radii) are the model's input: they are "
        "in `press_model/data/reference_press.toml` as printed in the paper. Values used in this run:",
        "",
        "| parameter | value | unit |",
        "|---|---|---|",
    ]
    for p in press.parameters.values():
        L.append(f"| {p.name} | {p.nominal:.6g} | {'-' if p.unit == '1' else p.unit} |")
    L += ["", f"Geometry: stroke {pm.assembly.stroke:.5f} m, BDC at {math.degrees(pm.assembly.theta_bdc):.2f} deg, TDC at "
          f"{math.degrees(pm.assembly.theta_tdc):.2f} deg. URDF: `urdf/eight_bar.urdf` + `urdf/eight_bar.loops.json`.", ""]

    L += ["## Cushion-test cycle (Section 4.1, theoretical parameters)", "",
          f"Peak motor torque {cushion['peak_motor_torque_Nm']:.0f} N m, RMS {cushion['rms_motor_torque_Nm']:.0f} N m per motor, "
          f"motor work {cushion['motor_work_all_motors_J'] / 1e3:.1f} kJ per cycle, process work {cushion['process_work_J'] / 1e3:.1f} kJ, "
          f"friction {cushion['friction_dissipation_J'] / 1e3:.1f} kJ. Paper: Eq. 24 RMS of the theoretical curve 13,195.4 N m "
          "(on its own, unpublished, experiment trajectory).", "", "![cushion cycle](cushion/cycle.png)", ""]

    keysets = record["key_parameters_by_load_case"]
    paper_keys = keysets["paper (load case not stated)"]
    L += [f"## Figure 3: Sobol sensitivity (N = {record['sobol_n']})", "",
          "**The paper does not state the load case (process force) or the crank motion of its Figure 3**, and the key "
          "set depends on them: the process force sets how large the friction and gear losses are next to the balance "
          "force and the slide's weight. We therefore report two load cases, the cushion test (5,000 kN over the last "
          "300 mm, the calibration experiment's cycle: the default of `servo-press sensitivity`) and the no-load cycle "
          "(the same motion without process force, `--job no-load`), side by side with the paper's key set. "
          "Any other job or planned profile: `servo-press sensitivity --job FILE [--profile profile.csv]`.", "",
          "| load case | key parameters (S_T > 0.05 on Y_RMSE or Y_PR) | in the paper's set | not in the paper's set | paper's, not selected |",
          "|---|---|---|---|---|"]
    for name, label in (("cushion-test", "cushion test, 5,000 kN (`sensitivity/`)"), ("no-load", "no-load cycle (`sensitivity_no_load/`)")):
        ks = keysets[name]
        L.append(f"| {label} | {', '.join(ks) or 'none'} | {', '.join(k for k in ks if k in paper_keys) or 'none'} | "
                 f"{', '.join(k for k in ks if k not in paper_keys) or 'none'} | {', '.join(k for k in paper_keys if k not in ks) or 'none'} |")
    L.append(f"| paper (load case not stated) | {', '.join(paper_keys)} | | | |")
    L += ["", "### Cushion test", "", "![Figure 3 analogue, cushion test](sensitivity/sobol_indices.png)", ""]
    L += (out / "sensitivity" / "paper_comparison.md").read_text(encoding="utf-8").splitlines()
    L += ["", "### No-load cycle", "", "![Figure 3 analogue, no load](sensitivity_no_load/sobol_indices.png)", ""]
    L += (out / "sensitivity_no_load" / "paper_comparison.md").read_text(encoding="utf-8").splitlines()
    L += [""]

    L += ["## Table 4 and Figure 5: calibration against the SYNTHETIC log", ""]
    L += ["| parameter | theoretical | calibrated (ours) | 95 % interval | synthetic truth | ours vs truth | paper: calibrated |",
          "|---|---|---|---|---|---|---|"]
    t4 = pc["table4"]
    for n, x in cal_rec["parameters"].items():
        lo, hi = cal_rec["intervals"][n]
        tv = truth.get(n)
        L.append(f"| {n} | {cal_rec['theoretical'][n]:.5g} | {x:.5g} | [{lo:.5g}, {hi:.5g}] | {tv:.5g} | {_rel(x, tv)} | "
                 f"{t4[n][1]:.5g} |" if tv is not None and n in t4 else f"| {n} | {cal_rec['theoretical'][n]:.5g} | {x:.5g} | [{lo:.5g}, {hi:.5g}] | | | |")
    L += ["", "| figure | ours: before | ours: after | paper: before | paper: after |", "|---|---|---|---|---|",
          f"| RMSE [N m] | {m['rmse_before_Nm']:.1f} | {m['rmse_after_Nm']:.1f} | {pc['rmse_before_Nm']} | {pc['rmse_after_Nm']} |",
          f"| peak error [N m] | {m['peak_error_before_Nm']:+.1f} | {m['peak_error_after_Nm']:+.1f} | {pc['peak_error_before_Nm']} | {pc['peak_error_after_Nm']} |",
          f"| peak error incl. die-contact spike [N m] | {m['peak_error_with_impact_before_Nm']:+.1f} | {m['peak_error_with_impact_after_Nm']:+.1f} | | |",
          f"| thermal error (Eq. 24) | {100 * m['thermal_error_before']:+.2f} % | {100 * m['thermal_error_after']:+.2f} % | "
          f"{100 * pc['thermal_error_before']:.1f} % | {100 * pc['thermal_error_after']:.1f} % |", ""]
    L += [f"Method reported: {cal_rec['method']} (lowest Eq. 28). Intervals: {cal_rec['interval_method']} "
          "(coverage on synthetic logs: `python scripts/bench_coverage.py`); the Jacobian intervals of linearised least squares "
          "are kept in `calibrated.json` as `intervals_jacobian`, a second opinion. "
          f"Measured peak of Eq. 23: {cal_rec['measured_peak']['method']}."]
    L += [f"> **Warning:** {w}" for w in cal_rec["warnings"]]
    if len(cal_rec["solver_runs"]) > 1:
        L += ["", "| method | Eq. 28 reached | above the minimum of all methods | model cycles | " + " | ".join(cal_rec["parameters"]) + " |",
              "|---|---|---|---|" + "---|" * len(cal_rec["parameters"])]
        for r in cal_rec["solver_runs"]:
            L.append(f"| {r['method']} | {r['objective_eq28']:.6f} | {r['gap_to_minimum_pct']:.3f} % | {r['model_cycles']} | "
                     + " | ".join(f"{v:.5g}" for v in r["parameters"].values()) + " |")
        L.append(f"| minimum of all methods | {cal_rec['objective_eq28_minimum_of_methods']:.6f} | | | " + " |" * len(cal_rec["parameters"]))
        L.append("| synthetic truth | | | | " + " | ".join(f"{truth[n]:.5g}" for n in cal_rec["parameters"]) + " |")
    L += ["", "What the experiment can tell apart:", ""] + [f"* {s}" for s in cal_rec["identifiability"]]
    v = cal_rec.get("validation")
    if v:
        L += ["", "### Out-of-sample validation", "",
              f"A second **SYNTHETIC** log, `{record['synthetic_inputs']['validation_log']}` (job `cushion-validation`: the same press "
              f"and cushion, another motion, noise seed {record['synthetic_inputs']['validation_seed']}), predicted with the theoretical "
              "and the calibrated parameters; nothing was fitted to it (`servo-press calibrate --validate`). "
              "Bottom panel of the Figure 5 analogue.", "",
              "| figure | theoretical | calibrated |", "|---|---|---|"] + validation_rows(v)
    L += ["", "![Figure 5 analogue](calibration/figure5.png)", ""]

    if design_rec is not None:
        L += design_section(design_rec, cal_rec)
    rows = cmp_rec["rows"]
    L += ["## Figures 6 and 7: door outer panel, planned with theoretical and calibrated parameters", "",
          "| plan | strokes/min | peak/T_max, theoretical model | peak/T_max, calibrated model | RMS theoretical model [N m] | RMS calibrated model [N m] |",
          "|---|---|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['plan']} | {r['strokes_per_min']:.3f} | {r['peak_ratio_theoretical_model']:.3f} | {r['peak_ratio_calibrated_model']:.3f} | "
                 f"{r['rms_theoretical_model_Nm']:.0f} | {r['rms_calibrated_model_Nm']:.0f} |")
    pp = cmp_rec["paper"]
    L += [""] + [f"* {name}: {text}" for name, text in cmp_rec.get("rows_are", {}).items()]
    L += [f"\n**{s[0].upper() + s[1:]}.**" for s in cmp_rec.get("overloads", [])]  # an overload in words, not only in the table
    w = verdict_warning(cmp_rec.get("calibration_verdict"))
    if w:
        L += ["", f"> **Warning:** {w}"]
    L += ["", f"Production rate: ours {rows[0]['strokes_per_min']:.3f} -> {rows[1]['strokes_per_min']:.3f} spm ({cmp_rec['rate_gain_percent']:+.2f} %); "
          f"paper {pp['strokes_per_min_theoretical']} -> {pp['strokes_per_min_calibrated']} spm ({pp['rate_gain_percent']:+.2f} %). "
          "Each plan's dwell at TDC is planned from the door panel's transfer window (`[planning.transfer]` in `door_panel.toml`: the "
          "slide at or above its opening for its time a stroke, the moving slide's time counting), not fitted to the paper's 11.4 spm "
          "(the earlier dwell of 1.7423 s was; a job with `dwell_s` and no transfer table plans as before).", ""]
    for name in sorted(p.name for p in out.joinpath("planning").glob("*.png")):
        L.append(f"![{name}](planning/{name})")
    jl = {r["plan"]: _json(out / "planning" / r["plan"] / "summary.json")["jerk_limit"] for r in rows}
    jt = jl["theoretical"]
    L += ["", "### Jerk limit", "",
          f"Every plan limits the crank jerk to {jt['crank_jerk_rad_s3']:g} rad/s^3 (`crank_jerk_rad_s3` in `door_panel.toml`) and is the "
          "time optimum under every limit and that jerk limit (direct collocation, IPOPT; limits held at the knots and between them; "
          "`planning/optimal.py`), started from toppra's jerk-free optimum, which is a lower bound on the stroke time. "
          "The moving-average smoothing of toppra's profile that planned before cost 3.52 s of stroke (11.40 spm) on the theoretical "
          "door panel. What the limit costs, at the same transfer window:", "",
          "| plan | stroke with the jerk limit [s] | stroke without it (bound) [s] | spm with | spm without | largest jerk [rad/s^3] | IPOPT |",
          "|---|---|---|---|---|---|---|"]
    for name, j in jl.items():
        without = j["strokes_per_min_without_jerk_limit"]
        opt = j.get("optimiser") or {}
        stroke = float(next(r["stroke_time_s"] for r in rows if r["plan"] == name))
        bound = f"{j['stroke_time_without_jerk_limit_s']:.4f}" if without is not None else "(breaks the thermal limit)"
        L.append(f"| {name} | {stroke:.4f} | {bound} | {j['strokes_per_min_with_jerk_limit']:.3f} | "
                 f"{f'{without:.3f}' if without is not None else '-'} | {j['max_crank_jerk_rad_s3']:.0f} | "
                 f"{opt.get('status', '-')}, {sum(opt.get('ipopt_iterations', []))} iterations |")
    jc = jl.get("calibrated")
    if jc and jt["strokes_per_min_without_jerk_limit"] and jc["strokes_per_min_without_jerk_limit"]:
        d_opt = 100.0 * (jc["strokes_per_min_with_jerk_limit"] / jt["strokes_per_min_with_jerk_limit"] - 1.0)
        d_bound = 100.0 * (jc["strokes_per_min_without_jerk_limit"] / jt["strokes_per_min_without_jerk_limit"] - 1.0)
        agree = "the same sign" if d_opt * d_bound > 0 else "OPPOSITE signs: the comparison then hinges on the jerk treatment, not on the press"
        L += ["", f"Calibrated minus theoretical: {d_opt:+.2f} % of production rate with the jerk limit, {d_bound:+.2f} % without it "
              f"({agree}). Which parameter moves which phase's torque is measured in planning/README.md (\"What we find\")."]
    L += energy_section(cmp_rec)
    L += modes_section(cmp_rec)
    if "robust" in cmp_rec:
        rb = cmp_rec["robust"]
        box = ", ".join(f"{n} [{lo:.5g}, {hi:.5g}]" for n, (lo, hi) in rb["box"].items())
        L += ["", "### Robust plan over the calibration's joint 95 % region", "",
              "The box holds every calibrated parameter's truth at once (calibrated.json's `joint_region`), not only each one alone: "
              "the plan must hold for the press, whose parameters are all true together.", "",
              f"Box: {box}" + (f" (clipped to the parameter ranges: {', '.join(rb['clipped_to_parameter_ranges'])})" if rb["clipped_to_parameter_ranges"] else "") + ".",
              f"The robust plan keeps |T_m| <= {cmp_rec['peak_torque_limit_Nm'] / cmp_rec['peak_torque_Nm']:g} T_max minus the feedback reserve at all "
              f"{rb['corners_checked']} corners of the box (worst corner {rb['worst_corner_peak_ratio']:.4f} T_max): "
              f"{rb['strokes_per_min_robust']:.3f} spm against {rb['strokes_per_min_nominal_calibrated']:.3f} spm for the calibrated values alone "
              f"({rb['rate_cost_percent']:+.2f} % cost): the jerk-limited optimum with each segment's worst corner's torque rows. "
              f"What drives the cost: {rb['cost_driver']['parameter']} ({100 * rb['cost_driver']['shares'].get(rb['cost_driver']['parameter'], 0):.0f} % "
              "of the torque spread at the binding knots; `servo-press design-experiment` designs runs that narrow it)."]
    if "playback" in cmp_rec:
        pb = cmp_rec["playback"]
        L += ["", "### Playback verification", "",
              f"The calibrated plan, played back through the forward dynamics of the calibrated model (Pinocchio constrained dynamics, "
              f"Baumgarte, RK4) with feed-forward + PD: max tracking error {pb['max_tracking_error_deg']:.4f} deg, peak motor torque "
              f"{pb['peak_motor_torque_Nm']:.0f} N m = {pb['peak_torque_ratio']:.3f} T_max (margin 0.9). Verdict: `{pb['verdict']['line']}`"]
    L += ["", "## Provenance", "", f"Packages: {', '.join(f'{k} {v}' for k, v in record['versions'].items())}.",
          "Parameters: `run.json` (theoretical and calibrated), and every step's own JSON.", "",
          "Wall time of each step on this machine: " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items())
          + f"; total {sum(timings.values()) if wall is None else wall:.1f} s"
          + (f" (the steps marked{SECOND_PROCESS} ran beside the others, so the steps add up to more)" if any(SECOND_PROCESS in k for k in timings) else "")
          + ".", ""]
    return "\n".join(L) + "\n"


def modes_section(cmp_rec: dict) -> list[str]:
    """report.md's modes comparison (comparison.json ``modes``, planning.mode = "auto"): per motion mode its strokes per
    minute with the theoretical, the calibrated (robust over the joint region) and the calibrated values alone, or why
    the job does not allow it or it could not be planned."""
    modes = cmp_rec.get("modes")
    if not modes:
        return []
    names = list(next(iter(modes.values()))["modes"])
    L = ["", "### Motion modes", "",
         "The door panel planned in every motion mode it allows (`planning.mode = \"auto\"`, planning/modes.py), each row's plan the "
         "fastest mode that keeps every limit. Strokes per minute:", "",
         "| mode | " + " | ".join(modes) + " |", "|---|" + "---|" * len(modes)]
    for n in names:
        cells = []
        for m in modes.values():
            r = m["modes"][n]
            cells.append("not allowed" if not r["allowed"] else ("not supported" if r.get("supported") is False else "infeasible")
                         if r["strokes_per_min"] is None
                         else f"{r['strokes_per_min']:.3f}" + ("" if r["keeps_every_limit"] else " (breaks a limit)"))
        L.append(f"| {n} | " + " | ".join(cells) + " |")
    why = [f"* {n} ({p}): {r.get('why_not') or r.get('infeasible')}" for p, m in modes.items() for n, r in m["modes"].items()
           if not r["allowed"] or r["strokes_per_min"] is None]
    vs = "; ".join(f"{n} {r['vs_stop_at_top_percent']:+.1f} % ({p})" for p, m in modes.items() for n, r in m["modes"].items()
                   if "vs_stop_at_top_percent" in r)
    L += ["", "Planned: " + ", ".join(f"{p} {m['planned']}" for p, m in modes.items()) + "."]
    L += [f"Against the stop-at-top plan of the same transfer: {vs}."] if vs else []
    return L + (["", *why] if why else [])


def energy_section(cmp_rec: dict) -> list[str]:
    """report.md's lines on each plan's energy per stroke (comparison.json ``energy``; none without [drive.electrical])."""
    rows = {k: e for k, e in cmp_rec.get("energy", {}).items() if "drawn_J" in e}
    if not rows:
        return []
    L = ["", "### Energy per stroke", "",
         "What each plan draws from the grid through the reference press's drive and supply (`[drive.electrical]`: values chosen "
         "for its class of motors, not the paper's; press_model/README.md, \"Energy and power\"). Energies in MJ a stroke, powers in MW.", "",
         "| plan | spm | drawn | returned | grid peak | shaft peak | copper | inverter + infeed | gear | friction | process work |",
         "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, e in rows.items():
        lost = e["lost_J"]
        L.append(f"| {name} | {e['strokes_per_min']:.3f} | {e['drawn_J'] / 1e6:.3f} | {e['returned_J'] / 1e6:.3f} | {e['grid_peak_W'] / 1e6:.2f} | "
                 f"{e['shaft_peak_W'] / 1e6:.2f} | {lost['copper_J'] / 1e6:.3f} | {(lost['inverter_J'] + lost['infeed_J']) / 1e6:.3f} | "
                 f"{lost['gear_J'] / 1e6:.3f} | {lost['friction_J'] / 1e6:.3f} | {lost['process_work_J'] / 1e6:.3f} |")
    L += ["", *(f"![{name}: power and DC-link voltage](planning/{name}/power.png)" for name in rows)]
    return L


def design_section(d: dict, cal_rec: dict) -> list[str]:
    """Beyond the paper: the designed calibration experiment (`design-experiment`) beside the single cushion test, and
    the cushion test's predicted half-widths beside the ones this run's calibration reached (Jacobian intervals)."""
    a, de, c = d["aim"], d["design"], d["cushion_test"]
    L = ["## Beyond the paper: a designed calibration experiment", "",
         f"`servo-press design-experiment` chose {len(de['runs'])} runs (D-optimal on the information of the calibrated parameters, "
         "every run's model torque within the feed-forward limit, the torque margin less `plan`'s feedback reserve, on 0.25-deg points, and "
         "within the speed and thermal limits, for every parameter draw; `design/report.md`). "
         "Predicted 95 % interval widths as a share of each calibration range, design against the paper's single cushion test, on the "
         "same noise level:", "",
         "| parameter | design | single cushion test | cushion test: predicted half-width | cushion test: this run's Jacobian half-width |",
         "|---|---|---|---|---|"]
    for n in d["parameters"]:
        lo, hi = cal_rec["intervals_jacobian"][n]
        L.append(f"| {n} | {100 * de['width_share_of_range'][n]:.1f} % | {100 * c['width_share_of_range'][n]:.1f} % | "
                 f"{c['half_widths'][n]:.4g} | {(hi - lo) / 2:.4g} |")
    L += ["", f"Largest |correlation|: design {a['design_max_abs_correlation']['value']:.2f}, cushion test "
          f"{a['cushion_test_max_abs_correlation']['value']:.2f} ({' and '.join(a['cushion_test_max_abs_correlation']['pair'])}); "
          f"widest interval {a['cushion_test_widest']['parameter']} {100 * a['cushion_test_widest']['width_share_of_range']:.1f} % -> "
          f"{a['design_widest']['parameter']} {100 * a['design_widest']['width_share_of_range']:.1f} % ({a['widest_interval_ratio']:.1f}x narrower).",
          "", "![designed runs and predicted intervals](design/design.png)", ""]
    return L


def reproduce_job(out: str, quick: bool = False, seed: int = 0) -> tuple[float, dict | None]:
    """The 'reproduce' command: :func:`run_reproduce` into the folder ``out`` (written whole at the end); returns
    the wall time it took (s) and the calibration's verdict (:mod:`press_model.calibration_verdict`)."""
    t0 = time.perf_counter()
    with output_folder(out, (), "reproduce") as tmp:
        rec = run_reproduce(tmp, quick=quick, seed=seed)
    return time.perf_counter() - t0, rec.get("calibration_verdict")
