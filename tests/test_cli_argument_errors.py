"""Bad command-line arguments: argparse's usage errors and the commands' own checks of their options.

Every case runs the real command line and checks what the user sees: exit code 2, one stderr line
``servo-press: error: ...`` naming the option, the value and the fix (usage errors point at the command's --help),
no traceback and nothing left behind. Also: every option has help with its default and is in servo_press/README.md.
"""
from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import pytest

from press_io.errors import PressDataError
from press_model.model import PressModel
from press_model.press_data import read_press
from bad_input_helpers import LONG_NAME, cli, servo_press, refused, usage_error, write_log, ref, check

pytestmark = pytest.mark.usefixtures("pyplot_imported")  # fixtures_suitecal.py: the figure workers start with matplotlib


@pytest.mark.parametrize("step", ["0", "nan", "-1", "7"])
def test_simulate_step_that_does_not_divide_the_turn(capsys, work, step):
    refused(cli(capsys, "simulate", "--step-deg", step, "--out", work.out),
            f"--step-deg: step = {float(step)!r}", "divide", "360")
    work.unchanged()


@pytest.mark.parametrize("spm", ["0", "-3", "inf"])
def test_simulate_strokes_per_minute_not_positive(capsys, work, spm):
    refused(cli(capsys, "simulate", "--spm", spm, "--out", work.out),
            f"--spm = {float(spm)!r}", "must be a positive number of strokes per minute")
    work.unchanged()


def test_simulate_strokes_per_minute_not_a_number(capsys, work):
    usage_error(cli(capsys, "simulate", "--spm", "fast", "--out", work.out), "argument --spm", "invalid float value: 'fast'")
    work.unchanged()


def test_simulate_unknown_load(capsys, work):
    usage_error(cli(capsys, "simulate", "--load", "bricks", "--out", work.out), "argument --load", "invalid choice: 'bricks'")
    work.unchanged()


@pytest.mark.parametrize("step", [0.0, -1.0, float("nan"), 7.0, 1000.0])
def test_bad_crank_step(step):
    from press_model.cycle import simulate_cycle
    from press_model.forces import NO_PROCESS
    from press_model.motion import ConstantSpeed

    with pytest.raises(PressDataError) as info:
        simulate_cycle(PressModel(read_press(ref(), "test")), ConstantSpeed(1.0), NO_PROCESS, step_deg=step)
    check(str(info.value), "step", "divide", "360")


def test_simulate_spm_zero_is_blamed_on_the_option_not_a_job(capsys, work):
    line = refused(cli(capsys, "simulate", "--spm", "0", "--out", work.out), "--spm = 0.0", "e.g. --spm 11.4")
    assert "cushion_test" not in line
    work.unchanged()


@pytest.mark.parametrize("step", ["0.001", "0.04", "12", "20"])
def test_simulate_step_outside_the_sensible_range(capsys, work, step):
    refused(cli(capsys, "simulate", "--step-deg", step, "--out", work.out), f"--step-deg = {float(step)!r}",
            "must lie in [0.05, 10] deg", "run_limits.toml")
    work.unchanged()


def test_simulate_beyond_the_motor_limits_warns(capsys, work):
    code, _, err = cli(capsys, "simulate", "--spm", "1000", "--step-deg", "10", "--out", work.out)
    assert code == 0 and "Traceback" not in err  # an analysis tool: it reports, the planner refuses
    lines = err.strip().splitlines()
    assert len(lines) == 2 and lines[0].startswith("WARNING: the motor limits are broken at 1000 spm"), err
    assert lines[1].startswith("WARNING: the DC-link voltage leaves its window (0-0 V, window 900-1200 V)")  # no supply feeds 700 x T_max
    assert "x T_max" in lines[0] and "exceeds the maximum 1000 rpm" in lines[0]
    lim = json.loads((work.out / "summary.json").read_text(encoding="utf-8"))["limits"]
    assert lim["within_limits"] is False and lim["peak_torque_ratio"] > 1 and lim["top_motor_speed_rpm"] > lim["max_speed_rpm"]
    header = (work.out / "cycle.csv").read_text(encoding="utf-8").splitlines()[0].split(",")
    assert "motor_speed_rpm" in header


@pytest.mark.parametrize("n", ["1000", "0", "-4"])
def test_sensitivity_n_not_a_power_of_two(capsys, work, n):
    refused(cli(capsys, "sensitivity", "--n", n, "--out", work.out), f"--n: n = {n}", "must be a power of two (e.g. 1024, 2048, 4096)")
    work.unchanged()


def test_sensitivity_convergence_n_min_zero(capsys, work):
    refused(cli(capsys, "sensitivity", "--convergence", "--n-min", "0", "--out", work.out), "--n-min")
    work.unchanged()


def test_sensitivity_convergence_n_min_above_n_max(capsys, work):
    refused(cli(capsys, "sensitivity", "--convergence", "--n-min", "1024", "--n-max", "256", "--out", work.out), "--n-m")
    work.unchanged()


