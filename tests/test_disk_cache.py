"""What press_model.disk_cache keeps between processes, the assembly sweep and the batch model's per-angle
constants: the same bits as a fresh computation, another file for another press, motion or load, damaged files
ignored, a failing press never stored, and a later process that loads a press without scipy.optimize."""
import os
import subprocess
import sys
from pathlib import Path

import dataclasses

import numpy as np
import pytest

from press_model import batch as BT
from press_model import disk_cache as DC
from press_io.errors import AssemblyError
from press_model.kinematics import assembly_sweep
from press_model.model import PressModel, Workspace
from press_model.press_data import load_press, read_press

FIELDS = ("thetas", "qs", "s_bdc", "stroke", "theta_bdc", "theta_tdc")


@pytest.fixture
def cache_home(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    return tmp_path / "servo-press-twin" / "assembly"


def sweep_files(folder: Path, kind: str = "assembly") -> list[Path]:
    return sorted(folder.glob(f"{kind}_*.npz"))


def assert_same_sweep(a, b):
    for k in FIELDS:
        assert np.array_equal(getattr(a, k), getattr(b, k)), k


def test_a_stored_sweep_is_the_fresh_sweep_to_the_bit(cache_home):
    press = load_press()
    first = PressModel(press)  # sweeps and stores
    assert len(sweep_files(cache_home)) == 1
    second = PressModel(press)  # reads the file
    fresh = assembly_sweep(first, Workspace(first))
    assert_same_sweep(second.assembly, fresh)
    assert_same_sweep(first.assembly, fresh)


def test_another_press_reads_another_file(cache_home):
    ref = PressModel(load_press())
    slider = PressModel(load_press("crank-slider"))
    assert len(sweep_files(cache_home)) == 2
    assert slider.assembly.stroke != ref.assembly.stroke
    raw = load_press().raw()
    crank = raw["bodies"]["crank"]["points_m"]
    crank["A"], crank["B"] = [1.001 * x for x in crank["A"]], [1.001 * x for x in crank["B"]]  # a 0.1 % longer crank
    longer = PressModel(read_press(raw, "test"))
    assert len(sweep_files(cache_home)) == 3
    assert longer.assembly.stroke != pytest.approx(ref.assembly.stroke, rel=1e-5)


def test_a_damaged_file_is_swept_again_and_replaced(cache_home):
    press = load_press()
    good = PressModel(press).assembly
    (path,) = sweep_files(cache_home)
    path.write_bytes(b"not an npz file")
    again = PressModel(press).assembly
    assert_same_sweep(again, good)
    assert DC._read(path, ("thetas", "qs")) is not None  # rewritten whole


def test_a_press_that_does_not_assemble_is_never_stored(cache_home):
    raw = load_press().raw()
    raw["bodies"]["link3"]["points_m"]["C"] = [0.5, 0.0]  # link 3 far too short to reach link 4
    for _ in range(2):  # refused the second time too: nothing was stored that could let it through
        with pytest.raises(AssemblyError):
            PressModel(read_press(raw, "test"))
    assert sweep_files(cache_home) == []


def test_only_the_newest_sweeps_are_kept(cache_home, monkeypatch):
    monkeypatch.setitem(DC.FILES_KEPT, "assembly", 2)
    raw = load_press().raw()
    for k in range(4):
        raw["press"]["gravity_m_s2"] = 9.81 + 0.001 * k  # another press each time, same geometry
        PressModel(read_press(raw, "test"))
    assert len(sweep_files(cache_home)) == 2


def _press_with_gravity(raw: dict, k: int):
    raw["press"]["gravity_m_s2"] = 9.81 + 0.001 * k  # another press each time, same geometry
    return read_press(raw, "test")


def test_a_sweep_read_again_outlives_older_unread_ones(cache_home, monkeypatch):
    """Pruning ranks by use, not by writing: the sweep read since is kept, the one only written before is pruned."""
    monkeypatch.setitem(DC.FILES_KEPT, "assembly", 2)
    raw = load_press().raw()
    PressModel(_press_with_gravity(raw, 0))
    (first,) = sweep_files(cache_home)
    PressModel(_press_with_gravity(raw, 1))
    (second,) = set(sweep_files(cache_home)) - {first}
    old = first.stat().st_mtime - 100.0
    os.utime(first, (old, old))  # both written long ago, the first before the second
    os.utime(second, (old + 50.0, old + 50.0))
    PressModel(_press_with_gravity(raw, 0))  # read: used now
    PressModel(_press_with_gravity(raw, 2))  # written: the folder pruned to two
    kept = sweep_files(cache_home)
    assert len(kept) == 2 and first in kept and second not in kept


def test_the_bytes_kept_bound_the_folder_but_keep_the_newest(cache_home, monkeypatch):
    monkeypatch.setitem(DC.BYTES_KEPT, "assembly", 1)  # less than one file: only the one just written stays
    raw = load_press().raw()
    for k in range(3):
        PressModel(_press_with_gravity(raw, k))
        assert len(sweep_files(cache_home)) == 1
    (last,) = sweep_files(cache_home)
    assert DC._read(last, ("thetas", "qs")) is not None


def test_an_unwritable_cache_costs_only_the_sweep(tmp_path, monkeypatch):
    monkeypatch.setattr(DC, "cache_dirs", lambda kind: [tmp_path / "file" / kind])
    (tmp_path / "file").write_text("a file where the folder would be")
    assert PressModel(load_press()).assembly.stroke == pytest.approx(1.40167, abs=1e-4)


def test_a_later_process_loads_the_press_without_scipy_optimize(tmp_path):
    """The reason for the cache: scipy.optimize's import was a fifth of a whole `simulate`."""
    code = ("import sys; from press_model.model import PressModel; from press_model.press_data import load_press; "
            "PressModel(load_press()); print('scipy.optimize' in sys.modules)")
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path)}
    runs = [subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout.strip()
            for _ in range(2)]
    assert runs == ["True", "False"]


