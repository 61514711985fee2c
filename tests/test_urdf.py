"""The committed URDF is current, valid for urdfdom, loads in Pinocchio, and carries the loop closures."""
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from press_model import kinematics as K
from press_model.model import Workspace, load_urdf_model
from press_model.press_data import load_press
from press_model.urdf import loops_dict, urdf_text

from in_process import servo_press  # noqa: E402 (tests/ is on sys.path, conftest.py)

REPO = Path(__file__).resolve().parents[1]
URDF = REPO / "urdf" / "eight_bar.urdf"


def test_committed_urdf_is_current():
    press = load_press()
    assert URDF.read_text(encoding="utf-8") == urdf_text(press, robot_name="eight_bar"), "regenerate: servo-press urdf --out urdf/eight_bar.urdf"
    import json

    assert json.loads(URDF.with_suffix(".loops.json").read_text()) == loops_dict(press, URDF.name)


def test_check_urdf_accepts_it():
    exe = shutil.which("check_urdf")
    if exe is None:
        pytest.fail("check_urdf not found: it ships with the pip package cmeel-urdfdom, a dependency of pin")
    out = subprocess.run([exe, str(URDF)], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "Successfully Parsed XML" in out.stdout


def test_urdf_round_trip_matches_the_model(ref_model):
    """Loaded back from disk, the tree with its loop file closes the loops of the in-memory model's solution."""
    model, cuts = load_urdf_model(URDF)
    assert model.nq == ref_model.nv == 7
    assert [c["name"] for c in cuts] == ["C", "F1", "F2"]
    assert np.allclose(model.gravity.linear, [0, -9.81, 0])
    data = model.createData()
    q = K.solve_position(ref_model, Workspace(ref_model), 1.0, ref_model.assembly.qs[57])
    pin.framesForwardKinematics(model, data, q)
    for c in cuts:
        a = data.oMf[model.getFrameId(c["first_frame"])].translation
        b = data.oMf[model.getFrameId(c["second_frame"])].translation
        assert np.linalg.norm(a - b) < 1e-10
    total = sum(model.inertias[i].mass for i in range(1, model.njoints))
    assert total == pytest.approx(ref_model.total_mass)


def test_cli_writes_urdf_without_touching_other_files(tmp_path):
    out = tmp_path / "press.urdf"
    r = servo_press("urdf", "--out", out)  # in this process (tests/in_process.py): the files are checked, not the process
    assert r.returncode == 0, r.stderr
    assert out.is_file() and out.with_suffix(".loops.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["press.loops.json", "press.urdf"]
