"""Drive traces as their tools export them: the named channels of a file, each with its own time if it has one.

Three readers, chosen by :func:`read_trace` from the file itself (never from its name alone):

* **TwinCAT 3 Scope View CSV export** (Beckhoff), :func:`read_scope_csv`: recognised by its first line,
  ``Name`` and the separator. Every separator the exporter offers (tab, space, colon, semicolon, comma) is taken
  from that line, and the decimal mark (point or comma, as the PC was set) from the data. The header lines
  (``Name``, ``File``, ``Starttime of export``, ...) and the metadata rows (``Name``, ``SampleTime[ms]``, ``Unit``
  ...) are read line by line; the data rows by pandas. Each channel has a time column (ms) of its own or shares
  one with the channels after it ("exclude double timestamp"), so channels with different sample times keep
  their own times here. The values are taken as exported (the scope's scaling already applied). A
  space-separated export whose channel names hold spaces cannot be split and is refused.
* **NI TDMS**, :func:`read_tdms`, through npTDMS: every channel of every group, named ``group/channel`` (or
  ``channel`` where that is unique); a channel with waveform timing (``wf_increment``) has its own time. A channel
  of text or time stamps, or with waveform timing that is no number, is kept aside with the reason, which a map
  naming it is told. npTDMS's own log lines (a file cut off inside its last segment) become notes, not terminal lines.
* **Plain CSV with a header row**, :func:`read_plain_csv`: ``#`` comment lines, then the column names, then
  numbers; separator (comma, semicolon or tab) from the header line, decimal mark from the data, parsed by
  pandas. No channel has a time of its own: the channel map names the time column.

Which channel is which, and in which unit, is the channel map's business (:mod:`calibration.traces.channel_map`).
"""
from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import re
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from press_io.errors import PressDataError
from press_model.readers import is_file

from calibration.traces.drive_log import comments_and_header

SCOPE = "TwinCAT Scope CSV export"
TDMS = "NI TDMS"
CSV = "CSV"
SCOPE_SEPARATORS = {"\t": "tab", " ": "space", ":": "colon", ";": "semicolon", ",": "comma"}
_LAYOUT_KEY = "Data-Type"  # the metadata row that gives the column layout: its cells hold neither spaces nor decimal commas
_DECIMAL_COMMA = re.compile(r"[-+]?\d+,\d+(?:[eE][-+]?\d+)?")
_DECIMAL_POINT = re.compile(r"[-+]?\d*\.\d+(?:[eE][-+]?\d+)?")
_FILETIME_EPOCH = datetime(1601, 1, 1, tzinfo=timezone.utc)  # Windows FILETIME counts 100 ns ticks from here (UTC)
_FILETIME_MAX = (datetime(9999, 12, 31, 23, 59, 59, 999999, tzinfo=timezone.utc) - _FILETIME_EPOCH) // timedelta(microseconds=1) * 10 + 9
_LISTED = 8  # message length only: how many channel names one message lists


@dataclass(frozen=True, eq=False)
class Channel:
    """One channel: ``values`` as in the file, ``time_s`` (s from the start of the recording) when the channel has a
    time of its own (None: a column of a plain CSV), ``lines`` the 1-based file line of each sample (None for a
    binary file), ``unit`` as the file states it ('' if it does not)."""

    name: str  # as the map names it: the column name, or 'group/channel' in a TDMS file
    values: np.ndarray
    time_s: np.ndarray | None
    lines: np.ndarray | None
    unit: str = ""


