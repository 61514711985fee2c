"""Absurd numbers and impossible geometry in a press file, through the real command line.

The class: a number far outside what any press can have (an angle of 1e300 deg, a point 1e308 m away, a centre
of mass metres outside its link, an empty file) used to end in a scipy traceback, numpy RuntimeWarnings, a
message blaming the friction iteration, or a silent run. Each is refused with one line naming the field, the
value and the bound (the bounds that are our choices are in press_model/data/run_limits.toml).
"""
from __future__ import annotations

import shutil
import warnings
from importlib import resources

import pytest

from servo_press.cli import main

pytestmark = pytest.mark.usefixtures("pyplot_imported")  # fixtures_suitecal.py: the figure workers start with matplotlib

REF = resources.files("press_model.data").joinpath("reference_press.toml").read_text(encoding="utf-8")
ERROR = "servo-press: error: "


def refused_simulate(capsys, tmp_path, old: str, new: str, *parts: str) -> str:
    """simulate on the reference press with one text edit: exit 2, one line holding ``parts``, no warning, no output."""
    assert old in REF, old
    path = tmp_path / "press.toml"
    path.write_text(REF.replace(old, new, 1), encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a numpy RuntimeWarning on the way is a failure too
        try:
            code = main(["simulate", "--press", str(path), "--step-deg", "10", "--out", str(tmp_path / "out")])
        except SystemExit as exc:
            code = exc.code
    _, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith(ERROR) and "Traceback" not in err, err
    for p in parts:
        assert p in lines[0], f"{p!r} not in: {lines[0]}"
    assert not (tmp_path / "out").exists()
    return lines[0]


@pytest.mark.parametrize("old, new, field", [
    ("angle_offset_deg = 90.0", "angle_offset_deg = 1e308", "drive.angle_offset_deg = 1e+308"),
    ("link4 = 47.0", "link4 = -1.7e308", "assembly.body_angles_deg.link4 = -1.7e+308"),
    ("crank = 90.0", "crank = 1e16", "assembly.body_angles_deg.crank = 1e+16"),
    ("crank_angle_deg = 0.0\n", "crank_angle_deg = 3e5\n", "assembly.crank_angle_deg = 300000.0"),
    ("angle_deg = 52.82", "angle_deg = 1e20", "bodies.link4.points_m.C.angle_deg = 1e+20"),
])
def test_an_angle_beyond_one_turn_is_refused(capsys, tmp_path, old, new, field):
    refused_simulate(capsys, tmp_path, old, new, field, "must be >= -360.0 and <= 360.0 (deg)")


def test_an_assembly_check_step_finer_than_the_finest_grid_is_refused(capsys, tmp_path):
    refused_simulate(capsys, tmp_path, "[parameters]\n", "[numerics]\nassembly_check_step_deg = 1e-300\n\n[parameters]\n",
                     "numerics.assembly_check_step_deg = 1e-300", ">= 0.05")


@pytest.mark.parametrize("old, new, field", [
    ("D = [1.55, 0.3]", "D = [1e308, 0.3]", "frame.points_m.D = [1e+308, 0.3]"),
    ("bearing_radius_m = 0.4925", "bearing_radius_m = 1e308", "joints.A.bearing_radius_m = 1e+308"),
    ("com = { from = \"B\", toward = \"C\", distance_m = 0.5585 }", "com = { from = \"B\", toward = \"C\", distance_m = 1e7 }",
     "bodies.link3.com.distance_m = 10000000.0"),
])
def test_a_length_far_beyond_any_press_is_refused(capsys, tmp_path, old, new, field):
    refused_simulate(capsys, tmp_path, old, new, field, "must be within 100 m", "max_length_m")


@pytest.mark.parametrize("old, new, field, where", [
    ("com = { from = \"B\", toward = \"C\", distance_m = 0.5585 }", "com = { from = \"B\", toward = \"C\", distance_m = 40.0 }",
     "bodies.link3.com", "its points are at most 1.369 m apart"),
    ("com = [0.0, 0.0]", "com = [0.0, -20.0]", "bodies.slide.com", "max_com_offset_m = 5 m"),
])
def test_a_centre_of_mass_outside_its_body_is_refused(capsys, tmp_path, old, new, field, where):
    refused_simulate(capsys, tmp_path, old, new, field, "outside the body", where)


def test_an_absurd_viscous_coefficient_is_named_not_blamed_on_the_friction_iteration(capsys, tmp_path):
    line = refused_simulate(capsys, tmp_path, "revolute_viscous_Nms_per_rad = 2.5", "revolute_viscous_Nms_per_rad = 1e308",
                            "friction.revolute_viscous_Nms_per_rad = 1e+308", "must be at most 1e+06 N m s/rad",
                            "max_revolute_viscous_Nms_per_rad in press_model/data/run_limits.toml", "check the unit and the exponent")
    assert "friction_max_iterations" not in line


MOTOR_FIELDS = [("peak_torque_Nm = 25000.0", "motor.peak_torque_Nm", "N m", "max_motor_torque_Nm"),
                ("rated_torque_Nm = 13500.0", "motor.rated_torque_Nm", "N m", "max_motor_torque_Nm"),
                ("max_speed_rpm = 1000.0", "motor.max_speed_rpm", "rpm", "max_motor_speed_rpm")]


@pytest.mark.parametrize("old, field, unit, key", MOTOR_FIELDS, ids=[f[1] for f in MOTOR_FIELDS])
@pytest.mark.parametrize("value, shown, why", [
    ("1e308", "1e+308", "must be at most"),
    ("2e6", "2000000.0", "must be at most"),
    ("-25000.0", "-25000.0", "must be > 0.0"),
    ("0.0", "0.0", "must be > 0.0"),
    ("nan", "nan", "must be a finite number"),
    ("inf", "inf", "must be a finite number"),
    ("-inf", "-inf", "must be a finite number"),
], ids=["1e308", "2e6", "negative", "zero", "nan", "inf", "-inf"])
def test_an_absurd_motor_limit_is_refused(capsys, tmp_path, old, field, unit, key, value, shown, why):
    """Peak torque, rated torque or top speed of the motor far beyond any servo motor (or not a positive number)
    would leave a plan bound by nothing but its jerk limit: refused at the press file, naming the bound's key."""
    name = old.split(" = ")[0]
    line = refused_simulate(capsys, tmp_path, old, f"{name} = {value}", f"{field} = {shown}", why)
    if why == "must be at most":
        assert f"{key} in press_model/data/run_limits.toml" in line and "far above any servo motor" in line, line


def test_plan_refuses_a_press_whose_motor_has_no_torque_limit(capsys, tmp_path):
    path = tmp_path / "press.toml"
    path.write_text(REF.replace("peak_torque_Nm = 25000.0", "peak_torque_Nm = 1e308", 1), encoding="utf-8")
    try:
        code = main(["plan", "--press", str(path), "--out", str(tmp_path / "plan")])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith(ERROR) and len(err.splitlines()) == 1, err
    assert "motor.peak_torque_Nm = 1e+308" in err and "max_motor_torque_Nm" in err, err
    assert not (tmp_path / "plan").exists()


@pytest.mark.parametrize("old, new, shown, bound", [
    ("[frame]", "gravity_m_s2 = 981.0\n\n[frame]", "press.gravity_m_s2 = 981.0", "must be at most 30 m/s^2"),
    ("gear_ratio = 32.0", "gear_ratio = 1e300", "drive.gear_ratio = 1e+300", "must be at most 1000,"),
    ("motors = 2 ", "motors = 9223372036854775807 ", "drive.motors = 9223372036854775807", "must be at most 64,"),
    ("guide_viscous_Ns_per_m = 3000.0", "guide_viscous_Ns_per_m = 1e300", "friction.guide_viscous_Ns_per_m = 1e+300", "must be at most 1e+08 N s/m"),
    ("cylinders = 4 ", "cylinders = 100000 ", "balance.cylinders = 100000", "must be at most 64,"),
    ("piston_area_m2 = 0.2", "piston_area_m2 = 2e3", "balance.piston_area_m2 = 2000.0", "must be at most 10 m^2"),
    ("tank_volume_m3 = 5.0", "tank_volume_m3 = 1e300", "balance.tank_volume_m3 = 1e+300", "must be at most 1000 m^3"),
    ("coefficient = 1.15", "pressure_offset_MPa = 103300.0\ncoefficient = 1.15", "balance.pressure_offset_MPa = 103300.0", "must be at most 10 MPa"),
    ("[parameters]\n", "[numerics]\nnewton_max_iterations = 9223372036854775807\n\n[parameters]\n", "numerics.newton_max_iterations = 9223372036854775807",
     "must be at most 100000,"),
    ("[parameters]\n", "[numerics]\nfriction_max_iterations = 10000000\n\n[parameters]\n", "numerics.friction_max_iterations = 10000000",
     "must be at most 100000,"),
], ids=["gravity", "gear ratio", "motors", "guide viscous", "cylinders", "piston area", "tank volume", "pressure offset",
        "newton iterations", "friction iterations"])
def test_a_drive_friction_balance_or_solver_number_beyond_any_press_is_refused(capsys, tmp_path, old, new, shown, bound):
    refused_simulate(capsys, tmp_path, old, new, shown, bound, "run_limits.toml", "check the unit and the exponent")


def test_a_design_mass_beyond_every_body_at_its_bound_is_refused(capsys, tmp_path):
    refused_simulate(capsys, tmp_path, "coefficient = 1.15", "design_mass_kg = 1e300\ncoefficient = 1.15",
                     "balance.design_mass_kg = 1e+300", "must be at most 7e+07 kg", "max_mass_kg")


def test_every_plausibility_bound_admits_the_reference_press():
    """The bounds are far from the reference's values, so a real press is never refused by them: each at least
    ten times the reference's value (the bound that matters is the one a typo crosses)."""
    from press_model.limits import run_limits
    from press_model.press_data import load_press

    press, lim = load_press(), run_limits()
    assert lim.max_motor_torque_Nm >= 10 * press.motor.peak_torque
    assert lim.max_motor_speed_rpm * 2 * 3.141592653589793 / 60 >= 10 * press.motor.max_speed
    assert lim.max_gravity_m_s2 >= 3 * press.gravity and lim.max_gear_ratio >= 10 * press.drive.gear_ratio
    assert lim.max_revolute_viscous_Nms_per_rad >= 10 * press.friction.c_r and lim.max_guide_viscous_Ns_per_m >= 10 * press.friction.c_s
    assert lim.max_piston_area_m2 >= 10 * press.balance.piston_area and lim.max_tank_volume_m3 >= 10 * press.balance.tank_volume
    assert lim.max_pressure_offset_MPa >= 10 * press.balance.pressure_offset_mpa


def test_an_empty_press_file_says_it_is_empty(capsys, tmp_path):
    path = tmp_path / "empty.toml"
    path.write_text("", encoding="utf-8")
    assert main(["simulate", "--press", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "the file is empty" in err and "[top level]" not in err


def test_a_ratio_is_shown_without_the_unit_1(capsys, tmp_path):
    assert main(["simulate", "--params", '{"eta_gear": 1.5}', "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("must lie in its range [0.7, 0.99]"), err


@pytest.mark.parametrize("command, old, new, shown, why", [
    ("sensitivity", "range = [0.005, 0.05]", "range = [0.005, 1e300]", "parameters.mu_r.range = [0.005, 1e+300]",
     "at 1e+300, friction.revolute_coefficient must be >= 0.0 and < 1.0"),
    ("calibrate", "range = [0.7, 0.99]", "range = [0.7, 1.5]", "parameters.eta_gear.range = [0.7, 1.5]", "at 1.5, drive.efficiency must be > 0.0 and <= 1.0"),
    ("sensitivity", "range = [1.0, 1.3]", "range = [0.0, 1.3]", "parameters.psi.range = [0.0, 1.3]", "at 0.0, balance.coefficient must be > 0 when cylinders > 0"),
], ids=["mu_r to 1e300 in sensitivity", "eta_gear above 1 in calibrate", "psi to 0 with cylinders"])
def test_a_parameter_range_reaching_invalid_values_is_refused(capsys, tmp_path, synthetic_log, command, old, new, shown, why):
    """The sampler and the optimisers run the model at the ends of every range: an end that the press file itself
    would refuse (a friction coefficient of 1e300) is named with the field's own rule, not as a non-finite design row."""
    assert old in REF
    path = tmp_path / "press.toml"
    path.write_text(REF.replace(old, new, 1), encoding="utf-8")
    args = {"sensitivity": ["sensitivity", "--n", "64"], "calibrate": ["calibrate", "--log", str(tmp_path / "log.csv")]}[command]
    if command == "calibrate":  # `experiment --out log.csv` (conftest.py: written once a session), its sidecar too
        shutil.copytree(synthetic_log.parent, tmp_path, dirs_exist_ok=True)
    try:
        code = main([*args, "--press", str(path), "--out", str(tmp_path / "out")])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    line = next((s for s in err if s.startswith(ERROR)), "")
    assert code == 2 and line and "Traceback" not in "\n".join(err), err
    assert shown in line and why in line and "narrow the range" in line, line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("old, new, parts", [
    ("tank_volume_m3 = 5.0 ", "tank_volume_m3 = 1e-300 ",
     ["balance.tank_volume_m3 = 1e-300", "compresses the balance gas to inf times its TDC pressure", "max_balance_pressure_ratio"]),
    ("tank_volume_m3 = 5.0 ", "tank_volume_m3 = 0.05 ",
     ["balance.tank_volume_m3 = 0.05", "14.1 times its TDC pressure", "over a stroke of 1.402 m", "at most 10"]),
    ("[parameters]\n", "[numerics]\nposition_tolerance_m = 1e-300\n\n[parameters]\n",
     ["numerics.position_tolerance_m = 1e-300", "must be at least 1e-14 m", "min_position_tolerance_m"]),
    ("[parameters]\n", "[numerics]\nfriction_tolerance = 1e-300\n\n[parameters]\n",
     ["numerics.friction_tolerance = 1e-300", "must be at least 1e-14", "min_friction_tolerance"]),
], ids=["tank 1e-300", "tank below the swept volume", "position tolerance 1e-300", "friction tolerance 1e-300"])
def test_a_balance_or_tolerance_no_press_can_have_is_named_not_blamed_on_the_reactions(capsys, tmp_path, old, new, parts):
    """A tank far smaller than the cylinders' swept volume overflowed Eq. 13 and was reported as overflowing joint
    reactions; a stop tolerance below float64's resolution never converged and was blamed on the link lengths or
    the friction iterations."""
    line = refused_simulate(capsys, tmp_path, old, new, *parts)
    assert "joint reactions" not in line and "link lengths" not in line and "friction_max_iterations" not in line


def test_the_reference_balance_is_far_inside_its_bound():
    """Eq. 13's BDC/TDC pressure ratio of the reference press, (1 + 0.2 m^2 x 1.40167 m / 5 m^3)^1.4 = 1.079, from
    the balance force itself at BDC and TDC (P0 times the ratio, per Eq. 13 with the pressure offset)."""
    from press_model.forces import BalanceForce
    from press_model.limits import run_limits
    from press_model.press_data import load_press

    press = load_press()
    bal = BalanceForce.from_press(press, 1.40167)
    x = 1.40167 * 0.2 / 5.0
    u1 = (bal.supply_pressure / 1e6 + 0.1033) * ((1 + x) ** 1.4 - 1) / (bal.supply_pressure / 1e6)
    assert float(bal(0.0)) / float(bal(1.40167)) == pytest.approx(1 + u1, rel=1e-12)
    assert run_limits().max_balance_pressure_ratio >= 5 * (1 + x) ** 1.4
