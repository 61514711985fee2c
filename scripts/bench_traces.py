"""Seconds to read a long drive trace: a TwinCAT Scope CSV export (tab, decimal comma) and an NI TDMS file of the
same channels, against the plain drive-log CSV reader, on this machine.

    python scripts/bench_traces.py [--minutes 10] [--rate 1000]

The trace is SYNTHETIC (made here: a crank turning at 11.4 strokes/min, five channels: angle, speed, two torques
and an extra one), written once to a temporary folder. Reading means `calibration.traces.trace_formats.read_trace` (file to
channels) and `calibration.traces.drive_log.read_drive_log` for the CSV (file to columns, checks and grid included).
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from calibration.traces.drive_log import read_drive_log, write_drive_log  # noqa: E402
from calibration.traces.trace_formats import read_trace  # noqa: E402
from trace_writers import write_scope_csv, write_tdms  # noqa: E402


def timed(label: str, fn, rows: int) -> None:
    t0 = time.perf_counter()
    fn()
    dt = time.perf_counter() - t0
    print(f"{label:<44} {dt:7.2f} s  ({rows / dt / 1e3:7.0f} k rows/s)", flush=True)


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="length of the trace (default 10)")
    ap.add_argument("--rate", type=float, default=1000.0, help="samples per second (default 1000)")
    a = ap.parse_args()
    w0 = 2.0 * math.pi * 11.4 / 60.0
    t = np.arange(0.0, a.minutes * 60.0, 1.0 / a.rate)
    th = w0 * t + 0.4 * np.sin(w0 * t)
    rpm = w0 * (1.0 + 0.4 * np.cos(w0 * t)) * 32.0 * 60.0 / (2.0 * math.pi)
    q = 5000.0 + 3000.0 * np.sin(th)
    angle = np.degrees(np.mod(th, 2.0 * math.pi))
    chans = [dict(name="fCrankAngle", time_ms=t * 1e3, values=angle), dict(name="Drive1_ActVelo", time_ms=t * 1e3, values=rpm),
             dict(name="Drive1_ActTorque", time_ms=t * 1e3, values=q / 135.0), dict(name="Drive2_ActTorque", time_ms=t * 1e3, values=q / 135.0),
             dict(name="DcBusVoltage", time_ms=t * 1e3, values=600.0 + 0.0 * t)]
    print(f"SYNTHETIC trace: {t.size} rows ({a.minutes:g} min at {a.rate:g} Hz), 5 channels")
    with tempfile.TemporaryDirectory() as d:
        scope, tdms, csv = Path(d) / "scope.csv", Path(d) / "log.tdms", Path(d) / "log.csv"
        write_scope_csv(scope, "SYNTHETIC benchmark trace", chans, "\t", ",")
        write_tdms(tdms, "Drive", [dict(name=c["name"], values=c["values"], dt_s=1.0 / a.rate) for c in chans])
        write_drive_log(csv, t, angle, rpm, q, ["SYNTHETIC benchmark trace"])
        timed("TwinCAT Scope export (tab, decimal comma)", lambda: read_trace(scope), t.size)
        timed("NI TDMS (npTDMS)", lambda: read_trace(tdms), t.size)
        timed("plain drive-log CSV (read_drive_log, gridded)", lambda: read_drive_log(csv, 32.0, 13500.0), t.size)


if __name__ == "__main__":
    run()
