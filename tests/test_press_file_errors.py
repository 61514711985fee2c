"""Bad press files: every error names the field, the bad value and the fix, in one line.

Three views of the one reader (:func:`press_model.press_data.load_press` / ``read_press``, then ``PressModel``):
the reference press with one thing broken, read directly (the message holds the field, the value and what is
valid, and no Python/numpy/Pinocchio exception leaks out in place of a :class:`PressDataError`); the same through
the real command line (exit code 2, one stderr line ``servo-press: error: ...``, nothing left behind); and
property-based fuzzing (structural mutations, random bytes and text: a valid press or a ServoPressError, never
another exception; fixed ``derandomize=True`` seeds).
"""
from __future__ import annotations

import copy
import math
import re
import tomllib
import xml.etree.ElementTree as ET
from importlib import resources

import numpy as np
import pytest
from hypothesis import event, given, settings, strategies as st

from press_io.errors import AssemblyError, PressDataError, ServoPressError
from press_model.model import PressModel
from press_model.press_data import load_press, read_press
from bad_input_helpers import (
    REF_TEXT, REF, LONG_NAME, FIXED, DATA, cli, servo_press, refused, edited_press, ref, setp, delp, both,
    message_of, check, run_cli, assert_clean_error,
)

pytestmark = pytest.mark.usefixtures("pyplot_imported")  # fixtures_suitecal.py: the figure workers start with matplotlib


