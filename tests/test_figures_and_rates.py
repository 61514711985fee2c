"""What an engineer reads at a glance: every torque figure draws T_max and the margin, an overload is drawn to scale
and said in words, one plan prints one rate (plan, compare, the cam files' headers), the paper's figures only on the
reference press (labelled as the paper's), and `simulate --job` simulates the user's own force.

The figures are checked on their drawing's data (the Line2D and bar objects), not on pixels."""
from __future__ import annotations

import json
import math
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from in_process import servo_press  # noqa: E402 (tests/ is on sys.path, conftest.py)

RATE = re.compile(r"(\d+\.\d+) spm")


def horizontal_lines(ax) -> dict[float, str]:
    """y value -> line style of the axes' horizontal lines (axhline: two points at the same y)."""
    out = {}
    for ln in ax.get_lines():
        y = np.asarray(ln.get_ydata(), float)
        if y.size == 2 and y[0] == y[1]:
            out[round(float(y[0]), 9)] = ln.get_linestyle()
    return out


def legend_outside(ax) -> bool:
    """Whether the axes' legend stands right of the plot (anchored beyond the axes' right edge)."""
    leg = ax.get_legend()
    box = leg.get_bbox_to_anchor().transformed(ax.transAxes.inverted())
    return leg is not None and box.x0 > 1.0


def test_a_torque_figure_draws_t_max_and_the_margin_with_its_legend_off_the_curves():
    from planning.figures import torque_figure
    from press_model.torque_limits import TorqueLimits

    limits = TorqueLimits(peak_torque=22_500.0, margin=0.9, feedback_reserve=0.05)
    t = np.linspace(0.0, 4.0, 101)
    fig = torque_figure([("plan", t, 20_000.0 * np.sin(t), 9_000.0)], limits, 13_500.0, "test")
    ax = fig.axes[0]
    lines = horizontal_lines(ax)
    # T_max (solid) and the margin (dashed), both signs, in kN m: the values the limits hold, not the curve's
    assert lines[22.5] == "-" and lines[-22.5] == "-"
    assert lines[round(0.9 * 22.5, 9)] == "--" and lines[round(-0.9 * 22.5, 9)] == "--"
    labels = [ln.get_label() for ln in ax.get_lines()]
    assert any("T_max = 22.5 kN m" in s for s in labels) and any("0.9 T_max = 20.25 kN m" in s for s in labels)
    assert ax.get_ylim()[1] >= 22.5 and ax.get_ylim()[0] <= -22.5  # the T_max lines inside the drawing
    assert legend_outside(ax)


def test_simulates_cycle_figure_draws_t_max_and_the_margin_a_plan_would_keep(tmp_path):
    # the job's own [planning.limits] peak_torque_margin where it sets one (0.85 here), else the planner's default 0.9
    from press_model.cycle import simulate_cycle
    from press_model.jobs import load_job, make_motion
    from press_model.model import PressModel
    from press_model.plots import cycle_figure
    from press_model.press_data import load_press
    from press_model.torque_limits import TorqueLimits
    from servo_press.simulate import SimulateCase, case_margin

    job = tmp_path / "job.toml"
    shipped = Path(__file__).resolve().parents[1] / "press_model" / "data" / "cushion_test.toml"
    job.write_text(shipped.read_text(encoding="utf-8") + "\n[planning.limits]\npeak_torque_margin = 0.85\n", encoding="utf-8")
    assert case_margin(SimulateCase()) == 0.9 and case_margin(SimulateCase(job=str(job))) == 0.85
    press = load_press(None)
    pm = PressModel(press)
    cycle = simulate_cycle(pm, make_motion(load_job("cushion-test").motion, "cushion-test"), load_job("cushion-test").process, step_deg=4.0)
    fig = cycle_figure(cycle, TorqueLimits(press.motor.peak_torque, 0.85), press.motor.rated_torque, "test")
    lines = horizontal_lines(fig.axes[0])
    t_max = press.motor.peak_torque / 1e3
    assert lines[round(t_max, 9)] == "-" and lines[round(0.85 * t_max, 9)] == "--" and lines[round(-0.85 * t_max, 9)] == "--"


def test_the_pendulum_slide_figure_keeps_its_legend_off_the_curves():
    from planning.figures import slide_height_figure

    t = np.linspace(0.0, 5.0, 51)
    fig = slide_height_figure(t, 0.5 + 0.4 * np.cos(t), 0.7, 1.8, [("turning point A", 0.0, 0.9)], "test")
    assert legend_outside(fig.axes[0])


