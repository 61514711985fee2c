"""`servo-press reproduce --quick`: the whole pipeline, its report, and byte-identical reruns."""
import hashlib
import json
import multiprocessing
import re
import shutil

import pytest

from servo_press.cli import main
from press_io.outputs import MARKER


def _digests(folder):
    # the run record (.servo-press-run.json) is left out: it holds the hash of report.md, whose wall times differ
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.suffix in (".csv", ".json") and p.name != MARKER}


def _reproduce_quick(folder):
    assert main(["reproduce", "--quick", "--out", str(folder / "run")]) == 0


@pytest.fixture(scope="module")
def reproduced(heavy_results):
    """`reproduce --quick`'s folder, run once for the suite (heavy_results.py), and its files' digests. Read only."""
    folder, _ = heavy_results.get("reproduce-quick", _reproduce_quick)
    return folder / "run", _digests(folder / "run")


def test_report_holds_every_table_and_figure(reproduced):
    out, _ = reproduced
    report = (out / "report.md").read_text(encoding="utf-8")
    for needle in ("Figure 2", "Figure 3", "Table 4", "Figure 5", "Figures 6 and 7", "SYNTHETIC", "1366.9", "11.4 -> 11.6", "Out-of-sample validation",
                   "Playback verification", "pin 4.", "toppra", "Energy per stroke", "Motion modes", "| pendulum | "):
        assert needle in report, needle
    assert re.search(r"Against the stop-at-top plan of the same transfer: pendulum [+-]\d+\.\d % \(theoretical\)", report)
    if "fork" in multiprocessing.get_all_start_methods():  # the theoretical plan is the second process's first step
        assert re.search(r"theoretical door-panel plan \(every mode but continuous\) \(second process\) \d+\.\d s", report)
    for img in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report):
        assert (out / img).is_file() and (out / img).stat().st_size > 5000, img
    run = json.loads((out / "run.json").read_text())
    assert run["synthetic_inputs"]["truth"] and run["versions"]["pin"]
    assert set(run["parameters_calibrated"]) == {"eta_gear", "psi", "mu_r", "m8", "J_gear", "mu_s"}
    # the key set under both load cases, beside the paper's, and the plain statement that the paper gives no load case
    keysets = run["key_parameters_by_load_case"]
    assert set(keysets) == {"cushion-test", "no-load", "paper (load case not stated)"}
    assert "does not state the load case" in report and "sensitivity_no_load/sobol_indices.png" in report
    for name, folder in (("cushion-test", "sensitivity"), ("no-load", "sensitivity_no_load")):
        assert json.loads((out / folder / "key_parameters.json").read_text())["key_parameters"] == keysets[name]


def test_same_seed_gives_identical_csv_and_json(reproduced, tmp_path):
    earlier, first = reproduced
    assert len(first) >= 15  # every step's tables and records
    out = tmp_path / "run"
    shutil.copytree(earlier, out, symlinks=True)  # the rerun replaces the earlier run's folder: a copy of the stored one
    assert main(["reproduce", "--quick", "--out", str(out)]) == 0
    second = _digests(out)
    changed = [k for k in first if first[k] != second.get(k)]
    assert not changed and set(first) == set(second), changed
    record = {f["path"]: f["sha256"] for f in json.loads((out / MARKER).read_text(encoding="utf-8"))["files"]}
    assert {k: record[k] for k in second} == second  # the record holds every file's hash, report.md's too
    # nothing names the temporary folder the run was written in (a rerun in another process would differ)
    leaked = [k for k in first if ".tmp-" in (out / k).read_text(encoding="utf-8")]
    assert not leaked and ".tmp-" not in (out / "report.md").read_text(encoding="utf-8"), leaked
