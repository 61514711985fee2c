"""The marked figures of the front page's worked example (docs/validation.md, "The worked example, run as written")
are the ones a run of README.md's documented commands gives (scripts/readme_figures.py runs them in a folder outside the
repository), and no README or docs page quotes a test count (it changes with every commit)."""
from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

import in_process  # noqa: E402 (tests/ is on sys.path, conftest.py)

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "validation.md"


def _script():
    spec = importlib.util.spec_from_file_location("readme_figures", ROOT / "scripts" / "readme_figures.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


rf = _script()


def test_a_stale_or_unmeasured_figure_is_caught():
    text = FIGURES.read_text(encoding="utf-8")
    have = rf.marked(text)
    assert {"worked_m8", "worked_m8_interval", "worked_all_F", "worked_key_set"} <= set(have)
    assert rf.differences(text, have) == []
    stale = text.replace(f"<!-- figure:worked_m8_interval -->{have['worked_m8_interval']}<!-- /figure -->",
                         "<!-- figure:worked_m8_interval -->1-2 kg<!-- /figure -->")
    assert rf.differences(stale, have) == [f"worked_m8_interval: recorded '1-2 kg', run {have['worked_m8_interval']!r}"]
    assert rf.marked(rf.update(stale, have)) == have
    assert rf.differences(text, {k: v for k, v in have.items() if k != "worked_all_F"}) == \
        [f"worked_all_F: recorded {have['worked_all_F']!r}, measured by nothing"]


def test_the_front_page_links_the_worked_examples_figures():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "docs/validation.md#the-worked-example-run-as-written" in readme
    assert "## The worked example, run as written" in FIGURES.read_text(encoding="utf-8")


def _servo_press_in_process(cwd: Path, argv: list[str]) -> None:
    """scripts/readme_figures.py's servo_press, run in this process (tests/in_process.py): the commands' results are
    what is checked, not their processes (each would import Pinocchio, CasADi and numba again)."""
    r = in_process.servo_press(*argv, cwd=cwd)
    if r.returncode != 0:
        raise RuntimeError(f"servo-press {' '.join(argv)} (in {cwd}) exited {r.returncode}: {r.stderr.strip()}")


# fixtures_suitecal.py: `sensitivity` forks its SALib process at its start, which imports matplotlib to draw the Sobol
# figure unless this process holds it (the calibrations draw Figure 5 here, so this process imports it anyway)
@pytest.mark.usefixtures("pyplot_imported")
def test_readme_worked_example_figures_are_what_its_commands_give(tmp_path, monkeypatch):
    """Steps 2 and 3 of README.md's worked example and its calibration without --parameters, run as README.md writes
    them, give the figures docs/validation.md marks."""
    monkeypatch.setattr(rf, "servo_press", _servo_press_in_process)
    measured = rf.measure(tmp_path)
    assert rf.differences(FIGURES.read_text(encoding="utf-8"), measured) == [], \
        "run `python scripts/readme_figures.py --update` and reread the record"


def test_no_readme_quotes_a_test_count():
    for readme in [ROOT / "README.md", *sorted(ROOT.glob("*/README.md")), *sorted(ROOT.glob("docs/*.md"))]:
        text = readme.read_text(encoding="utf-8")
        assert not re.search(r"\b\d[\d,]* tests\b", text), readme