# (id, mutation, substrings the message must contain: the field, the bad value, what is valid)
PRESS_CASES = [
    ("negative mass", setp("bodies.link3.mass_kg", -5.0), ["bodies.link3.mass_kg = -5.0", "must be > 0.0 (kg)"]),
    ("zero mass", setp("bodies.slide.mass_kg", 0), ["bodies.slide.mass_kg = 0", "must be > 0.0"]),
    ("negative inertia", setp("bodies.link4.inertia_kg_m2", -1.0), ["bodies.link4.inertia_kg_m2 = -1.0", "must be >= 0.0"]),
    ("infinite mass", setp("bodies.link3.mass_kg", math.inf), ["bodies.link3.mass_kg = inf", "finite number in kg"]),
    ("efficiency 0", setp("drive.efficiency", 0.0), ["drive.efficiency = 0.0", "must be > 0.0 and <= 1.0"]),
    ("efficiency 1.5", setp("drive.efficiency", 1.5), ["drive.efficiency = 1.5", "must be > 0.0 and <= 1.0"]),
    ("bearing radius 0", setp("joints.B.bearing_radius_m", 0.0), ["joints.B.bearing_radius_m = 0.0", "must be > 0.0 (m)"]),
    ("gravity 0", setp("press.gravity_m_s2", 0.0), ["press.gravity_m_s2 = 0.0", "must be > 0.0"]),
    ("gear ratio negative", setp("drive.gear_ratio", -32.0), ["drive.gear_ratio = -32.0", "must be > 0.0"]),
    ("motors 0", setp("drive.motors", 0), ["drive.motors = 0", "whole number >= 1"]),
    ("motors fractional", setp("drive.motors", 2.5), ["drive.motors = 2.5", "whole number >= 1"]),
    ("friction coefficient 1", setp("friction.guide_coefficient", 1.0), ["friction.guide_coefficient = 1.0", "must be >= 0.0 and < 1.0"]),
    ("polytropic exponent", setp("balance.polytropic_exponent", 0.5), ["balance.polytropic_exponent = 0.5", ">= 1.0 and <= 2.0"]),
    ("cylinders negative", setp("balance.cylinders", -1), ["balance.cylinders = -1", "whole number >= 0"]),
    ("position tolerance too loose", setp("numerics.position_tolerance_m", 1e-3), ["numerics.position_tolerance_m = 0.001", "<= 1e-06"]),
    ("assembly step 0", setp("numerics.assembly_check_step_deg", 0.0), ["numerics.assembly_check_step_deg = 0.0", ">= 0.05 and <= 10.0"]),
    # wrong types and missing fields
    ("mass is a string", setp("bodies.link3.mass_kg", "heavy"), ["bodies.link3.mass_kg = 'heavy'", "must be a finite number in kg"]),
    ("mass is a bool", setp("bodies.link3.mass_kg", True), ["bodies.link3.mass_kg = True", "must be a finite number"]),
    ("missing mass", delp("bodies.link5.mass_kg"), ["bodies.link5.mass_kg = '<missing>'", "required; add 'mass_kg' under [bodies.link5]"]),
    ("missing drive table", delp("drive"), ["drive = '<missing>'", "required; add the [drive] table"]),
    ("missing press name", delp("press.name"), ["press.name = '<missing>'", "required; add 'name' under [press]"]),
    ("name not a string", setp("press.name", 5), ["press.name = 5", "must be a non-empty string"]),
    ("table is a number", setp("friction", 3), ["friction.revolute_coefficient = '<missing>'", "required"]),
    ("points not a table", setp("frame.points_m", 5), ["frame.points_m = 5", "must be a table"]),
    ("no frame points", setp("frame.points_m", {}), ["frame.points_m = {}", "needs at least one frame point"]),
    ("no bodies", setp("bodies", {}), ["bodies = {}", "needs at least one moving body"]),
    ("body without points", setp("bodies.link3.points_m", {}), ["bodies.link3.points_m = {}", "joint points"]),
    ("point with three coordinates", setp("frame.points_m.D", [1.55, 0.3, 0.0]), ["frame.points_m.D = [1.55, 0.3, 0.0]", "must be a point [x_m, y_m]"]),
    ("point is nan", setp("frame.points_m.D", [math.nan, 0.3]), ["frame.points_m.D = [nan, 0.3]", "must be a point"]),
    ("standstill choice", setp("drive.efficiency_at_standstill", "coasting"), ["drive.efficiency_at_standstill = 'coasting'", "must be one of 'motoring', 'braking'"]),
    # joints
    ("joint type", setp("joints.A.type", "spherical"), ["joints.A.type = 'spherical'", "must be one of 'revolute', 'prismatic'"]),
    ("unknown body in connects", setp("joints.A.connects", ["crank.A", "link9.A"]), ["joints.A.connects = 'link9.A'", "body must be 'frame' or one of crank, link3"]),
    ("unknown point in connects", setp("joints.A.connects", ["crank.Z", "link6.A"]), ["joints.A.connects = 'crank.Z'", "point must be one of O, A, B on body 'crank'"]),
    ("connects is a string", setp("joints.A.connects", "crank.A"), ["joints.A.connects = 'crank.A'", 'must be two "body.point" names']),
    ("connects one body twice", setp("joints.A.connects", ["crank.A", "crank.B"]), ["joints.A.connects = ['crank.A', 'crank.B']", "must join two different bodies"]),
    ("guide axis zero", setp("joints.guide.axis", [0.0, 0.0]), ["joints.guide.axis = [0.0, 0.0]", "must be a non-zero direction"]),
    ("guide on a body", setp("joints.guide.connects", ["frame.guide", "slide.G"]), ["joints.guide.connects = ('slide', 'G')", "second end must be on 'frame'"]),
    ("two prismatic joints", setp("joints.G", {"type": "prismatic", "connects": ["link7.G", "slide.G"], "axis": [0.0, 1.0]}),
     ["joints = ['G', 'guide']", "needs exactly one prismatic joint: the slide guide"]),
    ("crank joint unknown", setp("drive.crank_joint", "Q"), ["drive.crank_joint = 'Q'", "must name a revolute joint"]),
    ("crank joint prismatic", setp("drive.crank_joint", "guide"), ["drive.crank_joint = 'guide'", "must name a revolute joint"]),
    ("crank joint off the frame", setp("drive.crank_joint", "B"), ["drive.crank_joint = 'B'", "must connect a body to 'frame'"]),
    # topology
    ("body joined to nothing", setp("bodies.extra", {"mass_kg": 1.0, "inertia_kg_m2": 1.0, "points_m": {"P": [0.0, 0.0]}, "com": [0.0, 0.0]}),
     ["bodies.extra = 'extra'", "is joined to nothing; add a joint"]),
    ("too many joints", setp("joints.X", {"type": "revolute", "connects": ["link3.C", "frame.D"], "bearing_radius_m": 0.1}),
     ["joints = [", "'X'", "has -1 degrees of freedom", "needs exactly 1"]),
    ("too few joints", delp("joints.E"), ["joints = [", "has 3 degrees of freedom", "needs exactly 1"]),
    ("far too few joints", both(delp("joints.A", "joints.B", "joints.D", "joints.G", "tree")),
     ["joints = ['O', 'C', 'E', 'F1', 'F2', 'guide']", "too few joints to connect every body to the frame"]),
    # centre of mass
    ("com from unknown point", setp("bodies.link3.com.from", "Q"), ["bodies.link3.com.from = 'Q'", "must name a point of this body (B, C)"]),
    ("com toward unknown point", setp("bodies.link3.com.toward", "Q"), ["bodies.link3.com.toward = 'Q'", "must name a point of this body (B, C)"]),
    ("com toward the from point", setp("bodies.link3.com.toward", "B"), ["bodies.link3.com.toward = 'B'", "must differ in position"]),
    ("com wrong form", setp("bodies.link3.com", "middle"), ["bodies.link3.com = 'middle'", "must be [x_m, y_m], {from, toward, distance_m}"]),
    ("two trilateration distances", delp("bodies.link4.com.distances_m.E"),
     ["bodies.link4.com.distances_m = {'C': 0.9496, 'D': 0.314}", "needs distances to at least three points"]),
    ("trilateration unknown point", setp("bodies.link4.com.distances_m.Z", 1.0), ["bodies.link4.com.distances_m.Z = 'Z'", "must name a point of this body (C, D, E)"]),
    ("trilateration distance 0", setp("bodies.link4.com.distances_m.D", 0.0), ["bodies.link4.com.distances_m.D = 0.0", "must be > 0.0 (m)"]),
    # motor, balance, assembly
    ("rated above peak torque", setp("motor.rated_torque_Nm", 30000.0), ["motor.rated_torque_Nm = 30000.0", "must not exceed peak_torque_Nm = 25000.0"]),
    ("balance psi 0 with cylinders", setp("balance.coefficient", 0.0), ["balance.coefficient = 0.0", "must be > 0 when cylinders > 0", "cylinders = 0"]),
    ("assembly angle of unknown body", setp("assembly.body_angles_deg.link9", 10.0), ["assembly.body_angles_deg.link9 = 'link9'", "must name a body (crank, link3"]),
    # tree hint
    ("cut joint unknown", setp("tree.cut_joints", ["C", "F1", "Q"]), ["tree.cut_joints = ['C', 'F1', 'Q']", "must list joint names among O, A, B"]),
    ("cut joints not a list", setp("tree.cut_joints", "C"), ["tree.cut_joints = 'C'", "must list joint names"]),
    ("cut joint not a name", setp("tree.cut_joints", [["C"], "F1", "F2"]), ["tree.cut_joints = [['C'], 'F1', 'F2']", "must list joint names"]),
    ("tree not a table", setp("tree", 5), ["tree = 5", "must be a table"]),
    # names end up in URDF names and Pinocchio frame names
    ("body named frame", lambda r: r["bodies"].__setitem__("frame", r["bodies"].pop("link7")), ["bodies.frame = 'frame'", "reserved for the fixed ground"]),
    ("body name with markup", lambda r: r["bodies"].__setitem__('li<nk&"7', r["bodies"].pop("link7")),
     ["bodies.li<nk&\"7 = 'li<nk&\"7'", "only letters, digits, '_' or '-'"]),
    ("empty body name", lambda r: r["bodies"].__setitem__("", r["bodies"].pop("link7")), ["bodies. = ''", "only letters, digits"]),
    ("body named universe", lambda r: r["bodies"].__setitem__("universe", r["bodies"].pop("link7")), ["bodies.universe = 'universe'", "not be 'universe'"]),
    ("point name with double underscore", setp("bodies.crank.points_m.A__x", [0.1, 0.0]), ["bodies.crank.points_m.A__x = 'A__x'", "without '__'"]),
    ("joint named like a body", lambda r: r["joints"].__setitem__("link6", r["joints"].pop("A")),
     ["joints.link6 = 'link6'", "a joint name must differ from every body name (frame, crank, link3"]),
    ("joint named universe", lambda r: r["joints"].__setitem__("universe", r["joints"].pop("A")), ["joints.universe = 'universe'", "not be 'universe'"]),
    # sensitivity parameters
    ("parameter path not a number", setp("parameters.m1.path", "bodies.crank.label"), ["parameters.m1.path = 'bodies.crank.label'", "must point at a number in this file"]),
    ("parameter path missing", setp("parameters.m1.path", "bodies.crank.mass"), ["parameters.m1.path = 'bodies.crank.mass'", "must point at a number"]),
    ("parameter range reversed", setp("parameters.mu_r.range", [0.05, 0.005]), ["parameters.mu_r.range = [0.05, 0.005]", "must have low < high"]),
    ("parameter range one number", setp("parameters.mu_r.range", [0.05]), ["parameters.mu_r.range = [0.05]", "must be [low, high]"]),
    ("parameter range strings", setp("parameters.mu_r.range", ["a", "b"]), ["parameters.mu_r.range.0 = 'a'", "must be a finite number"]),
    ("parameter range infinite", setp("parameters.mu_r.range", [0.0, math.inf]), ["parameters.mu_r.range.1 = inf", "must be a finite number"]),
    ("default range not a list", setp("sensitivity.default_relative_range", 0.7), ["sensitivity.default_relative_range = 0.7", "must be [low, high] factors"]),
    ("default range too short", setp("sensitivity.default_relative_range", [0.7]), ["sensitivity.default_relative_range = [0.7]", "must be [low, high]"]),
    ("default range strings", setp("sensitivity.default_relative_range", ["x", 1.3]), ["sensitivity.default_relative_range.0 = 'x'", "must be a finite number"]),
    ("default range of a zero nominal", setp("friction.revolute_viscous_Nms_per_rad", 0.0),
     ["parameters.c_r.range = [0.0, 0.0]", "must have low < high", "give this parameter an explicit range"]),
]


