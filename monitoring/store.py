"""The per-stroke store: stroke records as Parquet files partitioned by press and day (hive style,
``STORE/press=P1/day=2026-11-29/<log>-0.parquet``), and a DuckDB database beside them (``STORE/strokes.duckdb``)
that the queries run on.

One Parquet file per log and partition, named by the log's content digest: a log written again replaces its own file
and no other, so a store is rebuilt from its logs and never holds a stroke twice. The schema version is a column of
every record and the file's metadata (``servo_press_twin.schema``).

The Parquet files are the store; the database is derived from them and kept in step before every query: a file new or
changed since (its size and modification time) is read into the ``strokes`` table and a file gone takes its rows
with it. A query over a year of ten presses then reads DuckDB's own columnar storage, not 3,650 Parquet footers
(docs/benchmarks.md, "Tonnage monitor"). Deleting the database loses nothing: the next query builds it again.
"""
from __future__ import annotations

from pathlib import Path

import duckdb
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as ds

from monitoring.strokes import COLUMNS, SCHEMA_VERSION
from press_io.errors import PressDataError

PARTITIONS = ("press", "day")
DATABASE = "strokes.duckdb"  # beside the partitions; derived from them
MARKER = "store.json"  # in the store's folder: what it is, its schema (written by `servo-press strokes`)

# the README's queries, on the database's `strokes` table; shift_start (a macro of the database) buckets a time into
# shifts of `hours` from `first_hour` UTC (shift_start(tdc_time, first_hour := 6) for shifts from 06:00): it works on
# the time's microseconds, three times cheaper than time_bucket's time-zone arithmetic over 20 M rows
QUERIES = {
    "peak force per shift": (
        "SELECT press, shift_start(tdc_time) AS shift, count(*) AS strokes, max(peak_force_N) AS peak_force_N, "
        "avg(peak_force_N) AS mean_peak_force_N FROM strokes GROUP BY ALL ORDER BY press, shift"),
    "strokes over 110 %": (
        "SELECT press, day, stroke_index, tdc_time, peak_force_N FROM strokes WHERE overload ORDER BY tdc_time"),
}

_TYPES = {"int": pa.int64(), "float": pa.float64(), "str": pa.string(), "bool": pa.bool_(), "time": pa.timestamp("us", tz="UTC"),
          "floats": pa.list_(pa.float64())}
_SQL_TYPES = {"int": "BIGINT", "float": "DOUBLE", "str": "VARCHAR", "bool": "BOOLEAN", "time": "TIMESTAMPTZ", "floats": "DOUBLE[]"}
SCHEMA = pa.schema([(name, _TYPES[kind]) for name, kind in COLUMNS.items()],
                   metadata={"servo_press_twin.schema": str(SCHEMA_VERSION)})

_US_PER_HOUR = 3_600_000_000
_TABLES = (
    f"CREATE TABLE strokes ({', '.join(f'{n} {_SQL_TYPES[k]}' for n, k in COLUMNS.items())}, file VARCHAR)",
    "CREATE TABLE parquet_files (file VARCHAR, size BIGINT, mtime_ns BIGINT)",
    "CREATE TABLE about (schema_version INTEGER, what VARCHAR)",
    f"CREATE MACRO shift_start(t, hours := 8, first_hour := 0) AS make_timestamptz(((epoch_us(t) - first_hour * "
    f"{_US_PER_HOUR}) // (hours * {_US_PER_HOUR})) * (hours * {_US_PER_HOUR}) + first_hour * {_US_PER_HOUR})",
)


def records_table(records: list[dict]) -> pa.Table:
    """The Arrow table of ``records`` (:func:`monitoring.strokes.log_records`) in :data:`SCHEMA`'s types; a value a
    stroke does not have (NaN in its record) is NULL, which SQL's max() and avg() pass over where a NaN would win every
    max()."""
    table = pa.Table.from_pylist(records, schema=SCHEMA)  # the declared types, also where a log has no clock (tdc_time null)
    for k, field in enumerate(SCHEMA):
        if field.type == pa.float64():
            col = table.column(k)
            table = table.set_column(k, field, pc.if_else(pc.is_nan(col), pa.scalar(None, pa.float64()), col))
    return table


def write_table(table: pa.Table, store: str | Path, name: str) -> int:
    """Write ``table`` (:func:`records_table`) under ``store``, one file per press and day named ``name`` (the log's
    digest); returns how many records were written. The database follows at the next query."""
    ds.write_dataset(table, str(store), format="parquet", partitioning=list(PARTITIONS), partitioning_flavor="hive",
                     basename_template=f"{name}-{{i}}.parquet", existing_data_behavior="overwrite_or_ignore")
    return table.num_rows


