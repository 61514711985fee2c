"""The door panel's minimum-energy plan shared by the planning modules (conftest.py's ``pytest_plugins``; tests/ is on sys.path),
computed once for the suite in the store of heavy results (heavy_results.py)."""
from __future__ import annotations

import pytest

COARSE_DEG = 5.0  # the coarsest knots a job may state
TARGET_SPM = 11.0  # the door panel's minimum-energy rate (its time optimum: 13.7 spm)


def _min_energy_verified(folder):
    """make(folder) for the store: `plan --verify` of the shipped door panel on COARSE_DEG knots at TARGET_SPM
    ([planning.power] target_strokes_per_min), from no IPOPT solver built before it (planning.optimal.clear_solvers:
    its time-optimal stroke is then the suite's coarse_door_panel_plan to the bit); job.toml written into the folder,
    the plan into its plan/; returns (exit code, stdout, stderr)."""
    from importlib import resources

    from in_process import servo_press
    from planning.optimal import clear_solvers

    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    text = text.replace("[planning]\n", f"[planning]\ngrid_step_deg = {COARSE_DEG}\n", 1)
    (folder / "job.toml").write_text(text + f"\n[planning.power]\ntarget_strokes_per_min = {TARGET_SPM}\n", encoding="utf-8")
    clear_solvers()
    r = servo_press("plan", "--job", folder / "job.toml", "--verify", "--out", folder / "plan")
    return r.returncode, r.stdout, r.stderr


@pytest.fixture(scope="session")
def coarse_min_energy_verified(heavy_results):
    """(folder, exit code, stdout, stderr) of the suite's one `plan --job job.toml --verify --out plan` of the door panel
    on COARSE_DEG knots at TARGET_SPM (the folder holds job.toml and plan/): test_min_energy_plan reads the plan and its
    playback, test_min_energy_under_transfer_window its minimum-energy record (the window's saving on these knots).
    Read only."""
    folder, (code, out, err) = heavy_results.get("min-energy-coarse-verified", _min_energy_verified, COARSE_DEG, TARGET_SPM)
    return folder, code, out, err