@pytest.mark.parametrize("mutate, parts", [c[1:] for c in PRESS_CASES], ids=[c[0] for c in PRESS_CASES])
def test_press_file_error_names_field_value_and_fix(mutate, parts):
    msg = message_of(mutate)
    assert msg.startswith("test: ")
    assert " is not valid: " in msg
    check(msg, *parts)


def test_reference_and_the_mutation_helpers_are_sound():
    """The unmutated reference is valid, so every failure above comes from its mutation."""
    press = read_press(ref(), "test")
    assert len(press.bodies) == 7 and len(press.parameters) == 28
    assert REF == tomllib.loads(REF_TEXT)  # no case mutated the shared copy


def test_no_balance_needs_no_psi():
    raw = ref()
    setp("balance.cylinders", 0)(raw)
    setp("balance.coefficient", 0.0)(raw)
    setp("parameters.psi.range", [0.0, 1.3])(raw)
    assert read_press(raw, "test").balance.cylinders == 0


def test_impossible_trilateration_distances_never_give_an_absurd_com():
    """Distances no point can meet (C and D are 0.8 m apart, both 0.1 m from the COM): a clear error,
    or at worst a least-squares COM near the body; never the diverged fit (1e8 m away) of the past."""
    raw = ref()
    setp("bodies.link4.com.distances_m", {"E": 5.0, "C": 0.1, "D": 0.1})(raw)
    try:
        press = read_press(raw, "test")
    except PressDataError as exc:
        check(str(exc), "bodies.link4.com.distances_m = {'E': 5.0, 'C': 0.1, 'D': 0.1}", "no centre of mass fits these distances")
    else:
        body = press.bodies["link4"]
        reach = max(np.linalg.norm(p) for p in body.points.values()) + 5.0
        assert np.all(np.isfinite(body.com)) and np.linalg.norm(body.com) < reach