def write_records(records: list[dict], store: str | Path, name: str) -> int:
    """Write ``records`` (:func:`monitoring.strokes.log_records`) under ``store`` (:func:`write_table`); returns how many
    were written."""
    return write_table(records_table(records), store, name) if records else 0


def _parquet_files(store: Path) -> dict[str, tuple[int, int]]:
    """Each partition file of ``store`` (its path under the store, '/'-separated) with its size (bytes) and
    modification time (ns)."""
    out = {}
    for p in store.glob("press=*/day=*/*.parquet"):
        st = p.stat()
        out[p.relative_to(store).as_posix()] = (st.st_size, st.st_mtime_ns)
    return out


def _schema_ok(con) -> bool:
    tables = {r[0] for r in con.execute("SELECT table_name FROM duckdb_tables()").fetchall()}
    if not {"strokes", "parquet_files", "about"} <= tables:
        return False
    return con.execute("SELECT schema_version FROM about").fetchall() == [(SCHEMA_VERSION,)]


def sync(con, store: Path) -> tuple[int, int]:
    """Bring the database of ``con`` in step with the Parquet files of ``store``; returns (files read, files dropped).
    A database of another schema version is built again from the files (it holds nothing the files do not)."""
    if not _schema_ok(con):
        for kind, name in (("MACRO", "shift_start"), ("TABLE", "strokes"), ("TABLE", "parquet_files"), ("TABLE", "about")):
            con.execute(f"DROP {kind} IF EXISTS {name}")
        for ddl in _TABLES:
            con.execute(ddl)
        con.execute("INSERT INTO about VALUES (?, ?)", [SCHEMA_VERSION, "servo-press strokes: derived from the store's "
                                                        "Parquet files, rebuilt by the next query when deleted"])
    files = _parquet_files(store)
    known = {f: (s, m) for f, s, m in con.execute("SELECT file, size, mtime_ns FROM parquet_files").fetchall()}
    stale = [f for f, stamp in known.items() if files.get(f) != stamp]
    fresh = [f for f, stamp in files.items() if known.get(f) != stamp]
    if not stale and not fresh:
        return 0, 0
    con.execute("BEGIN TRANSACTION")  # a sync cut short leaves the database as it was
    try:
        if stale:
            con.execute("CREATE TEMP TABLE gone AS SELECT unnest(?::VARCHAR[]) AS file", [stale])
            con.execute("DELETE FROM strokes WHERE file IN (SELECT file FROM gone)")
            con.execute("DELETE FROM parquet_files WHERE file IN (SELECT file FROM gone)")
            con.execute("DROP TABLE gone")
        if fresh:
            root = store.resolve().as_posix().rstrip("/") + "/"
            paths = [root + f for f in fresh]
            # partition columns come from the folder names (kept as text, as the records write them); a file of an older
            # schema lacks the newer columns, which read as NULL
            con.execute("INSERT INTO strokes BY NAME SELECT * EXCLUDE (filename), substr(filename, ?) AS file FROM "
                        "read_parquet(?, hive_partitioning = true, hive_types_autocast = false, union_by_name = true, "
                        "filename = true)", [len(root) + 1, paths])
            con.execute("INSERT INTO parquet_files SELECT unnest(?::VARCHAR[]), unnest(?::BIGINT[]), unnest(?::BIGINT[])",
                        [fresh, [files[f][0] for f in fresh], [files[f][1] for f in fresh]])
        con.execute("COMMIT")
    except BaseException:
        con.execute("ROLLBACK")
        raise
    return len(fresh), len(stale)


def query(store: str | Path, sql: str, params: list | None = None) -> list[tuple]:
    """Rows of ``sql`` on the store's database (its ``strokes`` table, brought in step with the Parquet files first);
    ``{store}`` in ``sql`` stands for the store's folder, for SQL that reads the Parquet files themselves."""
    store = Path(store)
    if not store.is_dir() or not ((store / MARKER).is_file() or next(store.glob("press=*/day=*/*.parquet"), None)):
        # the database is written into the folder: never into one that is not a store
        raise PressDataError(str(store), "store", str(store), "is not a stroke store (no store.json, no press=*/day=*/*.parquet): "
                             "give the --out folder of `servo-press strokes`")
    try:
        con = duckdb.connect(str(store / DATABASE))
    except duckdb.IOException as e:  # another process writes it (DuckDB has one writer at a time)
        raise PressDataError(str(store), "store", str(store / DATABASE), f"cannot be opened ({str(e).splitlines()[0]}): "
                             "wait for the other servo-press run on this store to end, then query again") from None
    with con:
        con.execute("SET enable_progress_bar = false")  # a query's result, not a terminal's bar, is what the caller prints
        sync(con, store)
        return con.execute(sql.format(store=store.as_posix()), params).fetchall()
