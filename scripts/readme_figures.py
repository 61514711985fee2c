"""The figures docs/validation.md quotes for the front page's worked example, measured by running the example's
commands as README.md documents them.

README.md's "Your own press and drive log" block is read and run in a folder outside the repository: its ``cp`` lines,
then the steps whose results the record quotes (2: ``sensitivity``, 3: ``experiment`` and ``calibrate``), and the
calibration the record names "without --parameters" (the same ``calibrate`` line without it). Steps 1 and 4 (URDF,
simulate, plan, compare) feed none of the quoted figures and are not run.

The record's figures ("The worked example, run as written" in docs/validation.md) are marked there as
``<!-- figure:NAME -->value<!-- /figure -->``; this script prints each measured figure beside the record's,
``--update`` writes the measured ones into docs/validation.md and ``--check`` exits 1 when any differs
(tests/test_readme_figures.py runs the check). Usage, from the repository's root:

    python scripts/readme_figures.py [--check | --update] [--work DIR]
"""
from __future__ import annotations

import argparse
import json
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"  # the worked example's commands
FIGURES = ROOT / "docs" / "validation.md"  # the figures they give, marked
SECTION = "## Your own press and drive log"
MARK = re.compile(r"<!-- figure:(\w+) -->(.*?)<!-- /figure -->", re.S)
STEPS = ("sensitivity", "experiment", "calibrate")  # the commands whose results the record quotes


def example_commands(readme: str) -> list[list[str]]:
    """The worked example's shell lines as words (comments dropped, continuation lines joined)."""
    start = readme.index(SECTION)
    block = readme[start:].split("```sh", 1)[1].split("```", 1)[0]
    text = re.sub(r"\\\n\s*", " ", block)
    return [shlex.split(ln.split("#", 1)[0]) for ln in text.splitlines() if ln.split("#", 1)[0].strip()]


