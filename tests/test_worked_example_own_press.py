"""README.md's worked example ("Your own press and drive log"), every command run as README.md writes it (read from
README.md, run in this process in a folder outside the repository), on a press that is not the reference: the copied
press file edited as a user with another press would (slide 15 % heavier, motor peak torque 10 % lower, a 35:1 gear)
and the copied cushion job for that press's cushion (4,000 kN over the last 250 mm). The calibration ends adequate
and the part's plan plays back with VERIFY OK.

The copied job's [experiment.truth] (the paper's Table 4) stays as the user finds it: the SYNTHETIC log's J_gear, psi
and mu_s differ from the press file's values, which the sensitivity's key set (step 2) may hold fixed; the calibration
must find that out from the log (calibration/identification/held.py). One run of the whole example, shared by the
assertions (the heavy test: sensitivity at its default N, a calibration, a robust plan and a comparison)."""
from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest

import in_process  # noqa: E402 (tests/ is on sys.path, conftest.py)

ROOT = Path(__file__).resolve().parents[1]


def _example_commands() -> list[list[str]]:
    spec = importlib.util.spec_from_file_location("readme_figures", ROOT / "scripts" / "readme_figures.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.example_commands((ROOT / "README.md").read_text(encoding="utf-8"))


def _edit(path: Path, changes: dict[str, str]) -> None:
    """Replace each whole line ``key = value`` whose key and old value ``changes`` names (the first such line)."""
    text = path.read_text(encoding="utf-8")
    for old, new in changes.items():
        text, n = re.subn(rf"^{re.escape(old)}(?=\s|$)", new, text, count=1, flags=re.M)
        assert n == 1, f"{path.name}: no line {old!r}"
    path.write_text(text, encoding="utf-8")


def edit_own_press(folder: Path) -> None:
    """What the user edits after the `cp` lines: the press (README step 1) and the cushion job (step 3)."""
    _edit(folder / "my_press.toml", {"mass_kg = 30595.0": f"mass_kg = {30595.0 * 1.15:.1f}",  # the slide, 15 % heavier
                                     "peak_torque_Nm = 25000.0": f"peak_torque_Nm = {25000.0 * 0.9:.1f}",
                                     "gear_ratio = 32.0": "gear_ratio = 35.0",
                                     'name = "25,000 kN servo press, eight-bar linkage (reference)"': 'name = "my press"'})
    _edit(folder / "my_cushion.toml", {"contact_height_m = 0.30": "contact_height_m = 0.25",
                                       "heights_m = [0.30, 0.0]": "heights_m = [0.25, 0.0]",
                                       "forces_N = [5.0e6, 5.0e6]": "forces_N = [4.0e6, 4.0e6]"})


def run_example(work: Path, commands: list[list[str]]) -> tuple[str, dict]:
    """The worked example's ``commands`` run as README.md writes them in ``work`` (the repository's press_model linked
    in, the user's folder beside it), the press and job edited before the first command: (the folder the last `cd`
    went to, relative to ``work``; {command: its CompletedProcess})."""
    root = work / "repo"  # the commands' press_model/data/... paths are the repository's own: linked in
    root.mkdir()
    (root / "press_model").symlink_to(ROOT / "press_model", target_is_directory=True)
    cwd, results, edited = root, {}, False
    for words in commands:
        if words[0] == "mkdir":
            (cwd / words[-1]).mkdir(parents=True, exist_ok=True)
        elif words[0] == "cp":
            (cwd / words[2]).write_bytes((cwd / words[1]).read_bytes())
        elif words[0] == "cd":
            cwd = (cwd / words[1]).resolve()
        else:
            assert words[0] == "servo-press", words
            if not edited:
                edit_own_press(cwd)
                edited = True
            r = in_process.servo_press(*words[1:], cwd=cwd)
            results[words[1]] = r
            assert "Traceback" not in r.stderr, r.stderr
            assert r.returncode == 0, f"servo-press {' '.join(words[1:])}: exit {r.returncode}: {r.stderr}"
    return str(cwd.relative_to(work.resolve())), results


@pytest.fixture(scope="session")
def own_press_example(heavy_results):
    """The worked example run as README.md writes it on the edited press: (the example's folder, {step: result}), run
    once and kept while the code, this module and README.md's commands are unchanged (heavy_results.py). Read only."""
    commands = _example_commands()
    work, (folder, results) = heavy_results.get("worked-example-own-press", lambda w: run_example(w, commands), commands)
    return work / folder, results


def test_worked_example_on_an_own_press_calibrates_adequate(own_press_example):
    folder, results = own_press_example
    cal = json.loads((folder / "my_press" / "cal" / "calibrated.json").read_text(encoding="utf-8"))
    assert cal["press"] == "my press"
    assert cal["adequacy"]["adequate"], cal["warnings"]
    assert not any(w.startswith(("MODEL NOT ADEQUATE", "HELD PARAMETER WRONG")) for w in cal["warnings"])
    # the log's truth sits in every interval the fit reports, the freed parameters' included
    truth = json.loads((folder / "drive_log.truth.json").read_text(encoding="utf-8"))["truth"]
    box = cal["joint_region"]["box"]
    assert all(box[n][0] <= truth[n] <= box[n][1] for n in cal["parameters"]), (cal["parameters"], truth)
    # no ringing or recording shift printed that the log does not carry (the log has neither a delay nor an offset)
    assert "61100" not in cal["measured_peak"]["method"]
    assert "torque-channel delay of" not in results["calibrate"].stdout


def test_worked_example_on_an_own_press_plans_with_verify_ok(own_press_example):
    folder, results = own_press_example
    assert "VERIFY OK" in results["plan"].stdout, results["plan"].stdout
    summary = json.loads((folder / "my_press" / "plan" / "summary.json").read_text(encoding="utf-8"))
    assert summary["calibration_verdict"]["adequate"] is True
    assert "NOT ADEQUATE" not in results["plan"].stderr and "NOT ADEQUATE" not in results["compare"].stderr
