#!/usr/bin/env python
"""Benchmark: every figure of a `servo-press reproduce` run, measured where it is drawn.

Runs `servo-press reproduce ARGS` in this process with press_model.plots' saving wrapped (before any command module
imports it, so the forked figure workers and the second process inherit the wrapping) and prints one row per PNG:
the CPU seconds of its save (drawing, cropping, encoding, writing), how many times it was drawn (2: the tight-box
fallback), its PNG encoding's CPU seconds, its file size, and its visible text objects and artists (counted after the
draw, which makes the ticks). The rows are
collected through a JSON-lines file (each process appends its own).

Usage: python scripts/bench_figures_reproduce.py [--rows FILE] -- --quick --out DIR
With PYTHONPATH set to another checkout it measures that checkout's code.
"""
import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path


def instrument(rows: Path) -> None:
    """Wrap press_model.plots.save, its drawing (_draw) and its file writing (atomic_write) to append one JSON row per
    saved figure to ``rows``."""
    import press_model.plots as plots

    save, draw, write = plots.save, plots._draw, plots.atomic_write
    counts = {}

    def counted_draw(*a, **kw):
        counts["draws"] = counts.get("draws", 0) + 1
        return draw(*a, **kw)

    def timed_write(path, fn, **kw):
        t0 = time.process_time()
        out = write(path, fn, **kw)
        counts["encode_s"] = time.process_time() - t0
        return out

    def timed_save(fig, path):
        from matplotlib.text import Text

        counts.clear()
        t0 = time.process_time()
        save(fig, path)
        seconds = time.process_time() - t0
        texts = sum(1 for t in fig.findobj(Text) if t.get_visible() and t.get_text())  # tick labels made in the draw
        artists = len(fig.findobj())
        row = {"png": str(path), "save_s": seconds, "draws": counts.get("draws", 0),
               "encode_s": counts.get("encode_s", 0.0), "bytes": Path(path).stat().st_size if Path(path).exists() else 0,
               "texts": texts, "artists": artists, "pid": os.getpid()}
        with rows.open("a", encoding="utf-8") as f:
            f.write(json.dumps(row) + "\n")

    plots.save, plots._draw, plots.atomic_write = timed_save, counted_draw, timed_write


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rows", type=Path, default=None, help="the JSON-lines file of the rows (default: a new temp file)")
    ap.add_argument("argv", nargs=argparse.REMAINDER, help="reproduce's arguments, after --")
    args = ap.parse_args()
    rows = args.rows or Path(tempfile.mkstemp(prefix="bench_figures_", suffix=".jsonl")[1])
    rows.write_text("", encoding="utf-8")
    instrument(rows)
    from servo_press.cli import main as servo_press

    argv = [a for a in args.argv if a != "--"]
    t0 = time.process_time()
    code = servo_press(["reproduce", *argv])
    main_cpu = time.process_time() - t0
    table = [json.loads(line) for line in rows.read_text(encoding="utf-8").splitlines() if line]
    print(f"{'figure':44s} {'save s':>7s} {'draws':>5s} {'encode s':>8s} {'kB':>6s} {'texts':>5s} {'artists':>7s}")
    for r in sorted(table, key=lambda r: r["png"]):
        name = "/".join(Path(r["png"]).parts[-2:])  # its folder and name (written in a staging folder)
        print(f"{name[-44:]:44s} {r['save_s']:7.3f} {r['draws']:5d} {r['encode_s']:8.3f} {r['bytes'] / 1e3:6.1f} "
              f"{r['texts']:5d} {r['artists']:7d}")
    print(f"{len(table)} figures: save {sum(r['save_s'] for r in table):.2f} s CPU, encode {sum(r['encode_s'] for r in table):.2f} s, "
          f"{sum(r['draws'] for r in table)} draws, {sum(r['bytes'] for r in table) / 1e6:.2f} MB; "
          f"this process's CPU {main_cpu:.1f} s; rows in {rows}")
    sys.exit(code)


if __name__ == "__main__":
    main()