@dataclass(frozen=True, eq=False)
class Trace:
    """A trace file read: its format, its comments (metadata worth keeping, such as a ``recorded:`` date and any
    SYNTHETIC label) and its channels by name, in file order; ``how`` says how it was read (separator, decimal mark)."""

    source: str
    format: str
    comments: tuple[str, ...]
    channels: dict[str, Channel]
    how: str
    aliases: tuple[tuple[str, str], ...] = ()  # (short name, channel key): a TDMS channel's name where it is unique in the file
    unreadable: tuple[Unreadable, ...] = ()  # channels the file holds but no signal can be read from, with the reason
    notes: tuple[str, ...] = ()  # what the reading library reported (a file cut off ...), for the log's warnings
    sha256: str = ""  # "sha256:<hex>" of the file's bytes as :func:`read_trace` read them ("" from the format readers)

    def channel(self, name: str, source: str, field: str) -> Channel:
        """The channel ``name``; a name the file does not hold, holds in several groups, or holds without readable
        samples raises :class:`PressDataError` on ``field`` of ``source`` (the map) saying which."""
        key = dict(self.aliases).get(name, name)
        ch = self.channels.get(key)
        if ch is not None:
            return ch
        hit = next((u for u in self.unreadable if u.key == key), None)
        if hit is not None:
            if hit.error is not None:
                raise hit.error
            raise PressDataError(source, field, name, f"names the channel '{hit.key}' of {self.source}, which {hit.reason}: "
                                 "name a channel of numbers (the drive's signal)")
        same = [k for k in [*self.channels, *(u.key for u in self.unreadable)] if k.rpartition("/")[2] == name]
        if len(same) > 1:
            raise PressDataError(source, field, name, f"is ambiguous: {self.source} holds a channel of that name in several "
                                 f"groups ({', '.join(map(repr, same))}); write the one meant as 'group/channel'")
        names = list(self.channels)
        listed = ", ".join(map(repr, names[:_LISTED])) + (f" and {len(names) - _LISTED} more" if len(names) > _LISTED else "")
        raise PressDataError(source, field, name, f"names no channel of {self.source} ({self.format}; its channels: "
                             f"{listed or 'none'}); give the channel's name exactly as the file writes it")


@dataclass(frozen=True)
class Unreadable:
    """A channel of a trace that gives no samples: ``reason`` says why (text, time stamps); ``error``, when set, is
    the refusal of the file itself (a property that is no number), raised when a map names the channel."""

    key: str
    reason: str
    error: PressDataError | None = None


def read_trace(path: str | Path) -> Trace:
    """Read a trace file in whichever of the three formats it is (see the module docstring)."""
    p = Path(path)
    if not is_file(p):
        raise PressDataError(str(p), "<file>", str(p), "must be an existing trace file (TwinCAT Scope CSV export, NI TDMS or CSV)")
    data = _read_bytes(p)  # once: the format is told from the head of these bytes, which are then parsed and hashed
    if data.startswith(b"TDSm"):  # the lead-in tag of every TDMS segment
        trace = read_tdms(p, data)
    else:
        first = _decode(data[:4096], str(p), partial=True).removeprefix("\ufeff").split("\n", 1)[0]
        trace = read_scope_csv(p, data) if _scope_separator(first) is not None else read_plain_csv(p, data)
    return dataclasses.replace(trace, sha256="sha256:" + hashlib.sha256(data).hexdigest())


