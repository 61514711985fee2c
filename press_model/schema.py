"""Schema versions of job and press files, and the migrations that read an older file as the current form.

A file says its form with a top-level ``schema = N``; a file without it is schema 1, the form of every file before
schema 2 existed. Schema 2 lets a file leave out every setting whose default it keeps (the settings' dataclasses hold
the defaults, press_model/README.md "Defaults" lists them) and drops the keys that earlier code read and today's does
not. Schema 3 drops a job's ``[design] residual_rms_Nm`` and ``covariance_inflation``: they were a
first calibration's residual and its AR(1) factor, and the design now needs the noise of the stroke-averaged curve
under new names (``noise_rms_Nm``, ``noise_inflation``; calibration/design/noise.py), so an old value is never read
with the new meaning. Schema 4 (the current one) changes a default: ``[calibration.process_force] job_force_tolerance``
(how well the job's process force is known when a log does not carry it) was 0 (exact) and is 3 %; an older job that
leaves it out is read with the 0 it meant (:class:`Kept`), and its note says so. :func:`migrate` turns a parsed file of any schema into the current form
(never touching the file itself) and says what it changed in ONE ``note:`` line on stderr per file; an older file
whose every key still means what it meant is read silently.
"""
from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import dataclass

from press_io.errors import PressDataError

from .readers import copy_tree

CURRENT = 4  # the schema the shipped files are written in and the readers read
SCHEMA_KEY = "schema"


@dataclass(frozen=True)
class Removed:
    """A key earlier code read and today's does not: dropped from a file of an older schema, with why."""

    path: tuple[str, ...]
    why: str


@dataclass(frozen=True)
class Kept:
    """A setting whose default changed: a file of an older schema that leaves it out is read with the old default
    ``value`` (what the file meant), with why the default changed and how to take the new one."""

    path: tuple[str, ...]
    value: object
    why: str
    only_with: tuple[str, ...] = ()  # top-level tables one of which the file must have (none: every file)


# schema N -> the changes that turn a file of schema N into one of schema N + 1, for each kind of file
MIGRATIONS: dict[str, dict[int, tuple[Removed | Kept, ...]]] = {
    "job": {
        1: (
            Removed(("playback", "kp_Nm_per_rad"), "the playback's gains now come from the press's inertia at the crank "
                    "(planning/playback.py); set playback.bandwidth_Hz and damping_ratio instead"),
            Removed(("playback", "kd_Nm_s_per_rad"), "the playback's gains now come from the press's inertia at the crank"),
            Removed(("planning", "solver", "jerk_max_rounds"), "the jerk limit is the jerk-limited optimum's "
                    "(planning/optimal.py; optimal_tolerance, optimal_max_iterations), no longer smoothing rounds"),
            Removed(("planning", "solver", "jerk_tightening"), "the jerk-limited optimum has no tightening rounds"),
        ),
        2: (
            Removed(("design", "residual_rms_Nm"), "it was a first calibration's residual RMS, mostly model misfit: 151 N m on "
                    "the cushion test against a noise of 71.9 N m, intervals 2.9x too wide; the design now needs the noise "
                    "of the stroke-averaged curve: set [design] noise_rms_Nm = calibrated.json's adequacy.pure_error_rms_Nm and "
                    "noise_inflation = (1 + r) / (1 - r) of its pure_error_lag1 r (1 when r <= 0), or give design-experiment "
                    "--calibrated calibrated.json"),
            Removed(("design", "covariance_inflation"), "it was the residual's AR(1) factor, 1.94 on the cushion test; the "
                    "noise's is [design] noise_inflation"),
        ),
        3: (
            Kept(("calibration", "process_force", "job_force_tolerance"), 0.0,
                 "the job's process force taken as exact, as this file's schema meant; schema 4's default is 0.03 (a servo "
                 "die cushion's force is known to about 3 %, which moves eta_gear about 3 % when the log has no "
                 "process_force_N column): state job_force_tolerance to choose",
                 only_with=("calibration",)),  # a job that calibrates (it has the table); a job without it never reads the key
        ),
    },
    "press": {1: (), 2: (), 3: ()},
}

_NOTED: set[str] = set()  # sources whose note was printed in this process


def file_schema(raw: Mapping, source: str) -> int:
    """The schema ``raw`` says it is in (1 without the key); a value that is no known schema is refused."""
    value = raw.get(SCHEMA_KEY, 1)
    if isinstance(value, int) and not isinstance(value, bool) and value > CURRENT:
        raise PressDataError(source, SCHEMA_KEY, value, f"must be a whole number from 1 to {CURRENT}: schema {value} is "
                             f"newer than this servo-press reads ({CURRENT} is today's), so the file was written for a later "
                             "release, whose keys this one may read otherwise; update servo-press, or use a file written "
                             f"in schema {CURRENT} or older")
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= CURRENT:
        raise PressDataError(source, SCHEMA_KEY, value, f"must be a whole number from 1 to {CURRENT} (the form the file "
                             f"is written in; {CURRENT} is today's, see press_model/README.md \"Schema\")")
    return value


def migrate(raw: Mapping, kind: str, source: str, note=None) -> dict:
    """The parsed file ``raw`` of ``kind`` ("job" or "press") in the current form, without its ``schema`` key; a
    file of an older schema that needed changes gets one ``note:`` line on stderr (once per ``source`` and process)
    saying what was read differently. ``note`` (a callable taking the line) replaces stderr."""
    schema = file_schema(raw, source)
    out = copy_tree(dict(raw))
    out.pop(SCHEMA_KEY, None)
    if schema == CURRENT:
        return out
    changes = []
    for n in range(schema, CURRENT):
        for step in MIGRATIONS[kind].get(n, ()):
            node = out
            for key in step.path[:-1]:
                node = node.get(key) if isinstance(node, Mapping) else None
            if isinstance(step, Kept):
                if (_absent(out, step.path) and (not step.only_with or any(t in out for t in step.only_with))
                        and _set(out, step.path, step.value)):
                    changes.append(f"read {'.'.join(step.path)} as {step.value!r} ({step.why})")
            elif isinstance(node, dict) and step.path[-1] in node:
                del node[step.path[-1]]
                changes.append(f"dropped {'.'.join(step.path)} ({step.why})")
    if not changes:  # every key of the older form means today what it meant then: nothing to say
        return out
    how = "; ".join(changes)
    said = "no 'schema' key" if SCHEMA_KEY not in raw else f"schema = {schema}"
    line = (f"note: {source}: read as schema {schema} ({said}): {how}; absent settings take their defaults "
            f"(press_model/README.md \"Defaults\"); add 'schema = {CURRENT}' to silence")
    if note is not None:
        note(line)
    elif source not in _NOTED:
        _NOTED.add(source)
        print(line, file=sys.stderr)
    return out


def _absent(raw: Mapping, path: tuple[str, ...]) -> bool:
    node = raw
    for key in path:
        if not isinstance(node, Mapping) or key not in node:
            return True
        node = node[key]
    return False


def _set(raw: dict, path: tuple[str, ...], value) -> bool:
    """``value`` at ``path`` in ``raw``, making the tables on the way; False where a table on the way is there but no
    table (left to the readers, which refuse it naming the key: no note says it was read)."""
    node = raw
    for key in path[:-1]:
        node = node.setdefault(key, {})
        if not isinstance(node, dict):
            return False
    node[path[-1]] = value
    return True
