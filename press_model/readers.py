"""Readers of the project's data files, shared by all three packages: typed, range-checked fields of a TOML tree
(:class:`FieldReader`), TOML and text files with one-line errors, and a content fingerprint.

They know nothing of presses; :mod:`press_data`, :mod:`jobs` and the calibration readers build their plain
descriptions with them.
"""
from __future__ import annotations

import copy
import difflib
import hashlib
import json
import math
import tomllib
from collections.abc import Mapping
from importlib import resources
from pathlib import Path

import numpy as np

from press_io.errors import PressDataError


def fmt_path(parts) -> str:
    """A field path as the dotted name error messages give (``bodies.crank.mass_kg``)."""
    return ".".join(str(p) for p in parts)


class FieldReader:
    """Reads typed, range-checked fields from the raw TOML tree; every error names its field."""

    def __init__(self, source: str, raw: Mapping):
        self.source, self.raw = source, raw
        self.seen: set[tuple] = set()  # every path read, so that unread (misspelled) keys can be reported

    def reject_unread(self, hint: str = "see the reference press file for the format") -> None:
        """Fail on the first key of the file that nothing read: most often a misspelling. ``hint`` says where the format is."""

        def walk(node, path):
            if path not in self.seen:
                yield path
            elif isinstance(node, Mapping):
                for k, v in node.items():
                    yield from walk(v, (*path, k))

        for path in walk(self.raw, ()):
            if path:
                parent = fmt_path(path[:-1]) or "top level"
                known = [p[-1] for p in self.seen if len(p) == len(path) and p[:-1] == path[:-1] and isinstance(p[-1], str)]
                close = difflib.get_close_matches(str(path[-1]), sorted(set(known)), n=1, cutoff=0.7)
                guess = f"misspelled? did you mean '{close[0]}'?" if close else "misspelled?"
                if path[-1] == "schema":  # the file's form is said once, before any table (press_model/schema.py)
                    guess = "'schema' is a top-level key: move it above the file's first [table]"
                self.fail(path, self.node(path), f"is not a known key of [{parent}] ({guess}); {hint}")

    def delegate(self, path) -> None:
        """Mark the table at ``path`` and everything under it as read: another reader validates it."""

        def mark(node, at):
            self.seen.add(at)
            if isinstance(node, Mapping):
                for k, v in node.items():
                    mark(v, (*at, k))

        mark(self.node(path, required=False), tuple(path))

    def fail(self, path, value, expected):
        raise PressDataError(self.source, fmt_path(path) if not isinstance(path, str) else path, value, expected)

    def node(self, path, required=True):
        self.seen.add(())
        cur = self.raw
        for i, key in enumerate(path):
            self.seen.add(tuple(path[: i + 1]))
            if type(cur) is dict and key in cur:  # the common case, a parsed table holding the key: no ABC check
                cur = cur[key]
                continue
            if isinstance(cur, list) and isinstance(key, int) and 0 <= key < len(cur):
                cur = cur[key]
                continue
            if not isinstance(cur, Mapping) or key not in cur:
                if not required:
                    return None
                if isinstance(cur, Mapping) and isinstance(key, str):  # a misspelling of a required key: name it
                    close = difflib.get_close_matches(key, [k for k in cur if isinstance(k, str)], n=1, cutoff=0.7)
                    if close and tuple((*path[:i], close[0])) not in self.seen:
                        self.fail((*path[:i], close[0]), cur[close[0]], f"is not a known key of "
                                  f"[{fmt_path(path[:i]) or 'top level'}] (misspelled? did you mean '{key}'?); '{key}' is required")
                if not self.raw:  # nothing in the file at all: say so, not which key comes first
                    self.fail("<file>", "<empty>", f"holds no TOML keys: the file is empty; it needs at least the [{path[0]}] "
                              "table (start from a shipped file, e.g. a copy of press_model/data/reference_press.toml or of a job file there)")
                if i == 0:
                    self.fail(path[:1], "<missing>", f"required; add the [{key}] table")
                self.fail(path, "<missing>", f"required; add '{path[-1]}' under [{fmt_path(path[:-1])}]")
            cur = cur[key]
        return cur

    def table(self, path, required=True) -> Mapping:
        val = self.node(path, required)
        if val is None:
            return {}
        if not isinstance(val, Mapping):
            self.fail(path, val, "must be a table")
        return val

    def number(self, path, *, gt=None, ge=None, le=None, lt=None, default=None, unit="", limit=None, what="any press"):
        """A finite number within the given bounds; ``limit`` names a plausibility bound of run_limits.toml
        (``max_...`` an upper, ``min_...`` a lower one) that ``what`` the message says it is far beyond."""
        val = self.node(path, required=default is None)
        if val is None:
            return float(default)
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
            self.fail(path, val, f"must be a finite number{' in ' + unit if unit else ''}")
        conds = []
        ok = True
        if gt is not None:
            conds.append(f"> {gt}")
            ok &= val > gt
        if ge is not None:
            conds.append(f">= {ge}")
            ok &= val >= ge
        if lt is not None:
            conds.append(f"< {lt}")
            ok &= val < lt
        if le is not None:
            conds.append(f"<= {le}")
            ok &= val <= le
        if not ok:
            self.fail(path, val, f"must be {' and '.join(conds)}{' (' + unit + ')' if unit else ''}")
        if limit is not None:
            self.plausible(path, val, limit, unit, what)
        return float(val)

    def flag(self, path, default=None) -> bool:
        """A true/false switch; ``default`` when the key is absent (None: required)."""
        val = self.node(path, required=default is None)
        if val is None:
            return bool(default)
        if not isinstance(val, bool):
            self.fail(path, val, "must be true or false")
        return val

    def plausible(self, path, value, key: str, unit: str = "", what: str = "any press"):
        """``value`` if it lies on the right side of the bound ``key`` of run_limits.toml (``max_...``: at most,
        ``min_...``: at least), else refused naming the bound, its key and the file."""
        from .limits import LIMITS_FILE, run_limits

        bound = getattr(run_limits(), key)
        unit = unit.split(",")[0].split(";")[0].split(" about ")[0].split(" at ")[0]  # the unit alone, not its note
        upper = key.startswith("max_")
        if (value > bound) if upper else (value < bound):
            shown = f"{bound:g}" if isinstance(bound, float) else str(bound)
            self.fail(path, value, f"must be at {'most' if upper else 'least'} {shown}{' ' + unit if unit else ''}, far "
                      f"{'above' if upper else 'below'} {what} ({key} in {LIMITS_FILE}); check the unit and the exponent")
        return value

    def angle(self, path) -> float:
        """An angle in deg (a direction, not a count of turns): within one turn either way, so that a typo such as
        1e300 deg (no orientation at all: cos and sin of it are rounding noise) is refused here; returns radians."""
        return math.radians(self.number(path, ge=-360.0, le=360.0, unit="deg"))

    def integer(self, path, *, ge=1, le=None, default=None, limit="max_count", what="any count a run needs"):
        """A whole number >= ``ge`` (and <= ``le`` when given), at most the bound ``limit`` of run_limits.toml (by
        default max_count: a count of 2^63 asked numpy for an array it cannot hold); ``limit=None`` for a number that
        is no count (a seed)."""
        val = self.node(path, required=default is None)
        if val is None:
            return int(default)
        if isinstance(val, bool) or not isinstance(val, int) or val < ge or (le is not None and val > le):
            self.fail(path, val, f"must be a whole number >= {ge}" + ("" if le is None else f" and <= {le}"))
        if limit is not None:
            self.plausible(path, val, limit, "", what)
        return int(val)

    def string(self, path, choices=None, default=None):
        val = self.node(path, required=default is None)
        if val is None:
            return default
        if not isinstance(val, str) or not val:
            self.fail(path, val, "must be a non-empty string")
        if choices is not None and val not in choices:
            self.fail(path, val, f"must be one of {', '.join(map(repr, choices))}")
        return val

    def vec2(self, path):
        val = self.node(path)
        if isinstance(val, Mapping):  # polar form {r_m, angle_deg}
            r = self.number((*path, "r_m"), ge=0.0, unit="m")
            a = self.angle((*path, "angle_deg"))
            return np.array([r * math.cos(a), r * math.sin(a)])
        if (
            not isinstance(val, list)
            or len(val) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in val)
        ):
            self.fail(path, val, "must be a point [x_m, y_m] or {r_m = ..., angle_deg = ...}")
        return np.array([float(val[0]), float(val[1])])


