"""The ``servo-press`` command line: the composition root that wires press data, model and reports."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from press_model.errors import ServoPressError, os_error


def _load_model(args):
    from press_model.model import PressModel
    from press_model.params import apply_overrides, read_overrides
    from press_model.press_data import load_press

    overrides = read_overrides(getattr(args, "params", None))
    press = apply_overrides(load_press(args.press), overrides)
    return PressModel(press), overrides


def cmd_urdf(args) -> int:
    from press_model.press_data import load_press
    from press_model.urdf import write_urdf

    press = load_press(args.press)
    from press_model.model import PressModel

    PressModel(press)  # refuse to write a URDF of a linkage that cannot assemble
    urdf, loops = write_urdf(press, Path(args.out))
    print(f"wrote {urdf} and {loops}")
    return 0


def cmd_simulate(args) -> int:
    from .simulate import run_simulate

    pm, overrides = _load_model(args)
    info = run_simulate(pm, args.motion, args.load, args.spm, args.step_deg, Path(args.out), overrides, args.playback)
    print(
        f"{pm.press.name}: peak motor torque {info['peak_motor_torque_Nm']:.0f} N m, RMS {info['rms_motor_torque_Nm']:.0f} N m, "
        f"motor work {info['motor_work_all_motors_J'] / 1e3:.1f} kJ per cycle -> {args.out}"
    )
    if "playback" in info:
        pb = info["playback"]
        print(f"forward-dynamics playback: max loop gap {pb['max_loop_gap_m']:.2e} m, crank angle at cycle end off by {pb['final_crank_angle_error_deg']:+.2f} deg")
    return 0


def cmd_sensitivity(args) -> int:
    from calibration.sensitivity_report import powers_of_two, run_convergence, run_sensitivity

    pm, _ = _load_model(args)
    if args.convergence:
        ns = powers_of_two(args.n_min, args.n_max)
        rows = run_convergence(pm, ns, args.seed, Path(args.out))
        print(f"convergence of S_T over N = {ns[0]}..{ns[-1]} ({len(rows)} rows) -> {args.out}/convergence.csv, convergence.png")
        return 0
    rec = run_sensitivity(pm, args.n, args.seed, args.second_order, Path(args.out))
    t = rec["timing_s"]
    print(f"{rec['model_cycles']} model cycles in {t['evaluation']:.1f} s (total {t['total']:.1f} s); "
          f"key parameters: {', '.join(rec['key_parameters'])} -> {args.out}")
    return 0


def cmd_experiment(args) -> int:
    from calibration.experiment import ExperimentSettings, truth_path, write_experiment

    from press_model.jobs import load_job
    from press_model.params import read_overrides
    from press_model.press_data import load_press

    press = load_press(args.press)
    job = load_job(args.job)
    truth = read_overrides(args.truth) if args.truth is not None else ExperimentSettings.from_job(job).truth
    out = Path(args.out)
    _refuse_overwrite_input(out, [args.press, args.job, args.truth])
    prov = write_experiment(press, job, truth, args.seed, out)
    print(f"wrote SYNTHETIC drive log {out} ({prov['effects']['strokes']} strokes at {prov['effects']['sample_rate_Hz']:g} Hz, seed {args.seed}); "
          f"truth in {truth_path(out)}")
    return 0


def cmd_calibrate(args) -> int:
    from calibration.run import calibrate, key_parameters, write_outputs
    from calibration.settings import METHODS, CalibrationSettings

    from press_model.jobs import load_job
    from press_model.press_data import load_press

    press = load_press(args.press)
    job = load_job(args.job)
    cs = CalibrationSettings.from_job(job)
    methods = list(METHODS) if args.method == "all" else [args.method or cs.default_method]
    names = key_parameters(args.parameters, cs.parameters)
    out = Path(args.out)
    _refuse_overwrite_input(out / "calibrated.json", [args.log])
    cal = calibrate(press, job, Path(args.log), methods, args.seed, names, args.torque_unit)
    rec = write_outputs(cal, press, job, args.seed, out)
    m = rec["metrics"]
    for w in cal.log.warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(f"{'SYNTHETIC ' if cal.log.synthetic else ''}log {args.log}: {cal.log.strokes} strokes; method {rec['method']}: "
          f"RMSE {m['rmse_before_Nm']:.1f} -> {m['rmse_after_Nm']:.1f} N m, peak error {m['peak_error_before_Nm']:+.0f} -> {m['peak_error_after_Nm']:+.0f} N m, "
          f"thermal error {100 * m['thermal_error_before']:+.2f} % -> {100 * m['thermal_error_after']:+.2f} %")
    for n, x in rec["parameters"].items():
        lo, hi = rec["intervals"][n]
        print(f"  {n:>9} = {x:.6g}  (95 % interval {lo:.6g} .. {hi:.6g})")
    print(f"-> {out}/calibrated.json, table4.csv/.md, figure5.png")
    return 0


VERIFY_FAILED = 3  # exit status of plan --verify / compare when the playback breaks a limit (bad input stays 2)


def cmd_plan(args) -> int:
    from planning.progress import Progress
    from planning.report import run_plan

    from press_model.jobs import load_job, read_planning

    job = load_job(args.job)
    spec = read_planning(job)
    pm, overrides = _load_model(args)
    box = None
    if args.robust:
        from planning.robust import Box

        from press_model.params import read_intervals

        if args.params is None:
            raise ServoPressError("plan --robust needs --params calibrated.json (the calibration's values and 95 % intervals)")
        center, intervals = read_intervals(args.params)
        box = Box.from_calibration(pm.press, center, intervals, str(args.params))
    out = Path(args.out)
    _refuse_overwrite_input(out, [args.press, args.job, getattr(args, "params", None)])
    progress = Progress("plan")
    plan, info = run_plan(pm, job, spec, out, overrides, box, progress)
    b = {k: v["dominant"] for k, v in info["binding_constraints"].items() if isinstance(v, dict) and k != "dwell"}
    jl = info["jerk_limit"]
    print(f"{job.name}: {info['strokes_per_min']:.3f} spm (stroke {info['stroke_time_s']:.3f} s + dwell {info['dwell_s']:.3f} s); "
          f"peak torque {info['peak_torque_Nm']:.0f} N m ({info['peak_torque_ratio']:.3f} T_max), RMS {info['rms_torque_Nm']:.0f} N m; "
          f"binding: {', '.join(f'{k} {v}' for k, v in b.items())}; thermal {info['binding_constraints']['thermal_rms']} -> {out}")
    if jl["crank_jerk_rad_s3"] is not None:
        without = jl["strokes_per_min_without_jerk_limit"]
        print(f"jerk limit {jl['crank_jerk_rad_s3']:g} rad/s^3 (largest {jl['max_crank_jerk_rad_s3']:.0f}): {jl['strokes_per_min_with_jerk_limit']:.3f} spm; "
              + (f"{without:.3f} spm without it" if without is not None else "without it the stroke breaks the thermal limit"))
    if "robust" in info:
        r = info["robust"]
        print(f"robust over the calibration box: {r['strokes_per_min_robust']:.3f} spm against {r['strokes_per_min_nominal_calibrated']:.3f} spm "
              f"for the calibrated values alone (rate cost {r['rate_cost_percent']:+.2f} %; the jerk smoothing scatters stroke times by ~0.1 %); "
              f"worst of {r['corners_checked']} corners "
              f"{r['worst_corner_peak_ratio']:.4f} T_max")
    if args.verify:
        from planning.playback import run_playback

        with progress.phase("playback through the forward dynamics (FF + PD)"):
            pb = run_playback(pm, job, spec, plan, out, progress=progress.bar("playback"))
        print(pb["verdict"]["line"])
        if not pb["verdict"]["ok"]:
            return VERIFY_FAILED
    return 0


def cmd_compare(args) -> int:
    from planning.compare import run_compare
    from planning.progress import Progress

    from press_model.jobs import load_job, read_planning
    from press_model.params import read_intervals, read_overrides
    from press_model.press_data import load_press

    job = load_job(args.job)
    spec = read_planning(job)
    calibrated = read_overrides(args.calibrated)
    try:
        _, intervals = read_intervals(args.calibrated)
    except ServoPressError:
        intervals = None  # no intervals: no robust row
    out = Path(args.out)
    _refuse_overwrite_input(out, [args.press, args.job, args.calibrated])
    rec = run_compare(load_press(args.press), job, spec, calibrated, out, verify=not args.no_verify, intervals=intervals,
                      progress=Progress("compare"))
    for r in rec["rows"]:
        print(f"{r['plan']:>12} plan: {r['strokes_per_min']:.3f} spm; peak/T_max {r['peak_ratio_theoretical_model']:.3f} (theoretical model), "
              f"{r['peak_ratio_calibrated_model']:.3f} (calibrated model); RMS {r['rms_theoretical_model_Nm']:.0f} / {r['rms_calibrated_model_Nm']:.0f} N m")
    print(f"production rate {rec['rows'][0]['strokes_per_min']:.2f} -> {rec['rows'][1]['strokes_per_min']:.2f} spm "
          f"({rec['rate_gain_percent']:+.2f} %); paper: 11.4 -> 11.6 spm (+1.75 %) -> {out}")
    if "robust" in rec:
        r = rec["robust"]
        print(f"robust plan over the calibration box: {r['strokes_per_min_robust']:.3f} spm, rate cost {r['rate_cost_percent']:+.2f} % against the "
              "calibrated plan (the jerk smoothing scatters stroke times by ~0.1 %)")
    if "playback" in rec:
        pb = rec["playback"]
        print(f"calibrated plan played back on the calibrated model (FF + PD): max tracking error {pb['max_tracking_error_deg']:.4f} deg, "
              f"peak motor torque {pb['peak_motor_torque_Nm']:.0f} N m ({pb['peak_torque_ratio']:.3f} T_max)")
        print(pb["verdict"]["line"])
        if not pb["verdict"]["ok"]:
            return VERIFY_FAILED
    return 0


def cmd_reproduce(args) -> int:
    from .reproduce import run_reproduce

    t0 = time.perf_counter()
    run_reproduce(Path(args.out), quick=args.quick, seed=args.seed)
    print(f"reproduced the paper{' (quick)' if args.quick else ''} in {time.perf_counter() - t0:.1f} s -> {args.out}/report.md")
    return 0


def _refuse_overwrite_input(out: Path, inputs) -> None:
    """Refuse an output path that is one of the user's input files."""
    for i in inputs:
        if i is not None and Path(str(i)).exists() and Path(str(i)).resolve() == Path(out).resolve():
            raise ServoPressError(f"--out {out} is the input file {i}: choose another output path (inputs are never overwritten)")