@pytest.mark.parametrize(
    "cut, parts",
    [
        (["C", "F1"], ["tree.cut_joints = ['C', 'F1']", "must leave a tree", "leave loops through ['F2']"]),
        (["C", "F1", "guide"], ["tree.cut_joints = ['C', 'F1', 'guide']", "must not contain the prismatic guide joint"]),
        (["C", "F1", "F2", "B"], ["tree.cut_joints = ['C', 'F1', 'F2', 'B']", "leaves bodies ['link3'] unconnected", "cut fewer or other joints"]),
    ],
    ids=["leaves a loop", "contains the guide", "cuts a body off"],
)
def test_bad_cut_joints(cut, parts):
    raw = ref()
    setp("tree.cut_joints", cut)(raw)
    with pytest.raises(PressDataError) as info:
        PressModel(read_press(raw, "test"))
    check(str(info.value), *parts)


def test_linkage_that_cannot_assemble():
    raw = ref()
    setp("bodies.link3.points_m.C", [0.5, 0.0])(raw)  # link 3 far too short to reach link 4
    with pytest.raises(AssemblyError) as info:
        PressModel(read_press(raw, "test"))
    msg = str(info.value)
    check(msg, "test: the linkage does not assemble at crank angle", " deg: the loop closed at joint ", "Check the link lengths")
    assert re.search(r"at crank angle \d+\.\d\d deg: the loop closed at joint \w+ \(\w+\.\w+ to \w+\.\w+, gap [\d.e+-]+ m\)", msg), msg
    # the loop B-C-D is the one that cannot close: |BD| = 1.55 m, link 3 (0.5 m) + DC (0.8 m) leave 0.25 m
    assert "joint C (link3.C to link4.C, gap 0.25 m)" in msg, msg
    assert "F1" not in msg and "F2" not in msg


