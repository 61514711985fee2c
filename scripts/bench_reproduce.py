#!/usr/bin/env python
"""Benchmark: `servo-press reproduce` end to end, full and --quick (targets: 60 s and 30 s on 2 cores).

Runs each mode as a fresh process into a temporary folder and prints the wall time of each step (from
the command's own progress lines) and in total.
Usage: python scripts/bench_reproduce.py [--mode full|quick|both]
"""
import argparse
import re
import subprocess
import sys
import tempfile
import time

TARGET_S = {"full": 60.0, "quick": 30.0}


def run(mode: str) -> float:
    out = tempfile.mkdtemp(prefix=f"bench_reproduce_{mode}_")
    cmd = ["servo-press", "reproduce", "--out", out] + (["--quick"] if mode == "quick" else [])
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        print(res.stderr, file=sys.stderr)
        raise SystemExit(f"{' '.join(cmd)} failed with exit code {res.returncode}")
    steps = re.findall(r"^\[reproduce\] (.+): ([\d.]+) s$", res.stdout, flags=re.M)
    print(f"{mode}: {wall:.1f} s wall (target {TARGET_S[mode]:.0f} s) -> {out}")
    for name, sec in steps:
        print(f"    {name:<45} {float(sec):6.1f} s")
    return wall


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", choices=("full", "quick", "both"), default="both")
    args = ap.parse_args()
    modes = ("quick", "full") if args.mode == "both" else (args.mode,)
    walls = {m: run(m) for m in modes}
    return 0 if all(walls[m] <= TARGET_S[m] for m in walls) else 1


if __name__ == "__main__":
    sys.exit(main())
