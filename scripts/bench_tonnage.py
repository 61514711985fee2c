#!/usr/bin/env python
"""Benchmark: the tonnage monitor at production scale (`servo-press strokes`, monitoring/).

Prints, per CPU target (scripts/cpu_targets.py: AVX2 and this machine's own CPU by default, each in its own process):
1. records on one core: one SYNTHETIC log of --strokes strokes (seed 5, the reference press's cushion test) read,
   its virtual tonnage, its stroke records and their Parquet file, per stroke, against the press's own rate (a stroke
   every 4.4 s; target: at least 10 times faster);
   then a simulated year of one press: those records repeated a stroke every 4.4 s around the clock, written a day's
   file at a time, read back by DuckDB and the README's two queries;
2. a month on 2 cores: `servo-press strokes --workers 2` over --logs / 3 and --logs copies of that log (each with its own
   first line, so each is a log of its own in the store): the warm throughput from the difference of the two runs (the
   cluster's start and each worker's imports cancel), and the minutes a month of 200,000 strokes takes at it;
3. DuckDB over a SYNTHETIC year of ten presses (--rows records, random values, partitioned press/day as the command
   writes them): the store's database built from the files by the first query, then the README's two queries,
   each a whole `monitoring.store.query` call, median of five (target: under a second);
4. the CUSUM's false alarms on --production clean SYNTHETIC strokes (batch-model curves plus the log's noise) against
   the stated in-control run length, and its delay after a 3 % step and along a ramp of eta_gear.
The calibration is made once on the experiment's seed-0 log. Every log, store and figure is written under a temporary
folder and removed.
Usage: python scripts/bench_tonnage.py [--cpu avx2,host] [--strokes 100] [--logs 8] [--rows 20000000] [--production 1000000]
       [--only duckdb]
"""
import argparse
import contextlib
import io
import json
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import cpu_targets


def _cli(*argv):
    from servo_press.cli import main

    with contextlib.redirect_stdout(io.StringIO()) as out:
        code = main([str(a) for a in argv])
    if code != 0:
        raise SystemExit(f"servo-press {' '.join(map(str, argv))} failed ({code}): {out.getvalue()}")
    return out.getvalue()


def _long_log(tmp: Path, strokes: int) -> Path:
    job = tmp / "job.toml"
    text = Path(__file__).resolve().parents[1].joinpath("press_model/data/cushion_test.toml").read_text(encoding="utf-8")
    job.write_text(text.replace("[experiment]\n", f"[experiment]\nstrokes = {strokes}\n", 1), encoding="utf-8")
    log = tmp / "long.csv"
    _cli("experiment", "--job", job, "--seed", 5, "--out", log)
    return log


def records_on_one_core(cal: dict, log_path: Path, store: Path) -> tuple[float, int, list[dict]]:
    from monitoring.run import StrokeTask, _load, log_strokes
    from monitoring.store import write_records

    task = StrokeTask(log_path, None, "cushion-test", str(store.parent / "cal" / "calibrated.json"), None, "bench", True)
    loaded = _load(task)
    log_strokes(task, loaded)  # compiles and fills the caches: a production run pays this once
    t0 = time.perf_counter()
    res = log_strokes(task, loaded)
    n = write_records(res["records"], store, "one")
    return time.perf_counter() - t0, n, res["records"]


def year_of_one_press(records: list[dict], tmp: Path) -> dict:
    """A simulated year of one press through the store as `strokes` writes it: the log's stroke records (simulated
    strokes of the model) repeated a stroke every 4.4 s around the clock, a day's file at a time, then read back by the
    README's queries."""
    import pyarrow as pa

    from monitoring.store import QUERIES, SCHEMA, query, records_table, write_table

    one = records_table(records)
    per_day = int(86400 / 4.4)
    store = tmp / "one-press-year"
    start = np.datetime64("2026-01-01T00:00:00", "us")
    t0 = time.perf_counter()
    for d in range(365):
        k = d * per_day + np.arange(per_day)
        t = start + (k * 4_400_000).astype("timedelta64[us]")
        day = one.take(pa.array(k % one.num_rows))
        for name, values in (("stroke_index", pa.array(k)), ("tdc_time", pa.array(t, type=SCHEMA.field("tdc_time").type)),
                             ("day", pa.array(np.datetime_as_string(t, unit="D"))), ("press", pa.array(["P1"] * per_day))):
            day = day.set_column(day.schema.get_field_index(name), SCHEMA.field(name), values)
        write_table(day, store, f"day{d:03d}")
    out = {"strokes": 365 * per_day, "write_s": time.perf_counter() - t0}
    t0 = time.perf_counter()
    out["read_back"] = query(store, "SELECT count(*) FROM strokes")[0][0]
    out["database_s"] = time.perf_counter() - t0
    shifts = query(store, QUERIES["peak force per shift"])
    out["shifts"], out["shift_strokes"] = len(shifts), sum(r[2] for r in shifts)
    out["over_110"] = len(query(store, QUERIES["strokes over 110 %"]))
    return out