ROWS = [{"plan": "theoretical", "strokes_per_min": 13.1, "peak_ratio_theoretical_model": 0.89, "peak_ratio_calibrated_model": 1.144},
        {"plan": "calibrated", "strokes_per_min": 13.2, "peak_ratio_theoretical_model": 0.86, "peak_ratio_calibrated_model": 0.89}]


def test_an_overload_is_drawn_to_scale_and_said_in_words():
    from planning.compare import overload_lines
    from planning.figures import comparison_figure

    fig = comparison_figure(ROWS, None, 0.9, "test")
    ax1, ax2 = fig.axes[:2]
    heights = sorted(round(p.get_height(), 9) for p in ax2.patches)
    assert heights == sorted([0.89, 1.144, 0.86, 0.89])  # every bar its whole ratio
    low, high = ax2.get_ylim()
    assert low == 0.0 and high > 1.144  # nothing cut off: the 1.144 bar stands whole below the top
    lines = horizontal_lines(ax2)
    assert lines[1.0] == "-" and lines[0.9] == "--"  # T_max and the margin
    assert any("+14 % over T_max" in t.get_text() for t in ax2.texts)
    assert len(ax1.patches) == 2  # no paper bars: paper None
    words = overload_lines(ROWS, 0.9)
    assert words == ["the theoretical plan on the press as calibrated reaches 1.144 T_max: the motors would be overloaded by "
                     "14 % (above T_max, not only the margin 0.9 T_max)"]


def edited_copy(shipped: str, old: str, new: str, path: Path) -> Path:
    """A shipped data file (press_model/data) copied to ``path`` with ``old`` (which it must hold) replaced by ``new``: a
    user's own file, edited as the README's worked example says."""
    text = resources.files("press_model.data").joinpath(shipped).read_text(encoding="utf-8")
    assert old in text
    path.write_text(text.replace(old, new), encoding="utf-8")
    return path


def modified_press(tmp_path: Path) -> Path:
    """The reference press with its slide 15 % heavier: a user's own press."""
    return edited_copy("reference_press.toml", "mass_kg = 30595.0", f"mass_kg = {30595.0 * 1.15}", tmp_path / "my_press.toml")


def test_the_papers_figures_are_labelled_on_the_reference_press_and_absent_on_another(tmp_path):
    from calibration.identification.report import accuracy_lines
    from planning.compare import compare_lines, paper_record
    from press_model.params import apply_overrides
    from press_model.press_data import load_press

    ref = load_press()
    paper = paper_record(apply_overrides(ref, {"eta_gear": 0.84}))  # a calibration of the reference press is still it
    assert paper["strokes_per_min_theoretical"] == 11.4 and "paper's press" in paper["of"]
    assert paper_record(load_press(modified_press(tmp_path))) is None
    rec = {"rows": [{**r, "rms_theoretical_model_Nm": 9e3, "rms_calibrated_model_Nm": 9e3} for r in ROWS], "rate_gain_percent": 0.76}
    mine = "\n".join(compare_lines(rec, Path("out")))
    theirs = "\n".join(compare_lines({**rec, "paper": paper}, Path("out")))
    assert "11.4" not in mine and "paper" not in mine
    assert "the paper's press: 11.4 -> 11.6 spm (+1.75 %)" in theirs
    metrics = {"rmse_before_Nm": 700.0, "rmse_after_Nm": 120.0, "peak_error_before_Nm": 5.0, "peak_error_after_Nm": 1.0,
               "peak_error_with_impact_before_Nm": 50.0, "peak_error_with_impact_after_Nm": 40.0, "thermal_error_before": 0.01,
               "thermal_error_after": 0.001}
    assert "paper" not in "\n".join(accuracy_lines(metrics, None))
    from calibration.sensitivity.report import paper_figures

    assert "the paper's press: before" in "\n".join(accuracy_lines(metrics, paper_figures()["calibration"]))


def header(path: Path) -> str:
    return "\n".join(ln for ln in path.read_text(encoding="utf-8").splitlines() if ln.startswith("#"))


