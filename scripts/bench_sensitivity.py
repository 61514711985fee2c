#!/usr/bin/env python
"""Benchmark: the full Sobol run of Section 3 (N = 2048, 28 parameters: 61,440 model cycles, four responses).

Target: at most 10 s on the 2-core reference machine. Prints setup, evaluation, analysis and total time.
Usage: python scripts/bench_sensitivity.py [--n 2048] [--out DIR]
"""
import argparse
import tempfile
import time
from pathlib import Path

from press_model.model import PressModel
from press_model.press_data import load_press
from calibration.sensitivity_report import run_sensitivity


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=2048)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    t0 = time.perf_counter()
    pm = PressModel(load_press())
    t_model = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        rec = run_sensitivity(pm, args.n, 0, False, Path(args.out or tmp), progress=False)
    total = time.perf_counter() - t0
    t = rec["timing_s"]
    print(f"N = {args.n}: {rec['model_cycles']} model cycles")
    print(f"press model {t_model:.2f} s, batch setup {t['setup']:.2f} s, evaluation {t['evaluation']:.2f} s "
          f"({t['evaluation'] / rec['model_cycles'] * 1e3:.3f} ms per cycle), SALib analysis {t['analysis']:.2f} s")
    print(f"total {total:.2f} s (target <= 10 s); key parameters: {', '.join(rec['key_parameters'])}")


if __name__ == "__main__":
    main()