# --- text -----------------------------------------------------------------------------------------------
def _decode(data: bytes, source: str, partial: bool = False) -> str:
    """UTF-8 text, else Windows-1252 (what a German or English Windows PC writes without a byte-order mark)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        if partial and exc.start >= len(data) - 3:  # a character cut at the end of the first block read
            return data[:exc.start].decode("utf-8")
    try:
        return data.decode("cp1252")
    except UnicodeDecodeError as exc:
        raise PressDataError(source, "<file>", source, f"must be a text file in UTF-8 or Windows-1252 (byte {exc.start} is neither)") from None


def _read_bytes(p: Path) -> bytes:
    try:
        return p.read_bytes()
    except OSError as exc:
        raise PressDataError(str(p), "<file>", str(p), f"must be a readable file ({exc.strerror})") from None


def _read_text(p: Path, data: bytes | None = None) -> str:
    """The text of ``p``: of ``data`` when the file was read already (:func:`read_trace`), else read now."""
    return _decode(_read_bytes(p) if data is None else data, str(p)).removeprefix("\ufeff")


def _decimal_mark(cells, sep: str) -> str:
    """',' if any cell is a number written with a decimal comma, else '.' (a comma separator leaves only the point)."""
    if sep == ",":
        return "."
    for c in cells:
        c = c.strip()
        if _DECIMAL_COMMA.fullmatch(c):
            return ","
        if _DECIMAL_POINT.fullmatch(c):
            return "."
    return "."


def _numbers(rows: list[str], lines: list[int], sep: str, decimal: str, ncols: int, source: str, what: str) -> np.ndarray:
    """The data rows as a (rows, ncols) float array, NaN for empty cells; parsed by pandas. A row with more cells
    than ``ncols`` or a cell that is no number raises :class:`PressDataError` naming its line."""
    import pandas as pd

    rows = [r[:-1] if r.endswith(sep) and r.count(sep) == ncols else r for r in rows]  # a trailing separator ends a row
    for i, row in enumerate(rows):
        if row.count(sep) >= ncols:
            raise PressDataError(source, f"line {lines[i]}", row.strip()[:80].replace("\t", "\\t"),
                                 f"holds more than the {ncols} cells of {what}: a decimal comma in a comma-separated file, or "
                                 "rows of another export pasted in; export again with another separator or decimal mark")
    text = "\n".join(rows)
    common = dict(sep=sep, header=None, names=list(range(ncols)), skip_blank_lines=False, quoting=3, engine="c")
    try:  # the C parser reads the numbers directly; a blank cell (" ", as the Scope writes one) is a missing sample
        frame = pd.read_csv(io.StringIO(text), decimal=decimal, dtype=float, na_values=[" ", ""], keep_default_na=True, **common)
        return frame.to_numpy(dtype=float)
    except ValueError:
        pass  # a cell that is no number: find it, to name its line
    frame = pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False, **common)
    for j in range(ncols):
        col = frame[j].str.strip()
        num = pd.to_numeric(col.str.replace(decimal, ".", regex=False) if decimal != "." else col, errors="coerce")
        bad = num.isna() & (col != "") & (col.str.lower() != "nan")
        if bad.any():
            i = int(np.argmax(bad.to_numpy()))
            raise PressDataError(source, f"line {lines[i]}, column {j + 1}", col.iloc[i][:40],
                                 f"must be a number (decimal mark '{decimal}' detected from the file) or empty")
    raise PressDataError(source, f"lines {lines[0]}-{lines[-1]}", "data rows", f"could not be read as numbers with "
                         f"decimal mark '{decimal}'")


# --- TwinCAT Scope View CSV export ---------------------------------------------------------------------------
def _scope_separator(first_line: str) -> str | None:
    if first_line.startswith("Name") and len(first_line) > 4 and first_line[4] in SCOPE_SEPARATORS:
        return first_line[4]
    return None


def _split(line: str, sep: str) -> list[str]:
    cells = line.rstrip("\r").split(sep)
    return [c.strip().strip('"') if sep == " " else c.strip() for c in cells]


def _aligned(row: list[str], ncols: int) -> list[str]:
    """A metadata row if it splits into the layout's columns (a trailing separator allowed), else no cells."""
    return row if len(row) == ncols or (len(row) == ncols + 1 and row[-1] == "") else []


