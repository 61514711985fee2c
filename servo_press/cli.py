"""The ``servo-press`` command line: the composition root that wires press data, model and reports."""
from __future__ import annotations

import argparse
import difflib
import gc
import re
import sys
from pathlib import Path

from press_io.errors import ServoPressError, one_line, os_error
from press_io.interrupts import exit_status, handled


def _warn(text: str) -> None:
    print(f"WARNING: {one_line(text)}", file=sys.stderr)


def _note(text: str) -> None:
    """A warning of a run that goes on as asked, with something the user should know (lower case: not a broken limit)."""
    print(f"warning: {one_line(text)}", file=sys.stderr)


def cmd_urdf(args) -> int:
    from .urdf import urdf_job

    urdf, loops = urdf_job(args.press, args.out)
    print(f"wrote {urdf} and {loops}")
    return 0


def cmd_simulate(args) -> int:
    from press_model.plots import figure_worker

    from .simulate import SimulateCase, simulate_job

    case = SimulateCase(args.motion, args.load or "cushion", args.spm, args.step_deg, args.playback, args.job)
    with figure_worker() as figures:  # forked first: matplotlib's import runs beside the model's
        warnings, lines = simulate_job(args.press, args.params, case, args.out, figures)
    for w in warnings:
        _warn(w)
    print("\n".join(lines))
    return 0


def cmd_sensitivity(args) -> int:
    from calibration.sensitivity.report import SobolPlan, sensitivity_job

    plan = SobolPlan(args.n, args.seed, args.second_order, args.convergence, args.n_min, args.n_max)
    print("\n".join(sensitivity_job(args.press, args.job, args.profile, plan, args.out, warn=_warn)))
    return 0


def cmd_experiment(args) -> int:
    from calibration.synthetic.fleet import experiment_job

    def progress(i, n, path):
        print(f"  [{i}/{n}] {path.name}", file=sys.stderr, flush=True)

    print("\n".join(experiment_job(args.press, args.job, args.truth, args.seed, args.out, (args.fleet, args.drift),
                                     progress, effects=args.effect)))
    return 0


def cmd_calibrate(args) -> int:
    from calibration.identification.inputs import FitChoice, LogFormat

    from .calibrate import calibrate_job

    warnings, lines = calibrate_job(args.press, args.job or ["cushion-test"], args.log, args.validate,
                                    LogFormat(args.torque_unit, args.log_format), FitChoice(args.method, args.parameters, args.seed),
                                    args.out)
    for w in warnings:
        print(w, file=sys.stderr)
    print("\n".join(lines))
    return 0


def cmd_monitor(args) -> int:
    from calibration.fleet.cluster import Workers
    from calibration.fleet.monitor_report import monitor_fleet
    from calibration.identification.inputs import FitChoice, LogFormat

    print("\n".join(monitor_fleet(args.press, args.job, args.logs, args.baseline, args.out, FitChoice(args.method, seed=args.seed),
                                 LogFormat(args.torque_unit, args.log_format), Workers(args.workers, args.scheduler))))
    return 0


def cmd_strokes(args) -> int:
    from calibration.fleet.cluster import Workers
    from monitoring.run import run_strokes

    print("\n".join(run_strokes(args.logs, args.press, args.job, args.params, args.press_id, args.out, args.rules,
                                 Workers(args.workers, args.scheduler))))
    return 0


VERIFY_FAILED = 3  # exit status of plan --verify / compare when the playback breaks a limit (bad input stays 2)


def cmd_plan(args) -> int:
    from planning.report import plan_job, plan_lines, plan_warnings

    name, info, pb = plan_job(args.press, args.job, args.params, args.out, args.robust, args.verify, args.nominal, args.pareto)
    for w in (info.get("robust") or {}).get("warnings", []):
        _note(w)
    for w in plan_warnings(info):
        _warn(w)
    print("\n".join(plan_lines(name, info, pb, Path(args.out))))
    return VERIFY_FAILED if pb is not None and not pb["verdict"]["ok"] else 0