@pytest.mark.parametrize("n", ["2", "32", "131072"])
def test_sensitivity_n_outside_the_sensible_range(capsys, work, n):
    refused(cli(capsys, "sensitivity", "--n", n, "--out", work.out), f"--n: --n = {n}", "must be a power of two from 64 to 65536")
    work.unchanged()


def test_sensitivity_convergence_n_min_below_the_sensible_range(capsys, work):
    refused(cli(capsys, "sensitivity", "--convergence", "--n-min", "2", "--out", work.out), "--n-min = 2", "from 64 to 65536")
    work.unchanged()


@pytest.mark.parametrize("command", [["sensitivity", "--n", "4"], ["experiment"]])
def test_negative_seed(capsys, work, command):
    out = work.out / "log.csv" if command[0] == "experiment" else work.out
    code, _, err = cli(capsys, *command, "--seed", "-1", "--out", out)
    assert code == 2 and "Traceback" not in err and "--seed" in err, err
    work.unchanged()


def test_calibrate_parameters_list_too_long_for_a_file_name(capsys, work, log_lines):
    path = write_log(work, log_lines[0])
    refused(cli(capsys, "calibrate", "--log", path, "--parameters", "eta_gear,psi," + LONG_NAME, "--out", work.out), LONG_NAME[:50])
    work.unchanged()


@pytest.mark.parametrize("arg", ["", " , ", "keys.json"])
def test_calibrate_parameters_that_name_nothing(capsys, work, log_lines, arg):
    path = write_log(work, log_lines[0])
    if arg == "keys.json":
        (work.root / arg).write_text(json.dumps({"key_parameters": []}), encoding="utf-8")
        work.snap()
        arg = str(work.root / arg)
    refused(cli(capsys, "calibrate", "--log", path, "--parameters", arg, "--out", work.out), "--parameters = ", "names no parameter")
    work.unchanged()


def test_signed_numbers_never_show_minus_zero():
    from calibration.identification.console import signed as _signed

    assert [_signed(x) for x in (-0.3, 0.3, -5413.2, 0.0, -0.0)] == ["+0", "+0", "-5413", "+0", "+0"]


def test_missing_out_is_a_usage_error(capsys, work):
    usage_error(cli(capsys, "simulate"), "the following arguments are required: --out")
    work.unchanged()


def test_unknown_command_is_a_usage_error(capsys, work):
    usage_error(cli(capsys, "simulat", "--out", work.out), "invalid choice: 'simulat'")
    work.unchanged()


def test_argparse_errors_are_one_line_subprocess(work):
    line = usage_error(servo_press("simulate", "--spm", "fast", "--out", work.out), "argument --spm", "invalid float value: 'fast'",
                       "see 'servo-press simulate --help'")
    assert "usage:" not in line
    usage_error(servo_press("simulat"), "invalid choice: 'simulat'", "did you mean 'simulate'?")
    usage_error(servo_press(), "the following arguments are required: COMMAND")
    work.unchanged()


def test_version_subprocess():
    code, out, err = servo_press("--version")
    assert code == 0 and re.fullmatch(r"servo-press \d+\.\d+\S*\n", out), (out, err)


def test_every_option_has_help_with_its_default_and_is_in_the_readme():
    from servo_press.cli import build_parser

    readme = (Path(__file__).resolve().parents[1] / "servo_press" / "README.md").read_text(encoding="utf-8")
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for name, parser in sub.choices.items():
        rows = [ln for ln in readme.splitlines() if ln.startswith(f"| `servo-press {name}")]
        assert rows, f"README's command table has no row for {name}"
        for a in parser._actions:
            if a.dest == "help":
                continue
            flag = a.option_strings[0]
            assert a.help, f"{name} {flag} has no help"
            if not isinstance(a, argparse._StoreTrueAction):
                assert "(default: " in a.help or "(required" in a.help or a.required, f"{name} {flag}: no default in help: {a.help}"
                if a.default is not None and "%(default)s" not in a.help:
                    assert str(a.default) in a.help, f"{name} {flag}: help does not show the default {a.default!r}"
            assert any(flag in r for r in rows), f"README's row of {name} does not mention {flag}"


def _help(command: str) -> str:
    from servo_press.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return " ".join(sub.choices[command].format_help().split())


def test_plan_robust_help_names_the_joint_region_it_plans_over():
    """`plan --robust` reads the joint region's box (press_model.params.read_joint_box), not the per-parameter intervals."""
    text = _help("plan")
    start = text.rindex("--robust ")  # the option's help, after the usage line
    robust = text[start:text.index("--out", start)]
    assert "joint 95 % region" in robust and "joint_region" in robust, robust


def test_monitor_logs_help_names_the_traces_it_reads_with_a_log_format():
    from calibration.fleet.cluster import TRACE_SUFFIXES

    text = _help("monitor")
    start = text.rindex("--logs DIR|GLOB ")  # the option's help, after the usage line
    logs = text[start:text.index("--job", start)]
    assert all(suffix in logs for suffix in TRACE_SUFFIXES) and "--log-format" in logs, logs