def test_loops_that_conflict_are_named_as_such():
    raw = ref()
    setp("bodies.link7.points_m.G", [0.5, 0.0])(raw)  # link 7 cannot reach the guide, but each loop closes alone
    with pytest.raises(AssemblyError) as info:
        PressModel(read_press(raw, "test"))
    check(str(info.value), "every loop closes on its own", "conflict")


@pytest.mark.parametrize("path,value", [
    ("bodies.link3.mass_kgg", 5.0),          # misspelled unit suffix
    ("tree.cut_joint", ["C"]),               # misspelled optional key: would silently change the tree
    ("frictions", {}),                       # misspelled section
    ("joints.B.bearing_radius", 0.6),        # unit missing from the key
])
def test_unknown_keys_are_refused(path, value):
    raw = ref()
    setp(path, value)(raw)
    with pytest.raises(PressDataError) as info:
        read_press(raw, "test")
    check(str(info.value), path, "is not a known key", "misspelled")


def test_invalid_toml_syntax(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(REF_TEXT.replace("mass_kg = 743.8", "mass_kg = 743.8 kg"), encoding="utf-8")
    with pytest.raises(PressDataError) as info:
        load_press(bad)
    check(str(info.value), str(bad), "<file> = 'TOML'", "is not valid TOML", "line", "fix the syntax")


def test_missing_press_file(tmp_path):
    with pytest.raises(PressDataError) as info:
        load_press(tmp_path / "nope.toml")
    check(str(info.value), "--press = ", "nope.toml", "must be an existing TOML file or one of reference, crank-slider")
    with pytest.raises(PressDataError, match="must be an existing TOML file"):
        load_press(tmp_path)  # a folder


def test_load_press_refuses_a_file_not_utf8(tmp_path):
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(REF_TEXT.replace("eight-bar", "acht-Gelenk \xe4").encode("latin-1"))
    with pytest.raises(PressDataError) as info:
        load_press(bad)
    check(str(info.value), "--press = ", "latin1.toml", "must be a UTF-8 text file")


def test_press_file_not_found(capsys, work):
    refused(cli(capsys, "simulate", "--press", work.root / "nope.toml", "--out", work.out),
            "nope.toml", "--press = ", "must be an existing TOML file or one of reference, crank-slider")
    work.unchanged()


def test_press_file_is_a_folder(capsys, work):
    refused(cli(capsys, "simulate", "--press", work.root, "--out", work.out), "--press = ", "must be an existing TOML file")
    work.unchanged()


def test_press_file_name_too_long(capsys, work):
    refused(cli(capsys, "simulate", "--press", work.root / LONG_NAME, "--out", work.out), "--press = ", "must be an existing TOML file")
    work.unchanged()


def test_press_file_not_utf8(capsys, work):
    path = work.root / "latin1.toml"
    path.write_bytes(REF_TEXT.replace("eight-bar", "acht-Gelenk \xe4").encode("latin-1"))
    work.snap()
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "latin1.toml", "must be a UTF-8 text file", "at byte")
    work.unchanged()


def test_press_file_empty(capsys, work):
    path = work.root / "empty.toml"
    path.write_bytes(b"")
    work.snap()
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "empty.toml", "the file is empty", "the [press] table")
    work.unchanged()


def test_press_file_invalid_toml(capsys, work):
    path = edited_press(work, "mass_kg = 743.8", "mass_kg = 743.8 kg")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), str(path), "is not valid TOML", "line", "fix the syntax")
    work.unchanged()


def test_press_file_missing_required_key(capsys, work):
    path = edited_press(work, "gear_ratio = 32.0\n", "")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
            str(path), "drive.gear_ratio = '<missing>'", "required; add 'gear_ratio' under [drive]")
    work.unchanged()


def test_press_file_misspelled_key(capsys, work):
    path = edited_press(work, 'label = "link 3"', 'lable = "link 3"')
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
            "bodies.link3.lable = 'link 3'", "is not a known key of [bodies.link3] (misspelled? did you mean 'label'?)")
    work.unchanged()


def test_press_file_key_with_a_line_break_gives_one_line(capsys, work):
    path = edited_press(work, "[press]\n", '[press]\n"gear\\nratio" = 32.0\n')
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "press.gear\\nratio = 32.0", "is not a known key")
    work.unchanged()


def test_press_file_negative_mass(capsys, work):
    path = edited_press(work, "mass_kg = 743.8", "mass_kg = -743.8")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "bodies.link3.mass_kg = -743.8", "must be > 0.0 (kg)")
    work.unchanged()