def duckdb_year(tmp: Path, rows: int) -> dict:
    import pyarrow as pa
    import pyarrow.dataset as ds

    from monitoring.store import QUERIES, SCHEMA, query

    rng = np.random.default_rng(0)
    presses, days = 10, 365
    per = rows // (presses * days)
    t0 = time.perf_counter()
    store = tmp / "year"
    for p in range(presses):
        n = per * days
        day = np.repeat(np.arange(days), per)
        stamp = np.datetime64("2026-01-01T00:00:00") + (day * 86400 + np.sort(rng.integers(0, 86400, n))).astype("timedelta64[s]")
        peak = rng.normal(5.0e6, 0.1e6, n)
        table = pa.table({"press": np.full(n, f"P{p}"), "day": np.datetime_as_string(stamp, unit="D"),
                          "tdc_time": pa.array(stamp.astype("datetime64[us]"), type=SCHEMA.field("tdc_time").type),
                          "stroke_index": np.arange(n), "peak_force_N": peak, "overload": peak > 5.5e6})
        ds.write_dataset(table, str(store), format="parquet", partitioning=["press", "day"], partitioning_flavor="hive",
                         basename_template=f"p{p}-{{i}}.parquet", existing_data_behavior="overwrite_or_ignore",
                         max_partitions=days + 1)
    written = time.perf_counter() - t0
    t0 = time.perf_counter()
    files = query(store, "SELECT count(DISTINCT file) FROM strokes")[0][0]  # the first query builds the store's database
    out = {"rows": per * days * presses, "files": files, "write_s": written, "database_s": time.perf_counter() - t0}
    for name, sql in QUERIES.items():  # each a whole query() as a user calls it: open, check 3,650 files, run, close
        times = []
        for _ in range(5):
            t = time.perf_counter()
            query(store, sql)
            times.append(time.perf_counter() - t)
        out[name] = statistics.median(times)
    return out


def production(cal: dict, log_path: Path, strokes: int, stated: float) -> dict:
    from calibration.identification.settings import CalibrationSettings
    from calibration.identification.speed_fit import speed_harmonics
    from calibration.traces.drive_log import read_drive_log
    from monitoring.drift import Cusum
    from monitoring.production import eta_curves, production_ratios
    from monitoring.rules import load_rules
    from monitoring.strokes import log_tonnage, motoring_points
    from press_model.batch import build_batch_model
    from press_model.jobs import load_job
    from press_model.model import PressModel
    from press_model.motion import FourierSpeed
    from press_model.press_data import load_press

    press, job, rules = load_press(None), load_job("cushion-test"), load_rules()
    pm = PressModel(press)
    log = read_drive_log(log_path, press.drive.gear_ratio, press.motor.rated_torque)
    lt = log_tonnage(press, job, cal["parameters"], {k: tuple(v) for k, v in cal["joint_region"]["box"].items()}, log, rules, pm=pm)
    truth = json.loads(log_path.with_suffix(".truth.json").read_text(encoding="utf-8"))["all_parameters_true"]
    motion = FourierSpeed.fit(log.theta, log.crank_speed, speed_harmonics(log, CalibrationSettings.from_job(job)))
    bm = build_batch_model(press, motion, job.process, pm=pm)
    eta0 = truth["eta_gear"]
    etas = np.linspace(0.90, 1.0, 21) * eta0
    model, motoring = motoring_points(lt)
    curves = eta_curves(bm, truth, etas)
    d = rules.drift
    t0 = time.perf_counter()
    clean = production_ratios(curves, etas, np.full(strokes + d.baseline_strokes, eta0), model, motoring, lt.est.noise_Nm, seed=21)
    made = time.perf_counter() - t0
    chart = Cusum.from_baseline(clean[:d.baseline_strokes], stated, d.reference_sd)
    t0 = time.perf_counter()
    alarms = chart.run(clean[d.baseline_strokes:])
    charted = time.perf_counter() - t0
    step = production_ratios(curves, etas, np.full(20_000, 0.97 * eta0), model, motoring, lt.est.noise_Nm, seed=22)
    delays = []
    for rep in range(1000):
        a = chart.run(step[rep * 20:rep * 20 + 2000])
        delays.append(a[0] + 1 if a.size else np.inf)
    shift = (np.mean(step) - chart.mean) / chart.sd
    ramp_len = 200_000  # eta_gear falls 5 % over a month of strokes
    ramp_eta = eta0 * (1.0 - 0.05 * np.arange(ramp_len) / ramp_len)
    ramp = production_ratios(curves, etas, ramp_eta, model, motoring, lt.est.noise_Nm, seed=23)
    first = chart.run(ramp)
    return {"strokes": strokes, "made_s": made, "chart_s": charted, "false_alarms": int(alarms.size),
            "stated_rate": 1.0 / stated, "measured_rate": alarms.size / strokes, "limit_sd": chart.h,
            "step_shift_sd": shift, "step_delay_mean": float(np.mean(delays)), "step_delay_stated": chart.detection_delay(shift),
            "ramp_first_alarm_stroke": int(first[0]) if first.size else None,
            "ramp_eta_loss_at_alarm": float(0.05 * first[0] / ramp_len) if first.size else None}


