"""The stroke store's DuckDB database against its Parquet files (monitoring/store.py): the database is derived from the
files and must answer as the files do after every change a user or a run makes to them. Records here are made up
(plain values of the declared columns), not the physics: what is checked is the bookkeeping."""
from __future__ import annotations

import os
from datetime import datetime, timedelta, timezone

import duckdb
import pytest

from monitoring.store import DATABASE, QUERIES, query, write_records
from monitoring.strokes import COLUMNS, SCHEMA_VERSION
from press_io.errors import PressDataError

_PARQUET = "FROM read_parquet('{store}/**/*.parquet', hive_partitioning = true, hive_types_autocast = false)"


def _records(press: str, start: datetime, n: int, peak: float = 5.0e6) -> list[dict]:
    out = []
    for i in range(n):
        t = start + timedelta(seconds=4.4 * i)
        blank = {"int": 0, "float": 0.0, "bool": False, "str": "x", "floats": [0.5, 0.5]}
        r = {k: blank[kind] for k, kind in COLUMNS.items() if kind != "time"}
        r.update(schema_version=SCHEMA_VERSION, press=press, day=t.date().isoformat(), stroke_index=i, tdc_time=t,
                 peak_force_N=peak + 1.0e3 * i, overload=i % 7 == 0)
        out.append(r)
    return out


def _both(store, what: str) -> tuple[list, list]:
    """Rows of ``SELECT what`` from the database and from the Parquet files themselves, in one order."""
    db = query(store, f"SELECT {what} FROM strokes ORDER BY ALL")
    files = query(store, f"SELECT {what} {_PARQUET} ORDER BY ALL")
    return db, files


def test_the_database_answers_as_the_parquet_files_through_every_change(tmp_path):
    midnight = datetime(2026, 3, 1, 23, 0, tzinfo=timezone.utc)  # a log that runs past midnight: two day partitions
    assert write_records(_records("P1", midnight, 2000), tmp_path, "a") == 2000
    write_records(_records("P2", midnight, 50), tmp_path, "b")
    cols = "press, day, stroke_index, tdc_time, peak_force_N, overload"
    db, files = _both(tmp_path, cols)
    assert len(db) == 2050 and db == files
    assert (tmp_path / DATABASE).is_file()

    # a log written again (other values): its own rows replaced, no stroke twice
    write_records(_records("P1", midnight, 2000, peak=6.0e6), tmp_path, "a")
    db, files = _both(tmp_path, cols)
    assert db == files and len(db) == 2050 and max(r[4] for r in db) > 6.0e6
    # a partition file deleted by hand: its rows leave the database too
    victim = next(tmp_path.glob("press=P2/day=*/*.parquet"))
    victim.unlink()
    db, files = _both(tmp_path, cols)
    assert db == files and len(db) == 2000
    # the database deleted: the next query builds it again from the files
    (tmp_path / DATABASE).unlink()
    assert _both(tmp_path, cols)[0] == files


def test_a_database_of_another_schema_version_is_rebuilt(tmp_path):
    write_records(_records("P1", datetime(2026, 3, 2, tzinfo=timezone.utc), 30), tmp_path, "a")
    assert query(tmp_path, "SELECT count(*) FROM strokes") == [(30,)]
    with duckdb.connect(str(tmp_path / DATABASE)) as con:  # as an older release would have left it
        con.execute("UPDATE about SET schema_version = ?", [SCHEMA_VERSION - 1])
        con.execute("DELETE FROM strokes WHERE stroke_index < 10")
    assert query(tmp_path, "SELECT count(*) FROM strokes") == [(30,)]


def test_the_readme_queries_agree_with_their_plain_sql(tmp_path):
    # shift_start against DuckDB's own time_bucket on the files, for shifts from midnight and from 06:00
    start = datetime(2026, 3, 1, 21, 30, tzinfo=timezone.utc)
    write_records(_records("P1", start, 3000), tmp_path, "a")
    ours = query(tmp_path, QUERIES["peak force per shift"])
    plain = query(tmp_path, "SET TimeZone = 'UTC'; SELECT press, time_bucket(INTERVAL 8 HOUR, tdc_time) AS shift, count(*), "
                            f"max(peak_force_N), avg(peak_force_N) {_PARQUET} GROUP BY ALL ORDER BY press, shift")
    assert [r[:4] for r in ours] == [r[:4] for r in plain] and len(ours) >= 2
    six = query(tmp_path, "SELECT shift_start(tdc_time, first_hour := 6) AS s, count(*) FROM strokes GROUP BY ALL ORDER BY s")
    plain6 = query(tmp_path, "SET TimeZone = 'UTC'; SELECT time_bucket(INTERVAL 8 HOUR, tdc_time, INTERVAL 6 HOUR) AS s, "
                             f"count(*) {_PARQUET} GROUP BY ALL ORDER BY s")
    assert six == plain6
    # a stroke whose peak was not seen (NaN in its record) is NULL in the store: the shift's max is the strokes' that were
    recs = _records("P3", start + timedelta(days=10), 20)  # after P1's strokes: the overload list stays in P1, P3 order
    recs[3]["peak_force_N"] = float("nan")
    write_records(recs, tmp_path, "c")
    p3 = [r for r in query(tmp_path, QUERIES["peak force per shift"]) if r[0] == "P3"]
    assert sum(r[2] for r in p3) == 20 and max(r[3] for r in p3) == max(r["peak_force_N"] for r in recs if r["peak_force_N"] == r["peak_force_N"])
    assert query(tmp_path, "SELECT peak_force_N FROM strokes WHERE press = 'P3' AND stroke_index = 3") == [(None,)]
    over = query(tmp_path, QUERIES["strokes over 110 %"])
    assert [r[2] for r in over] == [i for i in range(3000) if i % 7 == 0] + [i for i in range(20) if i % 7 == 0]


def test_a_folder_that_is_not_a_store_is_refused_and_left_alone(tmp_path):
    (tmp_path / "notes.txt").write_text("mine", encoding="utf-8")
    with pytest.raises(PressDataError, match="not a stroke store"):
        query(tmp_path, "SELECT 1")
    assert os.listdir(tmp_path) == ["notes.txt"]
