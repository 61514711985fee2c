"""The chain a user walks (SYNTHETIC log -> calibrate -> plan --params calibrated.json) checked on the press that made
the log: the default plan keeps the 10 % torque margin on the true press, or `plan` says plainly that it may not."""
from __future__ import annotations

import importlib.util
from pathlib import Path

from in_process import servo_press

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "check_chain.py"


def _check_chain():
    spec = importlib.util.spec_from_file_location("check_chain", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_default_plan_from_a_calibration_keeps_the_margin_on_the_true_press_or_warns(tmp_path, monkeypatch):
    chain = _check_chain()
    # the script's commands (experiment, calibrate, plan) run in this process (in_process.py), not in three subprocesses
    # that would each import Pinocchio, CasADi, numba and matplotlib again: the same commands, arguments and folders
    monkeypatch.setattr(chain, "run_servo_press", lambda args, cwd: servo_press(*args, cwd=cwd))
    row = chain.run_row(1, "clean", tmp_path / "chain", plans=("default",))
    d = row["default"]
    # the profile.csv played on the truth's per-point model, Eq. 16: within 0.90 T_max, or plan printed a WARNING
    assert d["true_peak_ratio"] <= chain.MARGIN or d["warned"], (row["truth"], d)
    assert d["true_peak_ratio"] > 0.5  # the play-back did run the stroke (not an empty profile)