def _filetime(text: str, source: str, where: str) -> datetime | None:
    """The export's start as a UTC datetime from its Windows FILETIME (100 ns ticks since 1601-01-01 UTC); None for a
    cell that is no whole number or is 0 (no time stated). A FILETIME before 1601 or after the year 9999 raises
    :class:`PressDataError` naming ``where`` (the line)."""
    try:
        ticks = int(text)
    except ValueError:
        return None
    if ticks == 0:
        return None
    if not 0 < ticks <= _FILETIME_MAX:
        raise PressDataError(source, f"{where}, Starttime of export", text, f"must be a Windows FILETIME (100 ns ticks since "
                             f"1601-01-01 UTC) from 1 to {_FILETIME_MAX} (the year 9999): the export's start time is corrupt; "
                             "export again from TwinCAT Scope, or set the cell to 0 (no recording date)")
    return _FILETIME_EPOCH + timedelta(microseconds=ticks // 10)


def read_scope_csv(path: str | Path, data: bytes | None = None) -> Trace:
    """Read a TwinCAT 3 Scope View CSV export (any separator and decimal mark; see the module docstring); ``data``: the
    file's bytes when they were read already."""
    p = Path(path)
    source = str(p)
    lines = _read_text(p, data).splitlines()
    sep = _scope_separator(lines[0] if lines else "")
    if sep is None:
        raise PressDataError(source, "line 1", (lines[0] if lines else "")[:60], "must start with 'Name' and the separator "
                             "(the first line of a TwinCAT Scope CSV export)")
    meta_at = next((i for i in range(1, len(lines)) if lines[i].startswith("Name" + sep) or lines[i] == "Name"), None)
    if meta_at is None:
        raise PressDataError(source, "<file>", "no channel rows", "must hold the metadata rows of a TwinCAT Scope export "
                             "('Name', 'SampleTime[ms]', ... one row per key); export with the full header")
    header, header_at = {}, {}
    for at_line, line in enumerate(lines[1:meta_at], start=2):
        for key in ("File", "Starttime of export", "Endtime of export"):
            q = f'"{key}"' if sep == " " and " " in key else key
            if line.startswith(q + sep):
                header[key], header_at[key] = _split(line[len(q) + 1:], sep), at_line
    meta, i = {}, meta_at
    while i < len(lines) and lines[i].strip():
        for key in ("Name", _LAYOUT_KEY, "Unit", "SymbolComment"):
            if lines[i].startswith(key + sep):
                meta[key] = (i + 1, _split(lines[i], sep))
        i += 1
    if _LAYOUT_KEY not in meta or "Name" not in meta:
        raise PressDataError(source, "<file>", f"no 'Name' or '{_LAYOUT_KEY}' row", "must hold the metadata rows of the channel "
                             "names and data types; export with the full header")
    at, layout = meta[_LAYOUT_KEY]
    while layout and layout[-1] == "":
        layout.pop()
    ncols = len(layout)
    if not layout or layout[0] != _LAYOUT_KEY:
        raise PressDataError(source, f"line {at}", lines[at - 1][:60], f"must start with '{_LAYOUT_KEY}'")
    name_at, names = meta["Name"]
    names = names[:ncols] + [""] * (ncols - len(names))
    if len(meta["Name"][1]) > ncols and any(c for c in meta["Name"][1][ncols:]):
        raise PressDataError(source, f"line {name_at}", lines[name_at - 1][:80],
                             f"splits into more cells than the {ncols} columns of the '{_LAYOUT_KEY}' row: channel names hold "
                             f"the separator ({SCOPE_SEPARATORS[sep]}); export with tab or semicolon as the separator")
    # a space-separated export cannot split units or comments holding spaces: read them only where they split right
    units, comments_row = (_aligned(meta.get(k, (0, []))[1], ncols) for k in ("Unit", "SymbolComment"))
    decimal = _decimal_mark([c for r in lines[i + 1:i + 50] for c in r.split(sep)], sep)

    rows, numbers = [], []
    for k in range(i, len(lines)):
        s = lines[k]
        if not s.strip() or s.strip() == "EOF":
            continue
        rows.append(s)
        numbers.append(k + 1)
    if not rows:
        raise PressDataError(source, "<file>", "no data rows", "must hold data rows below the metadata rows")
    data = _numbers(rows, numbers, sep, decimal, ncols, source, f"the '{_LAYOUT_KEY}' row (line {at})")
    line_no = np.asarray(numbers)

    channels: dict[str, Channel] = {}
    title = lines[0][5:].rstrip("\r")
    comments = [f"{SCOPE} '{(title[:-1] if title.endswith(sep) else title).strip().strip(chr(34))}'"]
    started = _filetime(header.get("Starttime of export", [""])[0], source, f"line {header_at.get('Starttime of export')}")
    if started is not None:
        comments.append(f"recorded: {started.isoformat(timespec='milliseconds')}")
    t_col = None
    for j, key in enumerate(layout):
        if key == _LAYOUT_KEY:
            t_col = j
            continue
        name = names[j]
        if not name or name == "Name":
            raise PressDataError(source, f"line {name_at}, column {j + 1}", name, "must name the channel of this column")
        if name in channels:
            raise PressDataError(source, f"line {name_at}", name, "names two channels: rename one in the scope, or export "
                                 "without one of them (the channel map must find each channel by its name)")
        have = np.isfinite(data[:, t_col])
        unit = units[j] if j < len(units) and units[j] != "(None)" else ""
        channels[name] = Channel(name, data[have, j], data[have, t_col] / 1000.0, line_no[have], unit)
        note = comments_row[j] if j < len(comments_row) and comments_row[j] not in ("", "SymbolComment") else ""
        if note:
            comments.append(f"channel {name}: {note}")
    how = f"{SCOPE}, {SCOPE_SEPARATORS[sep]}-separated, decimal mark '{decimal}'"
    return Trace(source, SCOPE, tuple(comments), channels, how)


# --- NI TDMS ------------------------------------------------------------------------------------------------
def read_tdms(path: str | Path, data: bytes | None = None) -> Trace:
    """Read an NI TDMS file with npTDMS (see the module docstring); ``data``: the file's bytes when they were read
    already."""
    from nptdms import TdmsFile

    p = Path(path)
    source = str(p)
    with _nptdms_log() as said:
        try:
            f = TdmsFile.read(p if data is None else io.BytesIO(data))
        except Exception as exc:  # noqa: BLE001 (npTDMS raises many kinds for a damaged file; one line for all)
            raise PressDataError(source, "<file>", source, f"must be a readable NI TDMS file ({type(exc).__name__}: {exc})") from None
    comments = [f"{k}: {v}" for k, v in f.properties.items() if isinstance(v, str) and v]
    found, unreadable = [], []
    for g in f.groups():
        for ch in g.channels():
            key = f"{g.name}/{ch.name}"
            try:
                raw = ch[:]
            except Exception as exc:  # noqa: BLE001 (a data type or scaling npTDMS cannot read: this channel only)
                unreadable.append(Unreadable(key, f"npTDMS cannot read ({type(exc).__name__}: {exc})"))
                continue
            kind = getattr(raw, "dtype", np.dtype(object)).kind
            if kind == "M":  # numpy would turn time stamps into numbers of microseconds without a word
                unreadable.append(Unreadable(key, "holds time stamps (a TDMS timestamp channel), not samples"))
                continue
            try:
                values = np.asarray(raw, dtype=float)
            except (TypeError, ValueError):
                unreadable.append(Unreadable(key, "holds text (a TDMS string channel), not numbers"))
                continue
            try:
                time, start = _waveform_time(ch.properties, values.size, source, key)
            except PressDataError as exc:
                unreadable.append(Unreadable(key, "has waveform timing that is no number", exc))
                continue
            if start is not None and not any(c.startswith("recorded:") for c in comments):
                comments.append(f"recorded: {start}")
            found.append((g.name, ch.name, values, time, str(ch.properties.get("unit_string", ""))))
    counts: dict[str, int] = {}
    for short in [n for _, n, *_ in found] + [u.key.rpartition("/")[2] for u in unreadable]:
        counts[short] = counts.get(short, 0) + 1
    channels = {f"{g}/{n}": Channel(f"{g}/{n}", v, t, None, u) for g, n, v, t, u in found}
    aliases = tuple((k.rpartition("/")[2], k) for k in [*channels, *(u.key for u in unreadable)] if counts[k.rpartition("/")[2]] == 1)
    notes = (f"npTDMS reported while reading {source}: {'; '.join(dict.fromkeys(said))} (the file was cut off or written "
             "by a tool npTDMS does not fully know: check that the recording is complete).",) if said else ()
    return Trace(source, TDMS, tuple(comments), channels, f"{TDMS} (npTDMS)", aliases, tuple(unreadable), notes)


def _waveform_time(props, n: int, source: str, key: str) -> tuple[np.ndarray | None, str | None]:
    """A channel's own time (s) from its waveform timing (``wf_increment``, ``wf_start_offset``; None without it) and
    its start time as ISO-8601 UTC text (None without one). A property of the wrong type or value raises
    :class:`PressDataError` naming the channel and the property."""
    if "wf_increment" not in props:
        return None, None

    def number(name, default, positive):
        v = props.get(name, default)
        ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_)) and np.isfinite(v)
        if not ok or (positive and v <= 0):
            raise PressDataError(source, f"{key}: {name}", v if not isinstance(v, np.generic) else v.item(),
                                 f"must be a {'positive ' if positive else ''}finite number (s; the waveform timing LabVIEW "
                                 "writes as a double): write the property as a number, or remove the waveform properties "
                                 "and map a time channel (time_s)")
        return float(v)

    step, offset = number("wf_increment", None, True), number("wf_start_offset", 0.0, False)
    start = props.get("wf_start_time")
    text = None
    if start is not None:
        if not isinstance(start, (np.datetime64, datetime)):
            raise PressDataError(source, f"{key}: wf_start_time", start, "must be a TDMS timestamp (the waveform's start "
                                 "in UTC): write it as a timestamp, not as text, or leave it out")
        text = f"{np.datetime_as_string(np.datetime64(start, 'ms'))}+00:00"
    return offset + step * np.arange(n), text


