"""The ``servo-press`` command line: the composition root that wires press data, model and reports."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .errors import ServoPressError


def _load_model(args):
    from .model import PressModel
    from .params import apply_overrides, read_overrides
    from .press_data import load_press

    overrides = read_overrides(getattr(args, "params", None))
    press = apply_overrides(load_press(args.press), overrides)
    return PressModel(press), overrides


def cmd_urdf(args) -> int:
    from .press_data import load_press
    from .urdf import write_urdf

    press = load_press(args.press)
    from .model import PressModel

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
    from .sensitivity_report import powers_of_two, run_convergence, run_sensitivity

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
    g.add_argument("--seed", type=int, default=0, help="seed of the scrambled Sobol design and the bootstrap (default 0)")
    g.add_argument("--second-order", action="store_true", help="also compute second-order indices (N (2D+2) cycles)")
    g.add_argument("--convergence", action="store_true", help="instead: S_T of the key parameters for N from --n-min to --n-max")
    g.add_argument("--n-min", type=int, default=256)
    g.add_argument("--n-max", type=int, default=8192)
    g.add_argument("--out", required=True, help="output folder")
    g.set_defaults(func=cmd_sensitivity)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ServoPressError as exc:
        print(f"servo-press: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("servo-press: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