def servo_press(cwd: Path, argv: list[str]) -> None:
    """Run one servo-press command in ``cwd`` with this repository's code; raises with its stderr if it fails."""
    exe = [sys.executable, "-m", "servo_press.cli"]
    env = {**__import__("os").environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([*exe, *argv], cwd=cwd, capture_output=True, text=True, env=env)
    if r.returncode != 0:
        raise RuntimeError(f"servo-press {' '.join(argv)} (in {cwd}) exited {r.returncode}: {r.stderr.strip()}")


def run_example(work: Path) -> tuple[Path, dict]:
    """Run the worked example's steps 2-3 as README.md writes them, from ``work`` standing for the repository's root's
    parent (the example's ``../my-press-work`` lands in ``work``); returns the example's folder and the calibrate
    lines' --out folders by role ("keys": as written, "all": without --parameters)."""
    root = work / "repo"  # the commands' `press_model/data/...` paths are the repository's own: linked in
    root.mkdir(parents=True, exist_ok=True)
    if not (root / "press_model").exists():
        (root / "press_model").symlink_to(ROOT / "press_model", target_is_directory=True)
    cwd, outs = root, {}
    for words in example_commands(README.read_text(encoding="utf-8")):
        if words[0] == "mkdir":
            (cwd / words[-1]).mkdir(parents=True, exist_ok=True)
        elif words[0] == "cp":
            shutil.copyfile(cwd / words[1], cwd / words[2])
        elif words[0] == "cd":
            cwd = (cwd / words[1]).resolve()
        elif words[0] == "servo-press" and words[1] in STEPS:
            servo_press(cwd, words[1:])
            if words[1] == "calibrate":
                outs["keys"] = cwd / words[words.index("--out") + 1]
                i = words.index("--parameters")
                all_six = words[1:i] + words[i + 2:]
                j = all_six.index("--out")
                all_six[j + 1] += "_all"
                servo_press(cwd, all_six)
                outs["all"] = cwd / all_six[j + 1]
                truth = cwd / (words[words.index("--log") + 1].removesuffix(".csv") + ".truth.json")
                outs["truth"] = truth
            if words[1] == "sensitivity":
                outs["keys_file"] = cwd / words[words.index("--out") + 1] / "key_parameters.json"
    return cwd, outs


def _kg(v: float) -> str:
    return f"{v:,.0f}"


def figures(outs: dict) -> dict[str, str]:
    """The quoted figures, as docs/validation.md writes them, from the run's files."""
    keys = json.loads(outs["keys_file"].read_text())["key_parameters"]
    cal = json.loads((outs["keys"] / "calibrated.json").read_text())
    full = json.loads((outs["all"] / "calibrated.json").read_text())
    truth = json.loads(outs["truth"].read_text())["truth"]
    lo, hi = cal["intervals"]["m8"]
    label = next(ln.split(":", 1)[0] for ln in cal["identifiability"][1:] if re.search(r"\bm8\b", ln))
    missed = [n for n, (a, b) in full["intervals"].items() if not a <= truth[n] <= b]
    forces = [c["process_force"] for c in (cal, full)]
    logged = [all(lg["source"].startswith("logged") for lg in f["logs"]) for f in forces]
    warned = sum(bool(f.get("warned")) for f in forces)
    return {
        "worked_key_set": ", ".join(keys),
        "worked_keys_verdict": "adequate" if cal["adequacy"]["adequate"] else "MODEL NOT ADEQUATE",
        "worked_m8": f"{_kg(cal['parameters']['m8'])} kg",
        "worked_m8_interval": f"{_kg(lo)}-{_kg(hi)} kg",
        "worked_m8_truth": f"{_kg(truth['m8'])} kg",
        "worked_m8_label": label,
        "worked_all_verdict": "adequate" if full["adequacy"]["adequate"] else "MODEL NOT ADEQUATE",
        "worked_all_F": f"F = {full['adequacy']['lack_of_fit_ratio']:.2f}",
        "worked_all_cover": "every 95 % interval holds its truth" if not missed else
                            f"the 95 % intervals of {', '.join(missed)} miss their truth",
        "worked_force_column": "carries the cushion's force as process_force_N" if all(logged) else
                               "has no process_force_N column" if not any(logged) else "carries process_force_N in one fit only",
        "worked_force_warnings": {0: "neither warns about the process force", 1: "one of them WARNs PROCESS FORCE NOT LOGGED",
                                  2: "both WARN PROCESS FORCE NOT LOGGED"}[warned],
    }


def marked(text: str) -> dict[str, str]:
    """A text's marked figures by name."""
    return {m.group(1): m.group(2) for m in MARK.finditer(text)}


def differences(text: str, measured: dict[str, str]) -> list[str]:
    """One line per figure ``text`` marks otherwise than measured, or marks not at all (or that nothing measures)."""
    have = marked(text)
    out = [f"{n}: recorded {have.get(n)!r}, run {v!r}" for n, v in measured.items() if have.get(n) != v]
    out += [f"{n}: recorded {v!r}, measured by nothing" for n, v in have.items() if n.startswith("worked_") and n not in measured]
    return out


def update(text: str, measured: dict[str, str]) -> str:
    """``text`` with every marked figure replaced by its measured value."""
    return MARK.sub(lambda m: f"<!-- figure:{m.group(1)} -->{measured.get(m.group(1), m.group(2))}<!-- /figure -->", text)


def measure(work: Path | None = None) -> dict[str, str]:
    """Run the example (in ``work``, default a temporary folder) and return its figures."""
    if work is not None:
        return figures(run_example(Path(work))[1])
    with tempfile.TemporaryDirectory(prefix="readme-figures-") as tmp:
        return figures(run_example(Path(tmp))[1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--check", action="store_true", help="exit 1 if docs/validation.md's marked figures differ from the run's")
    g.add_argument("--update", action="store_true", help="write the run's figures into docs/validation.md's marks")
    ap.add_argument("--work", default=None, help="folder to run the example in (default: a temporary one)")
    args = ap.parse_args(argv)
    measured = measure(args.work)
    text = FIGURES.read_text(encoding="utf-8")
    have = marked(text)
    for n, v in measured.items():
        print(f"{n}: {v}" + ("" if have.get(n) == v else f"   (recorded: {have.get(n)!r})"))
    diff = differences(text, measured)
    if args.update and diff:
        FIGURES.write_text(update(text, measured), encoding="utf-8")
        print(f"updated {len(diff)} figure(s) in {FIGURES}")
        return 0
    if args.check and diff:
        print("\n".join(["docs/validation.md's figures differ from the run:", *diff]), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