def test_press_file_efficiency_above_one(capsys, work):
    path = edited_press(work, "efficiency = 0.917", "efficiency = 1.2")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "drive.efficiency = 1.2", "must be > 0.0 and <= 1.0")
    work.unchanged()


def test_press_file_balance_coefficient_zero(capsys, work):
    path = edited_press(work, "coefficient = 1.15", "coefficient = 0.0")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
            "balance.coefficient = 0.0", "must be > 0 when cylinders > 0", "set cylinders = 0")
    work.unchanged()


def test_press_file_joint_naming_an_unknown_body(capsys, work):
    path = edited_press(work, 'connects = ["crank.A", "link6.A"]', 'connects = ["crank.A", "link9.A"]')
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
            "joints.A.connects = 'link9.A'", "body must be 'frame' or one of crank, link3")
    work.unchanged()


def test_press_file_joint_naming_an_unknown_point(capsys, work):
    path = edited_press(work, 'connects = ["crank.A", "link6.A"]', 'connects = ["crank.Z", "link6.A"]')
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
            "joints.A.connects = 'crank.Z'", "point must be one of O, A, B on body 'crank'")
    work.unchanged()


def test_press_file_linkage_that_cannot_assemble(capsys, work):
    # link 3 far too short: |BD| is about 1.55 m, link 3 (0.5 m) + DC (0.8 m) cannot reach
    path = edited_press(work, "points_m = { B = [0.0, 0.0], C = [1.369, 0.0] }", "points_m = { B = [0.0, 0.0], C = [0.5, 0.0] }")
    line = refused(cli(capsys, "simulate", "--press", path, "--out", work.out),
                   str(path), "the linkage does not assemble at crank angle", "the loop closed at joint C (link3.C to link4.C",
                   "Check the link lengths")
    assert " deg" in line.split("at crank angle", 1)[1][:12]
    work.unchanged()


def test_press_file_body_name_that_breaks_xml(capsys, work):
    path = edited_press(work, "[bodies.link3]", '[bodies."link<3>&"]')
    refused(cli(capsys, "urdf", "--press", path, "--out", work.out / "x.urdf"),
            "bodies.link<3>& = 'link<3>&'", "names must use only letters, digits, '_' or '-'")
    work.unchanged()


def test_press_name_with_a_double_dash_still_gives_well_formed_urdf(capsys, work):
    path = edited_press(work, 'name = "25,000 kN servo press, eight-bar linkage (reference)"', 'name = "press -- test <&> \\"x\\""')
    code, _, err = cli(capsys, "urdf", "--press", path, "--out", work.out / "x.urdf")
    assert code == 0, err
    ET.parse(work.out / "x.urdf")  # any XML tool (ROS, urdfdom's strict parsers) must read it


def test_press_file_absurd_com_distance_gives_one_line_subprocess(work):
    # the least-squares trilateration of link 4's COM overflows; its numpy warnings must not reach the user
    path = edited_press(work, "com = { distances_m = { E = 1.2425", "com = { distances_m = { E = 1e300")
    refused(servo_press("simulate", "--press", path, "--out", work.out),
            "bodies.link4.com.distances_m.E = 1e+300", "must be within 100 m", "max_length_m")
    work.unchanged()


def test_press_file_absurd_coordinate_gives_one_line_subprocess(work):
    path = edited_press(work, "points_m = { O = [0.0, 0.0], A = [0.22, 0.0]", "points_m = { O = [0.0, 0.0], A = [1e300, 0.0]")
    refused(servo_press("simulate", "--press", path, "--out", work.out), "bodies.crank.points_m.A = [1e+300, 0.0]", "must be within 100 m")
    work.unchanged()


def test_parameter_range_without_its_nominal_value(capsys, work):
    path = edited_press(work, 'eta_gear = { path = "drive.efficiency", range = [0.7, 0.99]',
                        'eta_gear = { path = "drive.efficiency", range = [0.95, 0.99]')
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "parameters.eta_gear.range = [0.95, 0.99]",
            "must contain the nominal value drive.efficiency = 0.917 of parameter 'eta_gear'", "widen the range")
    work.unchanged()


def test_press_file_absurd_mass(capsys, work):
    path = edited_press(work, "mass_kg = 743.8", "mass_kg = 1e300")
    refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "bodies.link3.mass_kg = 1e+300",
            "must be at most 1e+07 kg", "run_limits.toml")
    work.unchanged()


