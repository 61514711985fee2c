"""The defaults table of press_model/README.md ("Defaults"), made from the settings dataclasses themselves.

    python scripts/settings_table.py           # print the table
    python scripts/settings_table.py --write   # put it into press_model/README.md between its two markers

tests/test_settings_defaults.py checks that the README's table is this one.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.design.runs import DesignSection  # noqa: E402
from calibration.identification.settings import SECTIONS as CALIBRATION_SECTIONS  # noqa: E402
from calibration.synthetic.experiment import ExperimentSection  # noqa: E402
from planning.cams import CamSettings  # noqa: E402
from planning.settings import SECTIONS as PLANNING_SECTIONS, PlaybackSection  # noqa: E402
from press_model.press_settings import SECTIONS as PRESS_SECTIONS  # noqa: E402
from press_model.settings_fields import defaults_rows  # noqa: E402

README = ROOT / "press_model" / "README.md"
BEGIN = "<!-- defaults table: written by `python scripts/settings_table.py --write` from the settings dataclasses -->"
END = "<!-- end of the defaults table -->"

# every settings section with defaults, by file kind: path -> settings dataclass
JOB_SECTIONS = {**PLANNING_SECTIONS, ("planning", "cam"): CamSettings, ("experiment",): ExperimentSection,
                **CALIBRATION_SECTIONS, ("design",): DesignSection, ("design", "playback"): PlaybackSection}
FILES = {"press file": PRESS_SECTIONS, "job file": JOB_SECTIONS}


def table() -> str:
    """The markdown table: file, key, default, unit and reason of every setting with a default."""
    lines = ["| file | key | default | unit | why |", "|---|---|---|---|---|"]
    for kind, sections in FILES.items():
        for key, default, unit, reason in defaults_rows(sections):
            lines.append(f"| {kind} | `{key}` | `{default}` | {unit} | {reason.replace('|', chr(92) + '|')} |")
    return "\n".join(lines)


def with_table(text: str) -> str:
    """``text`` (the README) with the table between its markers replaced by today's."""
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{BEGIN}\n{table()}\n{END}{tail}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="write the table into press_model/README.md (default: print it)")
    args = ap.parse_args()
    if args.write:
        README.write_text(with_table(README.read_text(encoding="utf-8")), encoding="utf-8")
    else:
        print(table())
    return 0


if __name__ == "__main__":
    sys.exit(main())
