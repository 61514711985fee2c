"""A pendulum plan carries what a stop-at-top plan carries: the calibration's verdict (summary.json
``calibration_verdict`` and the WARNING on stderr) and the energy per stroke (summary ``energy``, power.csv, power.png
with the press file's [drive.electrical]; the energy lines printed). One `plan --verify` of the door panel in pendulum mode
on a 5-degree grid (the coarsest a job may state: the verdict carried, the energy's bookkeeping and the process work hold
on any knots), with a calibration that says it is not adequate: the suite's (fixtures_suiteplan.py), which
test_planning_pendulum plays back."""
from __future__ import annotations

import csv
import json
from types import SimpleNamespace

import numpy as np
import pytest

# the door panel's process work, from its force curve (press_model/data/door_panel.toml: 2 MN at die contact 0.20 m
# rising linearly to 6 MN at 0.02 m, 6 MN down to BDC): (2 + 6) / 2 MN x 0.18 m + 6 MN x 0.02 m, done once per cycle on
# the working swing (the return carries no process force)
PROCESS_WORK_J = 0.5 * (2.0e6 + 6.0e6) * 0.18 + 6.0e6 * 0.02


@pytest.fixture(scope="module")
def pendulum(verified_coarse_pendulum):
    """(plan folder, the run's exit code, stdout and stderr, summary, calibrated.json): the suite's `plan --verify` of this
    job with a calibration at the press file's own slide mass that says it is not adequate (fixtures_suiteplan.py,
    test_planning_pendulum reads it too); the playback adds to what is read here and changes none of it."""
    folder, code, out, err = verified_coarse_pendulum
    r = SimpleNamespace(returncode=code, stdout=out, stderr=err)
    assert r.returncode == 0, r.stderr
    return folder / "plan", r, json.loads((folder / "plan" / "summary.json").read_text(encoding="utf-8")), folder / "calibrated.json"


def test_a_pendulum_plan_carries_the_calibrations_verdict_and_warns(pendulum):
    out, r, s, cal = pendulum
    assert s["mode"] == "pendulum"
    assert s["calibration_verdict"]["adequate"] is False and s["calibration_verdict"]["source"] == str(cal)
    warned = [ln for ln in r.stderr.splitlines() if ln.startswith(f"WARNING: {cal}")]
    assert len(warned) == 1 and "NOT ADEQUATE" in warned[0]


def test_a_pendulum_plan_writes_its_energy_as_stop_at_top_does(pendulum):
    out, r, s, _ = pendulum
    en = s["energy"]
    assert (out / "power.png").stat().st_size > 5000
    with open(out / "power.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    t = np.array([float(x["time_s"]) for x in rows])
    grid = np.array([float(x["grid_W"]) for x in rows])
    assert t[-1] == pytest.approx(s["cycle_time_s"], rel=1e-9)  # one cycle: both swings and both dwells
    assert float(np.trapezoid(grid, t)) == pytest.approx(en["net_J"], rel=2e-3)  # power.csv integrates to the summary's energy
    # the process work is the force curve's integral, however the slide gets there (within the 2 ms sampling)
    assert en["lost_J"]["process_work_J"] == pytest.approx(PROCESS_WORK_J, rel=5e-3)
    assert en["net_J"] > PROCESS_WORK_J  # the grid pays the forming and the losses
    assert any(line.startswith("energy per stroke:") for line in r.stdout.splitlines())