def test_press_file_with_a_utf8_byte_order_mark_is_read(capsys, work):
    """Read by a command that reads the press and builds its model (`urdf`: no cycle, no figures, which say nothing
    of the reading), and read as the reference press it holds (the same fingerprint)."""
    path = work.root / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + REF_TEXT.encode("utf-8"))
    code, _, err = cli(capsys, "urdf", "--press", path, "--out", work.out / "bom.urdf")
    assert code == 0, err
    assert load_press(path).fingerprint == load_press("reference").fingerprint


def test_job_file_given_as_press(capsys, work):
    refused(cli(capsys, "simulate", "--press", DATA / "cushion_test.toml", "--out", work.out),
            "--press = ", "is a job file (it has [job], no [press]): pass it as --job")
    work.unchanged()


def test_dead_point_on_a_one_loop_press(capsys, work):
    text = resources.files("press_model.data").joinpath("crank_slider.toml").read_text(encoding="utf-8")
    old = "points_m = { A = [0.0, 0.0], B = [1.2, 0.0] }"
    assert old in text
    path = work.root / "short_rod.toml"
    path.write_text(text.replace(old, "points_m = { A = [0.0, 0.0], B = [0.25, 0.0] }"), encoding="utf-8")  # rod = crank
    work.snap()
    line = refused(cli(capsys, "simulate", "--press", path, "--out", work.out), "short_rod.toml", "at crank angle 90.00 deg",
                   "the loop closed at joint A (crank.A to rod.A)", "passes a dead point")
    assert "every loop closes on its own" not in line and "gap" not in line  # one loop, and it is closed
    work.unchanged()


def test_cli_bad_press_file(tmp_path):
    raw_text = REF_TEXT.replace("mass_kg = 743.8", "mass_kg = -743.8")
    bad = tmp_path / "bad_press.toml"
    bad.write_text(raw_text, encoding="utf-8")
    proc = run_cli("simulate", "--press", str(bad), "--out", str(tmp_path / "out"))
    assert_clean_error(proc, str(bad), "bodies.link3.mass_kg = -743.8", "must be > 0.0 (kg)")
    assert not (tmp_path / "out").exists()


def test_cli_press_that_cannot_assemble(tmp_path):
    bad = tmp_path / "short_link.toml"
    bad.write_text(REF_TEXT.replace("points_m = { B = [0.0, 0.0], C = [1.369, 0.0] }", "points_m = { B = [0.0, 0.0], C = [0.5, 0.0] }"), encoding="utf-8")
    proc = run_cli("simulate", "--press", str(bad), "--out", str(tmp_path / "out"))
    assert_clean_error(proc, str(bad), "does not assemble at crank angle", " deg: the loop closed at joint ")


_TOML_ESCAPED = re.compile(r'["\\\x00-\x08\x0a-\x1f\x7f]')  # a quote, a backslash, the control characters but tab, DEL


def _toml_escape(match) -> str:
    ch = match.group()
    return "\\" + ch if ch in '"\\' else f"\\u{ord(ch):04X}"  # TOML basic strings must escape the control characters and DEL


def _toml_string(s: str) -> str:
    return '"' + _TOML_ESCAPED.sub(_toml_escape, s) + '"'  # a regex pass, not a Python loop per character (400 presses a run)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _toml_string(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_string(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def to_toml(raw: dict) -> str:
    """TOML text that ``tomllib`` reads back as ``raw`` (NaN aside, which never equals itself)."""
    return "".join(f"{_toml_string(k)} = {_toml_value(v)}\n" for k, v in raw.items())


def test_the_toml_writer_round_trips_the_reference_press():
    assert tomllib.loads(to_toml(REF)) == REF
    odd = {"a\"\\\x01\x7f\t": [1, 2.5, "x", [True], {"": -0.0}], "b": {"c": {"d": 1e300}}}
    assert tomllib.loads(to_toml(odd)) == odd


def _paths(node) -> list[tuple]:
    """Every key path of the tree (tables and leaves, list items by index), each before the paths under it."""
    out = []

    def walk(node, prefix):
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
        for k, v in items:
            out.append((*prefix, k))
            walk(v, out[-1])

    walk(node, ())
    return out


def _parent(raw, path):
    cur = raw
    for k in path[:-1]:
        cur = cur[k]
    return cur