def batch_arrays(bm) -> dict:
    return {f.name: getattr(bm, f.name) for f in dataclasses.fields(bm) if isinstance(getattr(bm, f.name), np.ndarray)}


def test_a_stored_batch_model_is_the_fresh_one_to_the_bit(cache_home, cushion):
    job, motion = cushion
    pm = PressModel(load_press())
    fresh = batch_arrays(BT.build_batch_model(pm.press, motion, job.process, pm=pm))
    stored = BT.build_batch_model(pm.press, motion, job.process, pm=pm)
    assert len(sweep_files(cache_home.parent / "batch", "batch")) == 1
    again = batch_arrays(stored)
    assert fresh.keys() == again.keys()
    for k in fresh:
        assert np.array_equal(fresh[k], again[k]) and fresh[k].dtype == again[k].dtype, k
        assert not again[k].flags.writeable and again[k].flags.c_contiguous, k


def test_another_motion_or_load_builds_another_batch_model(cache_home, cushion):
    from press_model.forces import NO_PROCESS
    from press_model.jobs import make_motion

    job, motion = cushion
    pm = PressModel(load_press())
    a = BT.build_batch_model(pm.press, motion, job.process, pm=pm)
    b = BT.build_batch_model(pm.press, make_motion(job.motion, job.source, 8.0), job.process, pm=pm)  # slower strokes
    c = BT.build_batch_model(pm.press, motion, NO_PROCESS, pm=pm)
    assert len(sweep_files(cache_home.parent / "batch", "batch")) == 3
    nominal = [BT.motor_torques(bm, bm.nominal[None])[0] for bm in (a, b, c)]
    assert np.max(np.abs(nominal[0] - nominal[1])) > 1.0 and np.max(np.abs(nominal[0] - nominal[2])) > 1.0  # N m


def test_a_stored_torque_table_is_the_fresh_table_to_the_bit(cache_home):
    """The model torque table of a synthetic log (calibration.synthetic.experiment) comes from the per-point path the first time,
    from the disk afterwards, with the same bits; another truth (the press data with overrides) or another load reads
    another file."""
    from calibration.synthetic.experiment import torque_table
    from press_model.cycle import motor_torque_at
    from press_model.forces import NO_PROCESS
    from press_model.jobs import load_job, make_motion

    job = load_job("cushion-test")
    motion = make_motion(job.motion, job.source)
    press = load_press("crank-slider")
    pm = PressModel(press)
    folder = cache_home.parent / "torque"
    theta, first = torque_table(pm, motion, job.process, np.radians(2.0))
    assert len(sweep_files(folder, "torque")) == 1
    theta2, second = torque_table(pm, motion, job.process, np.radians(2.0))
    fresh = motor_torque_at(pm, job.process, theta, motion.theta_dot(theta), motion.theta_ddot(theta))
    assert np.array_equal(theta, theta2) and np.array_equal(first, fresh) and np.array_equal(second, fresh)
    name = next(iter(press.parameters))
    heavier = PressModel(press.with_overrides({name: 1.1 * press.parameters[name].nominal}))
    _, other = torque_table(heavier, motion, job.process, np.radians(2.0))
    torque_table(pm, motion, NO_PROCESS, np.radians(2.0))
    assert len(sweep_files(folder, "torque")) == 3 and not np.array_equal(other, first)


def test_a_synthetic_logs_grid_kinematics_are_kept_by_the_press_geometry_alone(cache_home):
    """The kinematics under a synthetic log's torque table (press_model.kinematic_tables: the grid's states and
    the force steps) are solved once per press geometry: another truth of masses and friction reads them again, and its
    table is still the per-point model's to the bit; a rod 0.1 % longer keys other kinematics."""
    from calibration.synthetic.experiment import torque_table
    from press_model.kinematic_tables import geometry_key
    from press_model.cycle import motor_torque_at
    from press_model.jobs import load_job, make_motion

    job = load_job("cushion-test")
    motion = make_motion(job.motion, job.source)
    press = load_press("crank-slider")
    pm = PressModel(press)
    folder = cache_home.parent / "kinematics"
    torque_table(pm, motion, job.process, np.radians(2.0))
    solved = sweep_files(folder, "kinematics")
    assert len(solved) == 2  # the grid's states and the force steps
    truth = {"m3": 1.2 * press.parameters["m3"].nominal, "mu_r": 0.03, "eta_gear": 0.9}
    other = PressModel(press.with_overrides(truth))
    assert geometry_key(other) == geometry_key(pm)
    theta, table = torque_table(other, motion, job.process, np.radians(2.0))
    assert sweep_files(folder, "kinematics") == solved
    fresh = motor_torque_at(other, job.process, theta, motion.theta_dot(theta), motion.theta_ddot(theta))
    assert np.array_equal(table, fresh)
    raw = press.raw()
    rod = raw["bodies"]["rod"]["points_m"]
    rod["B"] = [1.001 * x for x in rod["B"]]
    assert geometry_key(PressModel(read_press(raw, "test"))) != geometry_key(pm)
