"""Write every version of the shipped job and press files in this repository's git history to
tests/data/history/<file stem>/<short hash>.toml, for tests/test_settings_history.py.

    python scripts/history_files.py            # from the repository's root; needs git

Renames are followed (``git log --follow``). The folder is written anew; nothing else is touched.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "press_model" / "data"
OUT = ROOT / "tests" / "data" / "history"


def git(*args: str) -> str:
    """The stdout of a git command run in the repository's root."""
    return subprocess.run(["git", *args], cwd=ROOT, check=True, capture_output=True, text=True).stdout


def shipped() -> list[Path]:
    """The shipped job files (a [job] table) and press files (a [press] table)."""
    out = []
    for path in sorted(DATA.glob("*.toml")):
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
        if "bodies" in raw or (isinstance(raw.get("job"), dict) and "name" in raw["job"]):  # not run_limits.toml's [press]
            out.append(path)
    return out


def versions(path: Path) -> list[tuple[str, str]]:
    """(short hash, path at that commit) of every commit that changed ``path``, renames followed."""
    rel = path.relative_to(ROOT).as_posix()
    lines = git("log", "--follow", "--format=%h", "--name-only", "--", rel).split("\n")
    out, commit = [], None
    for line in lines:
        if not line.strip():
            continue
        if commit is None:
            commit = line.strip()
        else:
            out.append((commit, line.strip()))
            commit = None
    return out


def main() -> int:
    if OUT.exists():
        shutil.rmtree(OUT)
    total = 0
    for path in shipped():
        folder = OUT / path.stem
        folder.mkdir(parents=True)
        for commit, old in versions(path):
            text = git("show", f"{commit}:{old}")
            (folder / f"{commit}.toml").write_text(text, encoding="utf-8")
            total += 1
        print(f"{path.name}: {len(list(folder.iterdir()))} versions")
    print(f"{total} files in {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