@contextlib.contextmanager
def _nptdms_log():
    """Collect the messages npTDMS logs while the block runs (else they reach the terminal through its own handler as
    '[nptdms.reader WARNING] ...' lines beside ours); yields the list they are collected in."""
    from nptdms.log import log_manager

    said: list[str] = []

    def keep(record):
        said.append(record.getMessage())
        return False

    loggers = list(log_manager.loggers.values())  # a logger's filter also keeps the record from the root's handlers
    for lg in loggers:
        lg.addFilter(keep)
    try:
        yield said
    finally:
        for lg in loggers:
            lg.removeFilter(keep)


# --- plain CSV ----------------------------------------------------------------------------------------------
def read_plain_csv(path: str | Path, data: bytes | None = None) -> Trace:
    """Read a CSV with ``#`` comments, a header row of channel names and numeric rows (see the module docstring);
    ``data``: the file's bytes when they were read already."""
    p = Path(path)
    source = str(p)
    lines = _read_text(p, data).splitlines()
    comments, at = comments_and_header(lines)
    if at is None:
        raise PressDataError(source, "<file>", "no header", "must hold a header row of channel names and the data rows below it")
    header = lines[at]
    sep = max(("\t", ";", ","), key=header.count)
    if header.count(sep) == 0:
        raise PressDataError(source, f"header (line {at + 1})", header.strip()[:80], "must name at least two columns, "
                             "separated by commas, semicolons or tabs")
    names = [c.strip().strip('"') for c in header.split(sep)]
    if any(not n for n in names) or len(set(names)) != len(names):
        raise PressDataError(source, f"header (line {at + 1})", header.strip()[:80], "must name every column once")
    rows, numbers = [], []
    for k in range(at + 1, len(lines)):
        if lines[k].strip():
            if lines[k].lstrip().startswith("#"):
                raise PressDataError(source, f"line {k + 1}", lines[k].strip()[:80], "comments must come before the header line")
            rows.append(lines[k])
            numbers.append(k + 1)
    if not rows:
        raise PressDataError(source, "<file>", "no data rows", "must hold data rows below the header")
    decimal = _decimal_mark([c for r in rows[:50] for c in r.split(sep)], sep)
    data = _numbers(rows, numbers, sep, decimal, len(names), source, f"the header (line {at + 1})")
    line_no = np.asarray(numbers)
    channels = {n: Channel(n, data[:, j], None, line_no) for j, n in enumerate(names)}
    sep_name = {",": "comma", ";": "semicolon", "\t": "tab"}[sep]
    return Trace(source, CSV, tuple(comments), channels, f"{CSV}, {sep_name}-separated, decimal mark '{decimal}'")

