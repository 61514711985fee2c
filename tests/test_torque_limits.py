"""The peak-torque margin is applied in one place, press_model/torque_limits.py: the plan's feed-forward limit and the
verdict's limit are the job file's margin and reserve times the press file's T_max, and no other module multiplies
the margin or the reserve out."""
import ast
import dataclasses
from pathlib import Path

import pytest

import source_trees

from planning.settings import LimitsSection, read_planning
from press_model.jobs import load_job

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("press_model", "planning", "calibration")
HOME = Path("press_model") / "torque_limits.py"
FRACTIONS = ("torque_margin", "peak_torque_margin", "feedback_reserve")


def test_plan_limits_are_the_job_files_fractions_of_t_max(press):
    """door_panel.toml: margin 0.9 and reserve 0.01 of the press file's T_max (25,000 N m), read from the files."""
    spec = read_planning(load_job("door-panel"))
    raw = {**{f.name: f.default for f in dataclasses.fields(LimitsSection)},  # the file's, else the defaults it keeps
           **load_job("door-panel").raw["planning"].get("limits", {})}
    t_max = press.raw()["motor"]["peak_torque_Nm"]
    lim = spec.torque_limits(press.motor.peak_torque)
    assert lim.verdict == pytest.approx(raw["peak_torque_margin"] * t_max, rel=1e-15)
    assert lim.feedforward == pytest.approx((raw["peak_torque_margin"] - raw["feedback_reserve"]) * t_max, rel=1e-15)
    assert lim.feedforward < lim.verdict < t_max


def margin_arithmetic(source: str, tree: ast.Module | None = None) -> list[str]:
    """Where ``source`` (Python; ``tree`` its parse if already made) multiplies out a torque margin or the feedback
    reserve (arithmetic on a name or attribute called torque_margin, peak_torque_margin or feedback_reserve)."""
    def named(node) -> bool:
        return (isinstance(node, ast.Name) and node.id in FRACTIONS) or (isinstance(node, ast.Attribute) and node.attr in FRACTIONS)

    return [f"line {node.lineno}: {ast.get_source_segment(source, node)}" for node in ast.walk(tree or ast.parse(source))
            if isinstance(node, ast.BinOp) and (named(node.left) or named(node.right))]


@pytest.mark.parametrize("spelling", [
    "return (spec.torque_margin - spec.feedback_reserve) * pm.press.motor.peak_torque",
    "margin = spec.torque_margin * t_max",
    "ok = peak <= s.peak_torque_margin * motor.peak_torque",
])
def test_the_margin_scan_finds_a_margin_multiplied_out(spelling):
    assert margin_arithmetic(spelling)


def test_the_torque_margin_is_applied_only_in_its_home():
    found = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT)
            if rel != HOME:
                found += [f"{rel}: {hit}" for hit in margin_arithmetic(source_trees.source(path), source_trees.tree(path))]
    assert not found, "a torque margin multiplied out outside press_model/torque_limits.py (use TorqueLimits):\n" + "\n".join(found)
