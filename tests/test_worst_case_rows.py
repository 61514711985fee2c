"""The worst case per segment (planning/limits.py, WorstCase): one row set that is, on each segment, the chosen member's rows."""
import dataclasses

import numpy as np

from planning.jerk import JerkProfile
from planning.optimal import TorqueRows
from planning.limits import WorstCase, _combine, row_values, segment_torques
from press_model.press_data import load_press


def _rows(rng, n, drive):
    return TorqueRows(rng.uniform(50, 80, n), rng.uniform(-5, 5, n), rng.uniform(-2e5, 2e5, n), rng.uniform(-2e5, 2e5, n),
                      rng.uniform(-3, 3, n), rng.uniform(-20, 20, n), rng.uniform(-20, 20, n), drive)


def _profile(rng, n):
    theta = np.linspace(0.0, 2 * np.pi, n)
    return theta, JerkProfile(theta, rng.uniform(0.5, 2.0, n), rng.uniform(-20, 20, n), rng.uniform(0.005, 0.02, n - 1), False)


def test_combined_rows_are_the_chosen_members_rows_on_each_segment():
    rng = np.random.default_rng(3)
    n = 40
    drive = load_press(None).drive
    members = [_rows(rng, n, dataclasses.replace(drive, gear_inertia=j)) for j in (50.0, 60.0, 70.0)]
    theta, prof = _profile(rng, n)
    pick = rng.integers(0, 3, n - 1)
    combined = _combine(members, pick)
    assert combined.drive.gear_inertia == 0.0  # carried into m
    got = segment_torques(combined, prof, theta)
    for k, r in enumerate(members):
        own = segment_torques(r, prof, theta)
        assert np.allclose(got[:, pick == k], own[:, pick == k], rtol=1e-12, atol=1e-6)


def test_the_worst_case_is_the_largest_row_of_its_group():
    rng = np.random.default_rng(4)
    n = 30
    drive = load_press(None).drive
    members = [_rows(rng, n, drive) for _ in range(4)]
    theta, prof = _profile(rng, n)
    still = np.zeros(n, bool)
    wc = WorstCase([("motoring", [0, 1]), ("braking", [2, 3])], theta, still)
    rows = wc.compose(members, prof)
    assert len(rows) == 2
    mot = np.max(row_values(rows[0], prof, theta, still)[0], axis=0)
    brk = np.max(row_values(rows[1], prof, theta, still)[1], axis=0)
    assert np.allclose(mot, np.max([np.max(row_values(members[i], prof, theta, still)[0], axis=0) for i in (0, 1)], axis=0))
    assert np.allclose(brk, np.max([np.max(row_values(members[i], prof, theta, still)[1], axis=0) for i in (2, 3)], axis=0))
    # every member's rows hold at the largest of them, and not below it
    level = float(max(np.max(mot), np.max(brk)))
    assert wc.holds(prof, level, 1e-9) and not wc.holds(prof, 0.99 * level, 1e-9)


def test_a_choice_is_kept_on_a_tie_and_given_up_when_beaten():
    rng = np.random.default_rng(5)
    n = 30
    drive = load_press(None).drive
    base = _rows(rng, n, drive)
    theta, prof = _profile(rng, n)
    still = np.zeros(n, bool)

    def shifted(d):  # the same rows with d N m more crank torque everywhere
        return dataclasses.replace(base, rest_right=base.rest_right + d, rest_left=base.rest_left + d)

    wc = WorstCase([("motoring", [0, 1])], theta, still)
    wc.compose([base, shifted(-1.0)], prof)
    assert np.all(wc.choice[0] == 0)
    wc.compose([base, shifted(1e-6)], prof)  # larger by far less than the hysteresis: no flip between re-solves
    assert np.all(wc.choice[0] == 0)
    wc.compose([base, shifted(100.0)], prof)
    assert np.all(wc.choice[0] == 1)