def test_plan_and_the_cam_headers_print_one_rate_and_the_rounding_once(door_panel_plan_run):
    from planning.profile import rate_text

    out, stdout, _ = door_panel_plan_run
    info = json.loads((out / "summary.json").read_text())
    rate = rate_text(info["strokes_per_min"])
    assert rate in stdout and float(rate.split()[0]) == pytest.approx(60.0 / info["cycle_time_s"], abs=5e-4)
    for name in ("cam_master.csv", "cam_master_isg.txt"):
        assert set(RATE.findall(header(out / name))) == {rate.split()[0]}, name
    tab = header(out / "cam_table.csv")
    rates = RATE.findall(tab)
    rows = [ln for ln in (out / "cam_table.csv").read_text(encoding="utf-8").splitlines() if not ln.startswith("#")]
    times = np.array([float(ln.split(",")[0]) for ln in rows[1:]])
    rounded = 60.0 / times[-1]  # the table's own cycle: its last row is the next cycle's first
    assert rates[0] == rate.split()[0] and len(rates) == 2 and float(rates[1]) == pytest.approx(rounded, abs=5e-5)
    # the two master cams state their follower axis and the conversion
    gear = 32.0
    for name, axis in (("cam_master.csv", "slave: motor shaft deg"), ("cam_master_isg.txt", "slave: crank deg")):
        text = header(out / name)
        assert axis in text and f"motor deg = crank deg x {gear:g}" in text, name


def test_compare_prints_each_rows_rate_as_plan_does(tmp_path):
    from planning.compare import compare_lines
    from planning.profile import rate_text

    rec = {"rows": [{**r, "rms_theoretical_model_Nm": 9e3, "rms_calibrated_model_Nm": 9e3} for r in ROWS], "rate_gain_percent": 0.76}
    text = "\n".join(compare_lines(rec, tmp_path))
    assert set(RATE.findall(text)) == {rate_text(r["strokes_per_min"]).split()[0] for r in ROWS}


def cushion_job(tmp_path: Path, force_N: float) -> Path:
    """The shipped cushion test with its cushion force set to ``force_N`` (a user's own job file)."""
    return edited_copy("cushion_test.toml", "forces_N = [5.0e6, 5.0e6]", f"forces_N = [{force_N!r}, {force_N!r}]",
                       tmp_path / "my_cushion.toml")


def test_simulate_job_simulates_the_jobs_own_force(tmp_path):
    job = cushion_job(tmp_path, 2.0e6)
    r = servo_press("simulate", "--job", job, "--step-deg", "2", "--out", tmp_path / "cycle")
    assert r.returncode == 0, r.stderr
    s = json.loads((tmp_path / "cycle" / "summary.json").read_text())
    # the cushion pushes 2,000 kN against the slide over its last 0.30 m down: work F x 0.30 m, not the shipped 5,000 kN's
    assert abs(s["process_work_J"]) == pytest.approx(2.0e6 * 0.30, rel=0.02)
    assert s["strokes_per_min"] == 11.4 and s["job_source"] == str(job)  # the job's [motion] rate
    r = servo_press("simulate", "--job", job, "--load", "cushion", "--out", tmp_path / "both")
    assert r.returncode == 2 and "not allowed with" in r.stderr and not (tmp_path / "both").exists()


def test_experiment_says_when_a_users_press_takes_the_reference_presss_truth(tmp_path):
    from calibration.synthetic.experiment import ExperimentSettings, reference_truth_note
    from press_model.jobs import load_job
    from press_model.press_data import load_press

    job = load_job("cushion-test")
    truth = ExperimentSettings.from_job(job).truth
    mine = load_press(modified_press(tmp_path))
    note = reference_truth_note(mine, job, None, truth)
    m8 = mine.parameter_values()["m8"]
    assert f"m8 = 32,940 kg (this press: {m8:,.6g} kg, {100 * (32940.0 / m8 - 1):+.1f} %)" in note
    assert reference_truth_note(load_press(), job, None, truth) is None  # the reference press: its own truth
    assert reference_truth_note(mine, job, '{"m8": 38000}', {"m8": 38000.0}) is None  # --truth: the user's own
    assert reference_truth_note(mine, job, None, {**truth, "m8": 38000.0}).count("m8") == 0  # m8 set for this press


def test_the_storage_figure_draws_its_stored_energy():
    from press_model.plots import power_figure

    t = np.linspace(0.0, 4.0, 41)
    stored = 2.0e6 + 0.5e6 * np.sin(t)
    cols = {"time_s": t, "shaft_W": 1e6 * np.cos(t), "grid_W": np.full_like(t, 0.4e6), "storage_W": 0.6e6 * np.cos(t),
            "dc_link_voltage_V": np.full_like(t, 1050.0), "storage_energy_J": stored}
    fig = power_figure(cols, (900.0, 1150.0), "test")
    curves = [ln for ax in fig.axes for ln in ax.get_lines() if ln.get_label() == "stored energy (storage)"]
    assert len(curves) == 1 and np.allclose(curves[0].get_ydata(), stored / 1e6)
    without = power_figure({**cols, "storage_energy_J": np.zeros_like(t)}, (900.0, 1150.0), "test")
    assert not any(ln.get_label() == "stored energy (storage)" for ax in without.axes for ln in ax.get_lines())