def cmd_compare(args) -> int:
    from planning.compare import compare_job, compare_lines

    from press_model.calibration_verdict import verdict_warning

    rec = compare_job(args.press, args.job, args.calibrated, args.out, verify=not args.no_verify)
    for w in (rec.get("robust") or {}).get("warnings", []):
        _note(w)
    w = verdict_warning(rec.get("calibration_verdict"))
    if w:
        _warn(w)
    print("\n".join(compare_lines(rec, Path(args.out))))
    return VERIFY_FAILED if "playback" in rec and not rec["playback"]["verdict"]["ok"] else 0


def cmd_design_experiment(args) -> int:
    from .design_experiment import design_job, design_lines

    rec = design_job(args.press, args.job, args.parameters, args.runs, args.out, verify=not args.no_verify, calibrated=args.calibrated)
    print("\n".join(design_lines(rec, Path(args.out))))
    ok = all(r["playback"]["verdict"]["ok"] for r in rec["design"]["runs"] if "playback" in r)
    return 0 if ok else VERIFY_FAILED


def cmd_reproduce(args) -> int:
    from .reproduce import reproduce_job

    from press_model.calibration_verdict import verdict_warning

    seconds, verdict = reproduce_job(args.out, quick=args.quick, seed=args.seed)
    w = verdict_warning(verdict)
    if w:
        _warn(w)
    print(f"reproduced the paper{' (quick)' if args.quick else ''} in {seconds:.1f} s -> {args.out}/report.md")
    return 0


def _seed(text: str) -> int:
    """argparse type of --seed: numpy and SALib take only non-negative integer seeds."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; a seed is a whole number >= 0")
    return value


def _count(text: str) -> int:
    """argparse type of a count (--workers, --fleet): a whole number >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not a count: give a whole number >= 1")
    return value


class _Parser(argparse.ArgumentParser):
    """argparse with the error format of servo_press/README.md: one line ``servo-press: error: ...`` on stderr, exit 2."""

    def error(self, message):
        hint = f"see '{self.prog} --help'"
        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            close = difflib.get_close_matches(m.group(1), re.findall(r"'([^']*)'", m.group(2)), n=1)
            hint = (f"did you mean '{close[0]}'? " if close else "") + hint
        self.exit(2, f"servo-press: error: {one_line(message)}; {hint}\n")


def _version() -> str:
    from press_io.outputs import versions  # the package metadata read once a process

    installed = versions()["servo-press-twin"]
    return "servo-press (not installed: running from a source tree)" if installed == "not installed" else f"servo-press {installed}"


