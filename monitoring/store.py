"""The per-stroke store: stroke records as Parquet files partitioned by press and day (hive style,
``STORE/press=P1/day=2026-11-29/<log>-0.parquet``), queried in place with DuckDB.

One file per log and partition, named by the log's content digest: a log written again replaces its own file and no
other, so a store is rebuilt from its logs and never holds a stroke twice. The schema version is a column of every
record and the file's metadata (``servo_press_twin.schema``).
"""
from __future__ import annotations

from pathlib import Path

import duckdb
import pyarrow as pa
import pyarrow.dataset as ds

from monitoring.strokes import COLUMNS, SCHEMA_VERSION

PARTITIONS = ("press", "day")

# the README's queries: {store} is the store's folder
QUERIES = {
    "peak force per shift": (  # 8-hour shifts from midnight UTC; time_bucket's third argument moves them (e.g. from 06:00)
        "SELECT press, time_bucket(INTERVAL 8 HOUR, tdc_time) AS shift, count(*) AS strokes, max(peak_force_N) AS peak_force_N, "
        "avg(peak_force_N) AS mean_peak_force_N FROM read_parquet('{store}/**/*.parquet', hive_partitioning = true) "
        "GROUP BY ALL ORDER BY press, shift"),
    "strokes over 110 %": (
        "SELECT press, day, stroke_index, tdc_time, peak_force_N FROM read_parquet('{store}/**/*.parquet', "
        "hive_partitioning = true) WHERE overload ORDER BY tdc_time"),
}


_TYPES = {"int": pa.int64(), "float": pa.float64(), "str": pa.string(), "bool": pa.bool_(), "time": pa.timestamp("us", tz="UTC"),
          "floats": pa.list_(pa.float64())}
SCHEMA = pa.schema([(name, _TYPES[kind]) for name, kind in COLUMNS.items()],
                   metadata={"servo_press_twin.schema": str(SCHEMA_VERSION)})


def write_records(records: list[dict], store: str | Path, name: str) -> int:
    """Write ``records`` (:func:`monitoring.strokes.log_records`) under ``store``, one file per press and day named
    ``name`` (the log's digest); returns how many were written."""
    if not records:
        return 0
    table = pa.Table.from_pylist(records, schema=SCHEMA)  # the declared types, also where a log has no clock (tdc_time null)
    ds.write_dataset(table, str(store), format="parquet", partitioning=list(PARTITIONS), partitioning_flavor="hive",
                     basename_template=f"{name}-{{i}}.parquet", existing_data_behavior="overwrite_or_ignore")
    return len(records)


def query(store: str | Path, sql: str) -> list[tuple]:
    """Rows of ``sql`` (``{store}`` stands for the store's folder) run by DuckDB over the store's Parquet files."""
    with duckdb.connect() as con:
        con.execute("SET enable_progress_bar = false")  # a query's result, not a terminal's bar, is what the caller prints
        return con.execute(sql.format(store=Path(store).as_posix())).fetchall()