def _print_year(y: dict, queries: dict) -> None:
    print(f"DuckDB over a SYNTHETIC year of ten presses, {y['rows']:,} records in {y['files']:,} Parquet files (written "
          f"in {y['write_s']:.0f} s, the store's database built from them by the first query in {y['database_s']:.1f} s): "
          + "; ".join(f"'{k}' {y[k]:.3f} s" for k in queries) + " (median of 5 whole queries)", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    cpu_targets.add_cpu_argument(ap)
    ap.add_argument("--strokes", type=int, default=100, help="strokes of the SYNTHETIC production log")
    ap.add_argument("--logs", type=int, default=48, help="copies of it the larger 2-core run reads (the smaller: a third)")
    ap.add_argument("--rows", type=int, default=20_000_000, help="records of the SYNTHETIC year of ten presses")
    ap.add_argument("--production", type=int, default=1_000_000, help="clean SYNTHETIC strokes for the false-alarm rate")
    ap.add_argument("--only", choices=("duckdb",), default=None, help="run only this part (the DuckDB year: no calibration)")
    args = ap.parse_args()
    if cpu_targets.current() is None:
        return cpu_targets.run_per_target(args.cpu)
    from monitoring.rules import load_rules
    from monitoring.store import QUERIES

    stated = load_rules().drift.in_control_strokes
    tmp = Path(tempfile.mkdtemp(prefix="bench-tonnage-"))
    try:
        if args.only == "duckdb":
            _print_year(duckdb_year(tmp, args.rows), QUERIES)
            return 0
        seed0 = tmp / "seed0.csv"
        _cli("experiment", "--seed", 0, "--out", seed0)
        _cli("calibrate", "--log", seed0, "--out", tmp / "cal")
        cal = json.loads((tmp / "cal" / "calibrated.json").read_text(encoding="utf-8"))
        log = _long_log(tmp, args.strokes)
        seconds, n, records = records_on_one_core(cal, log, tmp / "one")
        print(f"records on one core: {n} strokes in {seconds:.2f} s, {seconds / n * 1e3:.1f} ms a stroke: "
              f"{4.4 / (seconds / n):.0f} times the press's rate (one stroke every 4.4 s)", flush=True)
        # two runs, of half the logs and of all: their difference is the throughput once the workers are warm (the
        # cluster's start, each worker's imports and models, paid once a run, cancel)
        y1 = year_of_one_press(records, tmp)
        print(f"a simulated year of one press ({y1['strokes']:,} strokes, the log's records a stroke every 4.4 s): written in "
              f"{y1['write_s']:.0f} s, read back by DuckDB {y1['read_back']:,} ({y1['database_s']:.0f} s to build the store's "
              f"database); 'peak force per shift': {y1['shifts']:,} shifts of {y1['shift_strokes']:,} strokes; 'strokes "
              f"over 110 %': {y1['over_110']}", flush=True)
        text = log.read_text(encoding="utf-8")
        walls = {}
        for count in (args.logs // 3, args.logs):
            logs = tmp / f"logs{count}"
            logs.mkdir()
            for i in range(count):
                (logs / f"copy{i:03d}.csv").write_text(f"# copy {i} of the SYNTHETIC production log\n" + text, encoding="utf-8")
            t0 = time.perf_counter()
            _cli("strokes", "--logs", logs, "--params", tmp / "cal" / "calibrated.json", "--press-id", "bench", "--workers", 2,
                 "--out", tmp / f"store{count}")
            walls[count] = time.perf_counter() - t0
        half, full = args.logs // 3, args.logs
        rate = (full - half) * n / (walls[full] - walls[half])
        print(f"2 workers: {half * n} strokes of {half} logs in {walls[half]:.1f} s, {full * n} of {full} in {walls[full]:.1f} s "
              f"(cluster start included); warm, {rate:.0f} strokes/s: a month of 200,000 strokes in "
              f"{200_000 / rate / 60 + walls[half] / 60:.1f} min", flush=True)
        _print_year(duckdb_year(tmp, args.rows), QUERIES)
        p = production(cal, seed0, args.production, stated)
        print(f"CUSUM on {p['strokes']:,} clean SYNTHETIC strokes (made in {p['made_s']:.1f} s, charted in {p['chart_s'] * 1e3:.0f} ms): "
              f"{p['false_alarms']} false alarms, {p['measured_rate'] * 1e5:.2f} per 100,000 strokes against the stated "
              f"{p['stated_rate'] * 1e5:.2f} (limit {p['limit_sd']:.3f} sd)", flush=True)
        print(f"a 3 % step in eta_gear ({p['step_shift_sd']:.2f} sd): alarm after {p['step_delay_mean']:.2f} strokes on average "
              f"(1,000 repeats; stated {p['step_delay_stated']:.2f}); a ramp of -5 % over 200,000 strokes: first alarm at stroke "
              f"{p['ramp_first_alarm_stroke']} (eta_gear down {100 * (p['ramp_eta_loss_at_alarm'] or 0):.3f} %)", flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