_ATOMS = (str, int, float, bool, type(None))


def copy_tree(node):
    """A deep copy of a parsed TOML tree (tables as dicts, arrays as lists, immutable scalars shared): what
    ``copy.deepcopy`` gives for such a tree, several times faster (a press is copied at every read and override).
    Anything else in the tree (a date, a value a caller put there) is copied by ``copy.deepcopy``."""
    kind = type(node)
    if kind is dict:
        return {k: copy_tree(v) for k, v in node.items()}
    if kind is list:
        return [copy_tree(v) for v in node]
    if kind in _ATOMS:
        return node
    return copy.deepcopy(node)


def data_fingerprint(raw: Mapping) -> str:
    """"sha256:<16 hex>" of a data file's parsed content: formatting and comments do not count."""
    return "sha256:" + hashlib.sha256(json.dumps(raw, sort_keys=True, separators=(",", ":"), default=str).encode()).hexdigest()[:16]


def read_toml(path: str | Path | None, builtin: str | None, flag: str, missing: str) -> tuple[dict, str]:
    """A TOML data file as a table, and its name for messages: the shipped ``press_model/data/<builtin>`` when
    ``builtin`` is given, else the user's ``path``. A path that is no file raises :class:`PressDataError` naming
    ``flag`` and what ``missing`` says it must be; so does a file that is not valid TOML."""
    if builtin is not None:
        text = resources.files("press_model.data").joinpath(builtin).read_text(encoding="utf-8")
        source = f"<built-in {builtin}>"
    else:
        if not is_file(path):
            raise PressDataError(str(path), flag, str(path), missing)
        text, source = read_text_file(Path(path), flag), str(path)
    try:
        return tomllib.loads(text), source
    except tomllib.TOMLDecodeError as exc:
        raise PressDataError(source, "<file>", "TOML", f"is not valid TOML ({exc}); fix the syntax at that line") from None


