"""What a new user's first hour depends on in the READMEs: a virtual environment before `pip install` (systems that
manage their own Python refuse it outside one), that environment ignored by git, a worked example that writes
outside the repository, and an "Against the paper" paragraph that names the key set its own table gives.

The key set itself is measured by `sensitivity` (tests/test_cli_sensitivity.py, and `reproduce`); here the
README's statements are checked against each other and against the repository's files.
"""
from __future__ import annotations

import re
import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
CAL_README = (ROOT / "calibration" / "README.md").read_text(encoding="utf-8")


def _section(text: str, title: str) -> str:
    start = text.index(title)
    end = text.find("\n## ", start + len(title))
    return text[start:] if end < 0 else text[start:end]


def _commands(block: str) -> list[str]:
    """The shell lines of a README code block, comments dropped and continuation lines joined."""
    text = re.sub(r"\\\n\s*", " ", block)
    return [ln.split("#", 1)[0].strip() for ln in text.splitlines() if ln.split("#", 1)[0].strip()]


def test_the_two_commands_make_and_activate_a_virtual_environment_first():
    block = _section(README, "## The two commands").split("```sh", 1)[1].split("```", 1)[0]
    lines = _commands(block)
    venv = next(i for i, ln in enumerate(lines) if "-m venv .venv" in ln)
    assert ". .venv/bin/activate" in lines[venv]
    assert all(i > venv for i, ln in enumerate(lines) if "pip install" in ln), lines


def test_the_virtual_environment_is_ignored_by_git():
    ignored = [ln.strip() for ln in (ROOT / ".gitignore").read_text(encoding="utf-8").splitlines()]
    assert ".venv/" in ignored or "/.venv/" in ignored


def test_the_worked_example_writes_outside_the_repository():
    """Every file the worked example writes (cp targets, every --out) lies in ../my-press-work, after its cd."""
    block = _section(README, "## Your own press and drive log").split("```sh", 1)[1].split("```", 1)[0]
    cwd = ROOT  # the block is run from the repository's root
    written = []
    for line in _commands(block):
        words = shlex.split(line)
        if words[:1] == ["cd"]:
            cwd = (cwd / words[1]).resolve()
        elif words[:1] == ["mkdir"]:
            written.append(cwd / words[-1])
        elif words[:1] == ["cp"]:
            written.append(cwd / words[-1])
        elif words[:1] == ["servo-press"] and "--out" in words:
            written.append(cwd / words[words.index("--out") + 1])
    assert len(written) >= 10, written
    for path in written:
        assert ROOT not in path.resolve().parents and path.resolve() != ROOT, f"{path} lies inside the repository"


def _written_paths(block: str) -> list[Path]:
    """Every path a README code block's servo-press lines write (``--out``; an experiment's truth file goes beside its
    log), resolved from the repository's root (following ``cd``)."""
    cwd, written = ROOT, []
    for line in _commands(block):
        words = shlex.split(line)
        if words[:1] == ["cd"]:
            cwd = (cwd / words[1]).resolve()
        elif words[:1] == ["servo-press"] and "--out" in words:
            written.append((cwd / words[words.index("--out") + 1]).resolve())
    return written


def test_every_readme_command_run_from_the_root_writes_where_git_ignores_it():
    """Run from the repository's root as documented, the commands of the READMEs and of docs/ leave nothing beside the
    project's files: every --out lies under out/ (which .gitignore ignores) or outside the repository."""
    ignored = [ln.strip() for ln in (ROOT / ".gitignore").read_text(encoding="utf-8").splitlines()]
    assert "/out/" in ignored or "out/" in ignored
    found = 0
    for readme in sorted(ROOT.glob("*/README.md")) + [ROOT / "README.md"] + sorted(ROOT.glob("docs/*.md")):
        text = readme.read_text(encoding="utf-8")
        for block in re.findall(r"```(?:sh|bash)\n(.*?)```", text, re.S):
            for path in _written_paths(block):
                found += 1
                inside = path == ROOT or ROOT in path.parents
                assert not inside or (ROOT / "out") in path.parents, f"{readme.relative_to(ROOT)}: --out {path} is in the repository, not under out/"
    assert found >= 15, found


def test_against_the_paper_names_the_key_set_of_its_own_table():
    """The paragraph's key set for the cushion test is the table's first row, and its S_T figures round to that row's."""
    section = _section(CAL_README, "### Against the paper")
    row = next(ln for ln in CAL_README.splitlines() if ln.startswith("| cushion test"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    table_set = [p.strip() for p in cells[1].split(",")]
    said = re.search(r"our screening selects `(\w+)`, `(\w+)` and `(\w+)`", section)
    assert said and list(said.groups()) == table_set, (said and said.groups(), table_set)
    header = [c.strip() for c in next(ln for ln in CAL_README.splitlines() if ln.startswith("| load case")).strip("|").split("|")]
    st = re.search(r"S_T on Y_RMSE ([\d.]+), ([\d.]+) and ([\d.]+), on Y_PR ([\d.]+), ([\d.]+) and\s+([\d.]+)", section)
    assert st, section[:400]
    for k, name in enumerate(table_set):
        rmse, pr = (float(v) for v in cells[header.index(name)].split(" / "))
        assert abs(float(st.group(1 + k)) - rmse) <= 0.005 + 1e-12, name  # the table rounds to two decimals
        assert abs(float(st.group(4 + k)) - pr) <= 0.005 + 1e-12, name


def test_the_article_is_cited_by_title_and_venue_not_by_a_folder_outside_the_repository():
    """A reader of the repository alone has no copy of the article beside it: the READMEs and docstrings cite the article."""
    needle = "shared/" + "paper"  # split: this file must not match itself
    hits = [str(p.relative_to(ROOT)) for p in sorted(ROOT.rglob("*")) if p.suffix in (".md", ".py", ".toml") and p.is_file()
            and ".venv" not in p.parts and needle in p.read_text(encoding="utf-8", errors="replace")]
    assert hits == []
    citing = " ".join(_section(README, "### Citing").split())
    assert "Dynamics Parameter Calibration for Performance Enhancement of Heavy-Duty Servo Press" in citing
    assert "Applied Sciences" in citing and "847" in citing