def build_parser() -> argparse.ArgumentParser:
    from calibration.identification.methods import METHODS
    from calibration.traces.units import TORQUE_UNITS
    from press_model.limits import run_limits

    p = _Parser(prog="servo-press", description="Dynamics model, calibration and stroke planning for servo presses. "
                "Bad input is refused with one line 'servo-press: error: ...' and exit code 2. A run's output folder "
                "is written whole or not at all, also when Ctrl-C (exit 130) or SIGTERM (143) stops the run, and replaces "
                "only its own command's earlier result there, and only while that is as the run wrote it; monitor "
                "resumes its folder instead.")
    p.add_argument("--version", action="version", version=_version())
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    lim = run_limits()
    folder = ("output folder; written whole at the end, replacing this command's earlier, unchanged result folder there "
              "whole; a link to a folder: that folder (required)")

    def press_arg(sp):
        sp.add_argument("--press", default=None, metavar="FILE",
                        help="press TOML file, or a built-in name: 'reference' or 'crank-slider' (default: reference)")

    def params_arg(sp, example="such as calibrated.json"):
        sp.add_argument("--params", default=None, metavar="JSON",
                        help='parameter overrides in SI units: a JSON object (e.g. \'{"m8": 32940}\') or a JSON file '
                        f"{example}; a file made on another press is refused (default: none, the press file's values)")

    u = sub.add_parser("urdf", help="write the linkage as a URDF tree plus its loop-closure file")
    press_arg(u)
    u.add_argument("--out", default=None, metavar="FILE.urdf",
                   help="URDF path; the loop file is written beside it (.loops.json). An existing file is replaced only "
                   "if it is the URDF of the same press (default: <press name>.urdf in the current folder)")
    u.set_defaults(func=cmd_urdf)

    s = sub.add_parser("simulate", help="one crank turn: kinematics, reactions and motor torque")
    press_arg(s)
    params_arg(s)
    s.add_argument("--motion", choices=("constant", "cushion-test"), default="cushion-test",
                   help="crank motion: constant speed, or the cushion test's modulated speed (default: %(default)s)")
    s.add_argument("--spm", type=float, default=None,
                   help="strokes per minute (default: the --job's [motion] rate if it has one, else 11.4)")
    load = s.add_mutually_exclusive_group()
    load.add_argument("--load", choices=("none", "cushion", "door-panel"), default=None,
                      help="a built-in process force on the slide: none, the shipped 5,000 kN servo cushion, or the shipped "
                      "door panel's drawing force (default: cushion)")
    load.add_argument("--job", default=None, metavar="JOB.toml",
                      help="your own job file (or a built-in job's name): its [process] force is the load and its [motion], "
                      "if it has one, the motion (instead of --motion) (default: none: --load)")
    s.add_argument("--step-deg", type=float, default=1.0,
                   help=f"crank-angle step in degrees, dividing 360, from {lim.min_step_deg:g} to {lim.max_step_deg:g} (default: %(default)s)")
    s.add_argument("--playback", action="store_true", help="also play the motor torque back through the forward dynamics (playback.csv)")
    s.add_argument("--out", required=True, metavar="DIR", help=folder)
    s.set_defaults(func=cmd_simulate)

    g = sub.add_parser("sensitivity", help="Sobol indices of the 28 parameters on Y_RMSE, Y_PR, Y_TL, Y_Work (Section 3)")
    press_arg(g)
    g.add_argument("--n", type=int, default=2048, help=f"Sobol base sample size, a power of two from {lim.min_n} to {lim.max_n}; "
                   f"below {lim.warn_below_n} a WARNING says the intervals are wide (default: %(default)s)")
    g.add_argument("--seed", type=_seed, default=0, help="seed of the scrambled Sobol design and the bootstrap (default: %(default)s)")
    g.add_argument("--job", default="cushion-test", metavar="FILE",
                   help="load case: a job file with [process] (optional: no process force) and [motion], or a built-in job: "
                        "cushion-test, no-load, door-panel (needs --profile) (default: %(default)s)")
    g.add_argument("--profile", default=None, metavar="PROFILE.csv",
                   help="take the crank motion from a planned profile CSV (profile.csv of `servo-press plan`: one turn, the dwell "
                        "left out) with the process force of --job (default: the job's [motion])")
    g.add_argument("--second-order", action="store_true", help="also compute second-order indices (N (2D+2) cycles)")
    g.add_argument("--convergence", action="store_true", help="instead: S_T of the key parameters for N from --n-min to --n-max")
    g.add_argument("--n-min", type=int, default=256, help="with --convergence: smallest N, a power of two (default: %(default)s)")
    g.add_argument("--n-max", type=int, default=8192, help="with --convergence: largest N, a power of two (default: %(default)s)")
    g.add_argument("--out", required=True, metavar="DIR", help=folder)
    g.set_defaults(func=cmd_sensitivity)

    pl = sub.add_parser("plan", help="time-optimal stroke of a job with toppra (Section 4.3): profile.csv, summary.json, figures")
    press_arg(pl)
    pl.add_argument("--job", default="door-panel", metavar="FILE",
                    help="job file with [process], [planning] and [playback], or 'door-panel' (default: %(default)s)")
    params_arg(pl)
    pl.add_argument("--verify", action="store_true", help="also play the plan back through the forward dynamics with feed-forward + PD "
                    "(playback.csv); exit status 3 and a VERIFY FAILED line if the playback breaks a limit")
    pl.add_argument("--robust", action="store_true", help="the default for a --params calibrated.json with a joint 95 %% region (its "
                    "\"joint_region\" box: every parameter's truth inside it at once; a file written before the joint region existed: "
                    "its per-parameter \"intervals\"), kept as an alias: plan so that the torque margin holds over the whole region; "
                    "refused without one")
    pl.add_argument("--nominal", action="store_true", help="plan at --params calibrated.json's values alone (the point estimate) "
                    "instead of over its joint region; prints a WARNING with the peak torque the plan reaches at the region's worst corner")
    pl.add_argument("--pareto", action="store_true", help="also plan at a row of grid peak-power limits ([planning.power] of the job) "
                    "and write the front of strokes per minute against grid peak power and energy per stroke (pareto.csv, pareto.png); "
                    "needs [drive.electrical] in the press file")
    pl.add_argument("--out", required=True, metavar="DIR", help=folder)
    pl.set_defaults(func=cmd_plan)

    cp = sub.add_parser("compare", help="plan with the theoretical and the calibrated parameters and cross-evaluate both plans")
    press_arg(cp)
    cp.add_argument("--calibrated", required=True, metavar="JSON",
                    help="calibrated.json of `servo-press calibrate` on the same press, or a JSON object of parameter values "
                    "(required; it must name at least one parameter); with a joint region (or \"intervals\") the calibrated row is the plan "
                    "robust over it and a third row, calibrated-nominal, the plan at the calibrated values alone")
    cp.add_argument("--job", default="door-panel", metavar="FILE", help="job file, or 'door-panel' (default: %(default)s)")
    cp.add_argument("--no-verify", action="store_true", help="skip the forward-dynamics playback of the calibrated plan "
                    "(with it: exit status 3 and a VERIFY FAILED line if the playback breaks a limit)")
    cp.add_argument("--out", required=True, metavar="DIR", help=folder)
    cp.set_defaults(func=cmd_compare)

    e = sub.add_parser("experiment", help="write a SYNTHETIC drive log of the servo-cushion calibration experiment (Section 4.1)")
    press_arg(e)
    e.add_argument("--job", default="cushion-test", metavar="FILE",
                   help="job file with [motion], [process] and [experiment], or a shipped job: cushion-test, or "
                   "cushion-validation (another motion, for calibrate --validate) (default: %(default)s)")
    e.add_argument("--seed", type=_seed, default=0, help="seed of the measurement noise (default: %(default)s)")
    e.add_argument("--truth", default=None, metavar="JSON",
                   help="synthetic truth: JSON object or file of parameter values (SI); parameters not named take their "
                   "theoretical values (default: the job's [experiment.truth], Table 4)")
    e.add_argument("--fleet", type=_count, default=None, metavar="N",
                   help="instead: a SYNTHETIC fleet of N dated logs whose truth drifts; --out is then a folder, written whole at "
                   "the end (fleet.json holds the schedule) (default: one log)")
    e.add_argument("--drift", default=None, metavar="FILE",
                   help="drift schedule TOML of --fleet (default: the shipped press_model/data/synthetic_fleet.toml)")
    e.add_argument("--effect", action="append", default=None, metavar="NAME=VALUE",
                   help="a SYNTHETIC effect of a real log, applied to the log and not in the model (repeatable): channel_delay_s, "
                   "angle_offset_deg, efficiency_drop_at_rated, viscous_loss_of_rms, noise_ar1_rho, ripple_of_rms, ripple_order "
                   "(calibration/synthetic/effects.py) (default: the job's [experiment.effects], else none)")
    e.add_argument("--out", required=True, metavar="LOG.csv",
                   help="drive-log CSV to write, the truth beside it in <name>.truth.json; an existing file is replaced only "
                   "if it is an earlier synthetic log (required)")
    e.set_defaults(func=cmd_experiment)

    c = sub.add_parser("calibrate", help="calibrate the key parameters against a drive log (Eq. 28, Section 4.2)")
    press_arg(c)
    c.add_argument("--log", required=True, metavar="LOG.csv", action="append",
                   help="drive-log CSV: time_s, crank_angle_deg, motor_speed_rpm, motor_torque_Nm (per motor) (required); "
                   "repeat it to fit several logs jointly (another speed, another cushion force)")
    c.add_argument("--job", default=None, metavar="FILE", action="append",
                   help="job file of the logged experiment: its process force and [calibration]; with several --log, one "
                   "--job per log in order, or one for all (default: cushion-test)")
    c.add_argument("--method", choices=(*METHODS, "all"), default=None,
                   help="optimiser; 'all' runs and compares all three (default: the job's default_method, aco)")
    c.add_argument("--parameters", default=None, metavar="FILE|LIST",
                   help="parameters to calibrate: key_parameters.json of `sensitivity`, or a comma list such as "
                   "eta_gear,mu_r (default: the job's list, the paper's six)")
    c.add_argument("--seed", type=_seed, default=0, help="seed of the stochastic optimisers and random starts (default: %(default)s)")
    c.add_argument("--torque-unit", choices=tuple(TORQUE_UNITS), default="N*m", help="unit of the log's torque column (default: %(default)s)")
    c.add_argument("--log-format", default=None, metavar="MAP.toml",
                   help="channel map of a drive trace (TwinCAT Scope CSV export, NI TDMS, or a CSV with other names): which "
                   "channel is which, in which unit; used for --log and --validate (default: the plain drive-log CSV)")
    c.add_argument("--validate", default=None, metavar="LOG.csv",
                   help="a second drive log (another day, another motion; same press and process) predicted with the "
                   "theoretical and the calibrated parameters, not fitted: 'validation' in calibrated.json (default: none)")
    c.add_argument("--out", required=True, metavar="DIR", help=folder)
    c.set_defaults(func=cmd_calibrate)
    de = sub.add_parser("design-experiment", help="design calibration runs that identify the key parameters (D-optimal, within the motor's limits)")
    press_arg(de)
    de.add_argument("--job", default="cushion-test", metavar="FILE",
                    help="job with [design] (what the press and cushion can do) and [calibration] (default: %(default)s)")
    de.add_argument("--parameters", default=None, metavar="FILE|LIST",
                    help="parameters to identify: key_parameters.json of `sensitivity`, or a comma list (default: the job's list)")
    de.add_argument("--runs", type=int, default=None, help="number of runs (default: the job's [design] runs, 2)")
    de.add_argument("--calibrated", default=None, metavar="FILE",
                    help="calibrated.json of a first calibration of this press: the noise of its stroke-averaged curve and that "
                    "noise's AR(1) inflation (adequacy.pure_error_rms_Nm, pure_error_lag1) instead of the job's [design] "
                    "noise_rms_Nm and noise_inflation (default: the job's)")
    de.add_argument("--no-verify", action="store_true", help="skip the forward-dynamics playback of each run (default: play each back)")
    de.add_argument("--out", required=True, metavar="DIR", help=folder)
    de.set_defaults(func=cmd_design_experiment)
    mo = sub.add_parser("monitor", help="calibrate every drive log of a press, track the parameters over time and raise alarms")
    press_arg(mo)
    mo.add_argument("--logs", required=True, metavar="DIR|GLOB",
                    help="folder of drive logs (*.csv; with --log-format also *.tdms traces), or a quoted glob; ordered by their "
                    "'# recorded:' date (a trace's own start time), else by name (required)")
    mo.add_argument("--job", default="cushion-test", metavar="FILE",
                    help="job file of the logged experiment: its process force and [calibration] (default: %(default)s)")
    mo.add_argument("--baseline", default=None, metavar="FILE",
                    help="calibrated.json to compare every log with (default: the first log that calibrates with a good fit)")
    mo.add_argument("--workers", type=_count, default=None, metavar="N",
                    help="local worker processes; 1 runs in this process (default: the number of cores)")
    mo.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="address of a Dask scheduler, e.g. tcp://10.0.0.5:8786, to run the calibrations on that cluster (default: local processes)")
    mo.add_argument("--method", choices=METHODS, default=None,
                    help="optimiser (default: the job's default_method; aco, the ant colony, in the shipped jobs)")
    mo.add_argument("--seed", type=_seed, default=0, help="seed of the optimiser, the same for every log (default: %(default)s)")
    mo.add_argument("--torque-unit", choices=tuple(TORQUE_UNITS), default="N*m", help="unit of the logs' torque column (default: %(default)s)")
    mo.add_argument("--log-format", default=None, metavar="MAP.toml",
                    help="channel map the logs are read through (TwinCAT Scope CSV exports, NI TDMS *.tdms, CSVs with other "
                    "names) (default: plain drive-log CSVs)")
    mo.add_argument("--out", required=True, metavar="DIR",
                    help="output folder: trend.csv, alarms.json, trend.png, report.md and logs/ (one result per log); an earlier "
                    "monitor folder is resumed, not replaced (required)")
    mo.set_defaults(func=cmd_monitor)
    st = sub.add_parser("strokes", help="the slide force of every stroke from the drive torque (virtual tonnage) into a per-stroke "
                        "Parquet store, with force-band and drift alarms")
    press_arg(st)
    st.add_argument("--logs", required=True, metavar="DIR|GLOB", help="folder of drive logs (*.csv) or a quoted glob (required)")
    st.add_argument("--job", default="cushion-test", metavar="FILE",
                    help="job file of the production: its process force (the alarms' band) and peak window (default: %(default)s)")
    st.add_argument("--params", required=True, metavar="JSON",
                    help="calibrated.json of `servo-press calibrate`: the parameters and their joint region (required)")
    st.add_argument("--press-id", required=True, metavar="NAME", help="the press's name in the store (its partition press=NAME) (required)")
    st.add_argument("--rules", default=None, metavar="FILE", help="tonnage rules (default: press_model/data/tonnage.toml)")
    st.add_argument("--workers", type=_count, default=None, metavar="N",
                    help="local worker processes; 1 runs in this process (default: 1)")
    st.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="address of a Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: local processes)")
    st.add_argument("--out", required=True, metavar="STORE",
                    help="the store folder: STORE/press=NAME/day=DAY/*.parquet, STORE/_reports/NAME/drift.json and trend.png; "
                    "new logs are added, a log given again replaces its own records (required)")
    st.set_defaults(func=cmd_strokes)
    r = sub.add_parser("reproduce", help="the whole paper on the embedded reference press, with report.md (the main job)")
    r.add_argument("--out", default="out/reproduce", metavar="DIR",
                   help="output folder, replaced whole at the end (default: %(default)s)")
    r.add_argument("--quick", action="store_true", help="N = 256 and one calibration method (the ant colony): the same pipeline, faster")
    r.add_argument("--seed", type=_seed, default=0, help="seed of the Sobol design, the synthetic noise and the optimisers (default: %(default)s)")
    r.set_defaults(func=cmd_reproduce)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with handled():  # Ctrl-C and SIGTERM: one exception that every command's cleanup sees (press_io.interrupts)
            return args.func(args)
    except ServoPressError as exc:
        print(f"servo-press: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # an output path the system refuses (a file where a folder is wanted, no permission ...)
        print(f"servo-press: error: {os_error(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C: 130, SIGTERM: 143, as a shell reports a process those signals ended
        print("servo-press: interrupted", file=sys.stderr)
        return exit_status(exc)


def run() -> None:
    """The ``servo-press`` program: :func:`main` with the garbage collector set for a short-lived process."""
    # the imports of a command (scipy, matplotlib, numba, Pinocchio) leave ~1M objects that live as long as
    # the process; with Python's default threshold (700) the collector walks them all several times during
    # start-up and once more at exit, and finds nothing to free (0.5 s of the 6 s of sensitivity --n 2048,
    # scripts/bench_sensitivity.py). Cyclic garbage made while a command runs is still collected
    gc.set_threshold(10_000, 10, 10)
    code = main()
    stop_while_exiting(code)
    gc.freeze()  # what is left at exit goes with the process, without a last walk over it
    sys.exit(code)


def stop_while_exiting(code: int) -> None:
    """From now until the process ends (the interpreter's exit, libraries' exit hooks): Ctrl-C or SIGTERM ends it at
    once with 128 + the signal and one line ``servo-press: interrupted`` (not printed twice), instead of a
    KeyboardInterrupt raised inside an exit hook, which Python reports as 'Exception ignored in ...' with a
    traceback. The command's work is over by then; this only keeps the exit quiet and its status honest."""
    import os
    import signal

    def stop(signum, frame):
        try:
            if code not in (130, 143):
                print("servo-press: interrupted", file=sys.stderr)
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(128 + signum)

    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, stop)


if __name__ == "__main__":
    run()