def is_file(path: str | Path) -> bool:
    """True if ``path`` names an existing regular file; False also for a name the system cannot look up
    (too long, or holding a NUL), which ``Path.is_file`` raises on."""
    try:
        return Path(path).is_file()
    except (OSError, ValueError):
        return False


def read_text_with_digest(path: Path, field: str) -> tuple[str, str]:
    """A user's text file as :func:`read_text_file` gives it (UTF-8, a byte-order mark dropped) and "sha256:<hex>" of its
    bytes, from one read: what was hashed is what was parsed. Errors as :func:`read_text_file`'s."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise PressDataError(str(path), field, str(path), f"must be a readable file ({exc.strerror})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise PressDataError(str(path), field, str(path), f"must be a UTF-8 text file ({exc.reason} at byte {exc.start})") from None
    return text.removeprefix("\ufeff"), "sha256:" + hashlib.sha256(data).hexdigest()


def read_text_file(path: Path, field: str) -> str:
    """A user's text file as UTF-8; unreadable or undecodable files raise :class:`PressDataError`."""
    try:
        return Path(path).read_text(encoding="utf-8").removeprefix("\ufeff")  # a UTF-8 byte-order mark (Windows editors)
    except UnicodeDecodeError as exc:
        raise PressDataError(str(path), field, str(path), f"must be a UTF-8 text file ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise PressDataError(str(path), field, str(path), f"must be a readable file ({exc.strerror})") from None