_ODD_VALUES = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, 0, 0.0, -0.0, -1, -1.0, 1e300, -1e300, 1e-300, 2**63 - 1, -(2**63),
                     "", " ", "frame", "universe", "crank.O", "O", True, False, [], [0.0], [1.0, 2.0, 3.0],
                     ["crank.A", "link6.A"], {}, {"r_m": -1.0, "angle_deg": 0.0}, {"from": "O", "toward": "O"}]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.text(max_size=8),
    st.lists(st.floats(allow_nan=True), max_size=3),
)


_PRESS_EDITS = st.one_of(
    st.tuples(st.just("delete"), st.integers(0, 10_000)),
    st.tuples(st.just("replace"), st.integers(0, 10_000), _ODD_VALUES),
    st.tuples(st.just("rename"), st.integers(0, 10_000), st.text(max_size=6)),
    st.tuples(st.just("duplicate"), st.integers(0, 10_000), st.text(min_size=1, max_size=6)),
    st.tuples(st.just("scale"), st.integers(0, 10_000), st.sampled_from([-1.0, 0.0, 1e-9, 0.5, 0.9, 1.1, 2.0, 1e9])),
)


def mutate_press(edits) -> dict:
    """The reference press's tree with the edits applied; each edit picks its target by index modulo the paths."""
    raw = copy.deepcopy(REF)
    for op, index, *arg in edits:
        paths = _paths(raw)
        if op in ("duplicate",):
            paths = [p for p in paths if isinstance(_parent(raw, p)[p[-1]], dict)]
        elif op == "scale":
            paths = [p for p in paths if isinstance(_parent(raw, p)[p[-1]], (int, float)) and not isinstance(_parent(raw, p)[p[-1]], bool)]
        if not paths:
            continue
        path = paths[index % len(paths)]
        parent, key = _parent(raw, path), path[-1]
        if op == "delete":
            del parent[key]
        elif op == "replace":
            parent[key] = copy.deepcopy(arg[0])
        elif op == "scale":
            parent[key] = parent[key] * arg[0]
        elif op == "rename" and isinstance(parent, dict):
            parent[arg[0]] = parent.pop(key)
        elif op == "duplicate" and isinstance(parent, dict):
            parent[f"{key}{arg[0]}"] = copy.deepcopy(parent[key])
    return raw


def load_and_assemble(path):
    """What the command line does with --press: read, validate, and build the model (full-turn assembly check)."""
    return PressModel(load_press(path))


@settings(max_examples=400, **FIXED)
@given(st.lists(_PRESS_EDITS, min_size=1, max_size=3))
def test_a_mutated_press_file_loads_or_raises_a_servo_press_error(tmp_path, edits):
    raw = mutate_press(edits)
    path = tmp_path / "fuzz_press.toml"
    path.write_text(to_toml(raw), encoding="utf-8")
    try:
        pm = load_and_assemble(path)
    except ServoPressError as exc:
        event(type(exc).__name__)
        assert str(exc).startswith(str(path)) and "\n" not in str(exc).strip()
        return
    event("loaded and assembled")
    assert all(math.isfinite(v) for v in pm.press.parameter_values().values())
    assert 0.0 < pm.assembly.stroke < math.inf  # m: a press that assembled over the turn moves its slide


@settings(max_examples=200, **FIXED)
@given(st.one_of(st.binary(max_size=400), st.text(max_size=400).map(lambda s: s.encode("utf-8")),
                 st.tuples(st.integers(0, len(REF_TEXT)), st.integers(0, len(REF_TEXT)), st.text(max_size=20))
                 .map(lambda e: (REF_TEXT[: min(e[:2])] + e[2] + REF_TEXT[max(e[:2]):]).encode("utf-8"))))
def test_random_bytes_or_spliced_text_as_a_press_file_raise_a_servo_press_error(tmp_path, blob):
    path = tmp_path / "fuzz_press.toml"
    path.write_bytes(blob)
    try:
        load_and_assemble(path)
    except ServoPressError as exc:
        assert "\n" not in str(exc).strip()


def test_press_file_without_a_default_range_samples_70_to_130_percent_and_one_it_gives_its_own():
    """[sensitivity] default_relative_range has a default (it was required): 0.7-1.3 x nominal for a parameter without
    a range of its own; a file that gives the key gets its own factors."""
    raw = ref()
    raw.pop("sensitivity", None)
    m1 = read_press(raw, "test").parameters["m1"]
    assert (m1.low, m1.high) == (0.7 * m1.nominal, 1.3 * m1.nominal)
    setp("sensitivity.default_relative_range", [0.5, 1.5])(raw)
    m1 = read_press(raw, "test").parameters["m1"]
    assert (m1.low, m1.high) == (0.5 * m1.nominal, 1.5 * m1.nominal)