def _seed(text: str) -> int:
    """argparse type of --seed: numpy and SALib take only non-negative integer seeds."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; a seed is a whole number >= 0")
    return value


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="servo-press", description="Dynamics model, calibration and stroke planning for servo presses.")
    sub = p.add_subparsers(dest="command", required=True)

    def press_arg(sp):
        sp.add_argument("--press", default=None, help="press TOML file, or 'reference' / 'crank-slider' (default: the reference press)")

    u = sub.add_parser("urdf", help="write the linkage as a URDF tree plus its loop-closure file")
    press_arg(u)
    u.add_argument("--out", default="urdf/eight_bar.urdf", help="URDF path; the loop file is written beside it (.loops.json)")
    u.set_defaults(func=cmd_urdf)

    s = sub.add_parser("simulate", help="one crank turn: kinematics, reactions and motor torque")
    press_arg(s)
    s.add_argument("--params", default=None, help='parameter overrides: JSON object (e.g. \'{"m8": 32940}\') or a JSON file')
    s.add_argument("--motion", choices=("constant", "cushion-test"), default="cushion-test")
    s.add_argument("--spm", type=float, default=11.4, help="strokes per minute (default 11.4)")
    s.add_argument("--load", choices=("none", "cushion", "door-panel"), default="cushion")
    s.add_argument("--step-deg", type=float, default=1.0, help="crank-angle step in degrees (default 1)")
    s.add_argument("--playback", action="store_true", help="also play the motor torque back through the forward dynamics (playback.csv)")
    s.add_argument("--out", required=True, help="output folder")
    s.set_defaults(func=cmd_simulate)

    g = sub.add_parser("sensitivity", help="Sobol indices of the 28 parameters on Y_RMSE, Y_PR, Y_TL, Y_Work (Section 3)")
    press_arg(g)
    g.add_argument("--n", type=int, default=2048, help="Sobol base sample size, a power of two (default 2048)")
    g.add_argument("--seed", type=_seed, default=0, help="seed of the scrambled Sobol design and the bootstrap (default 0)")
    g.add_argument("--second-order", action="store_true", help="also compute second-order indices (N (2D+2) cycles)")
    g.add_argument("--convergence", action="store_true", help="instead: S_T of the key parameters for N from --n-min to --n-max")
    g.add_argument("--n-min", type=int, default=256)
    g.add_argument("--n-max", type=int, default=8192)
    g.add_argument("--out", required=True, help="output folder")
    g.set_defaults(func=cmd_sensitivity)

    pl = sub.add_parser("plan", help="time-optimal stroke of a job with toppra (Section 4.3): profile.csv, summary.json, figures")
    press_arg(pl)
    pl.add_argument("--job", default="door-panel", help="job file with [process], [planning] and [playback], or 'door-panel' (default)")
    pl.add_argument("--params", default=None, help='parameter overrides: JSON object (e.g. \'{"m8": 32940}\') or a JSON file such as calibrated.json')
    pl.add_argument("--verify", action="store_true", help="also play the plan back through the forward dynamics with feed-forward + PD "
                    "(playback.csv); exit status 3 and a VERIFY FAILED line if the playback breaks a limit")
    pl.add_argument("--robust", action="store_true", help="plan so that the torque margin holds over the 95 %% box of --params calibrated.json "
                    "(its \"intervals\"); reports the rate it costs against the calibrated values alone")
    pl.add_argument("--out", required=True, help="output folder")
    pl.set_defaults(func=cmd_plan)

    cp = sub.add_parser("compare", help="plan with the theoretical and the calibrated parameters and cross-evaluate both plans")
    press_arg(cp)
    cp.add_argument("--calibrated", required=True, help="calibrated.json (a JSON file with a \"parameters\" object) or a JSON object")
    cp.add_argument("--job", default="door-panel", help="job file, or 'door-panel' (default)")
    cp.add_argument("--no-verify", action="store_true", help="skip the forward-dynamics playback of the calibrated plan "
                    "(with it: exit status 3 and a VERIFY FAILED line if the playback breaks a limit)")
    cp.add_argument("--out", required=True, help="output folder")
    cp.set_defaults(func=cmd_compare)
    e = sub.add_parser("experiment", help="write a SYNTHETIC drive log of the servo-cushion calibration experiment (Section 4.1)")
    press_arg(e)
    e.add_argument("--job", default="cushion-test", help="job file with [motion], [process] and [experiment] (default cushion-test)")
    e.add_argument("--seed", type=_seed, default=0, help="seed of the measurement noise (default 0)")
    e.add_argument("--truth", default=None, help="synthetic truth: JSON object or file of parameter values (SI); "
                   "parameters not named take their theoretical values (default: the job's [experiment.truth], Table 4)")
    e.add_argument("--out", required=True, help="drive-log CSV to write; the truth goes beside it in <name>.truth.json")
    e.set_defaults(func=cmd_experiment)

    c = sub.add_parser("calibrate", help="calibrate the key parameters against a drive log (Eq. 28, Section 4.2)")
    press_arg(c)
    c.add_argument("--log", required=True, help="drive-log CSV: time_s, crank_angle_deg, motor_speed_rpm, motor_torque_Nm (per motor)")
    c.add_argument("--job", default="cushion-test", help="job file of the logged experiment: its process force and [calibration] (default cushion-test)")
    c.add_argument("--method", choices=("aco", "least-squares", "differential-evolution", "all"), default=None,
                   help="optimiser (default: the job's default_method, the winner on the synthetic benchmark); 'all' runs and compares all three")
    c.add_argument("--parameters", default=None, help="parameters to calibrate: key_parameters.json of `sensitivity`, or a comma list (default: the paper's six)")
    c.add_argument("--seed", type=_seed, default=0, help="seed of the stochastic optimisers and random starts (default 0)")
    c.add_argument("--torque-unit", choices=("N*m", "kN*m"), default="N*m", help="unit of the log's torque column (default N*m)")
    c.add_argument("--out", required=True, help="output folder")
    c.set_defaults(func=cmd_calibrate)
    r = sub.add_parser("reproduce", help="the whole paper on the embedded reference press, with report.md (the main job)")
    r.add_argument("--out", default="out/reproduce", help="output folder (default out/reproduce)")
    r.add_argument("--quick", action="store_true", help="N = 256 and one calibration method: the same pipeline in under 30 s")
    r.add_argument("--seed", type=_seed, default=0, help="seed of the Sobol design, the synthetic noise and the optimisers (default 0)")
    r.set_defaults(func=cmd_reproduce)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ServoPressError as exc:
        print(f"servo-press: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # an output path the system refuses (a file where a folder is wanted, no permission ...)
        print(f"servo-press: error: {os_error(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("servo-press: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
