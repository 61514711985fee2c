"""Typed settings with their defaults: each settings section of a job or press file is a frozen dataclass whose
fields are the file's keys, with today's shipped value as the default and its unit, reason and checks in one place.

:func:`setting` declares a field with a default; :func:`key` a key of the file's own data (required, or off by
default; no defaults table lists it); :func:`section` a table inside the section (read into its own settings
dataclass); :func:`own` a key of the file's own data that no plain reader reads (a list of names). :func:`read_section`
reads a section's table through a :class:`FieldReader` (every present value checked with the field's checks and
messages, every absent key its default, every inner table into its dataclass); :func:`sections` lists a section's
tables by path; :func:`fill_defaults` writes the defaults into a parsed file (what it holds once read);
:func:`defaults_rows` is the table the README shows (``python scripts/settings_table.py``); :func:`replaced` is a
section with some of its settings, inner ones by dotted name, changed.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import field

from .readers import FieldReader


def setting(default, unit: str, reason: str, /, read: Callable | None = None, **check):
    """A settings field: ``default`` in the file's unit (``unit``, "" for a pure number or a name), ``reason`` one
    line saying why that value; ``check`` the reader's keyword arguments (bounds, choices, ``unit``/``limit``/
    ``what`` of the message) exactly as :class:`FieldReader` takes them; ``read(rd, path, default)`` reads a
    value no plain reader can (a list)."""
    return field(default=default, metadata={"unit": unit, "reason": reason, "check": check, "read": read})


def key(kind: type, unit: str, meaning: str, /, default=dataclasses.MISSING, read: Callable | None = None, **check):
    """A key that is the file's own data, not a choice of ours with a shipped default (the defaults table does not
    list it): ``kind`` (float, int, str or bool) picks its reader, ``meaning`` says what it is, ``check`` as for
    :func:`setting`; required unless ``default`` is given (the value that leaves an option off). Declare the
    required ones before the fields with defaults."""
    meta = {"unit": unit, "reason": meaning, "check": check, "read": read, "kind": kind, "data": True}
    return field(metadata=meta) if default is dataclasses.MISSING else field(default=default, metadata=meta)


def section(cls, read: Callable | None = None):
    """A table inside a settings section: the field's value is the settings dataclass ``cls`` read from the table of
    the field's name (absent: all its defaults); ``read(rd, path)`` reads one whose checks span its keys."""
    return field(default_factory=cls, metadata={"section": cls, "read": read})


def own(read: Callable, default_factory: Callable | None = None):
    """A key that is the file's own data, not a choice with a shipped default (no defaults table lists it):
    ``read(rd, path)`` reads and checks it; without ``default_factory`` the field has no default (declare it first)."""
    if default_factory is None:
        return field(metadata={"own": True, "read": read})
    return field(default_factory=default_factory, metadata={"own": True, "read": read})


def settings_of(cls) -> list[dataclasses.Field]:
    """The fields of the settings dataclass ``cls`` declared with :func:`setting` (not its tables, nor its keys of
    the file's own data)."""
    return [f for f in dataclasses.fields(cls) if "reason" in f.metadata and "data" not in f.metadata]


def sections(path: tuple, cls) -> dict[tuple, type]:
    """path -> settings dataclass of the section ``cls`` at ``path`` and of every table inside it, in file order."""
    out = {path: cls}
    for f in dataclasses.fields(cls):
        if "section" in f.metadata:
            out.update(sections((*path, f.name), f.metadata["section"]))
    return out


def read_value(rd: FieldReader, path: tuple, f: dataclasses.Field):
    """The value of the field ``f`` at ``path``: the file's, checked, or the field's default when the key is absent;
    an inner table's settings dataclass; a key of the file's own as its reader reads it."""
    if "section" in f.metadata:
        read = f.metadata["read"]
        return read(rd, path) if read is not None else read_section(rd, path, f.metadata["section"])
    if "own" in f.metadata:
        return f.metadata["read"](rd, path)
    d, check, read = f.default, dict(f.metadata["check"]), f.metadata["read"]
    if d is dataclasses.MISSING:
        d = None  # a required key
    if read is not None:
        return read(rd, path, d)
    kind = f.metadata.get("kind", type(d))
    if kind is bool:
        return rd.flag(path, default=d)
    if kind is int:
        return rd.integer(path, default=d, **check)
    if kind is float:
        return rd.number(path, default=d, **check)
    if kind is str:
        return rd.string(path, default=d, **check)
    raise TypeError(f"{f.name}: no reader for a value of type {kind.__name__}")


def read_section(rd: FieldReader, path: tuple, cls, skip: tuple[str, ...] = ()):
    """An instance of the settings dataclass ``cls`` from the table at ``path`` (absent: all defaults), its inner
    tables read into theirs; fields named in ``skip`` keep their defaults unread (the caller reads them). A value that
    is not a table is refused: as such, or, in a section with a required key, as that key missing (the message a
    press file's [friction] = 3 has always had)."""
    fields = dataclasses.fields(cls)
    if all(f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING for f in fields):
        rd.table(path, required=False)
    return cls(**{f.name: read_value(rd, (*path, f.name), f) for f in fields if f.name not in skip})


def file_value(value):
    """A default as the TOML file writes it (a tuple as a list)."""
    return list(value) if isinstance(value, tuple) else value


def fill_defaults(raw: dict, sections: Mapping[tuple, type], only_present: bool = False) -> dict:
    """``raw`` (changed in place and returned) with every absent key of each section (path -> settings dataclass)
    set to its default; ``only_present``: only in the sections the file has."""
    for path, cls in sections.items():
        node, ok = raw, True
        for key in path:
            if not isinstance(node, dict):
                ok = False
                break
            if key not in node:
                if only_present:
                    ok = False
                    break
                node[key] = {}
            node = node[key]
        if ok and isinstance(node, dict):
            for f in settings_of(cls):
                node.setdefault(f.name, file_value(f.default))
    return raw


def defaults_rows(sections: Mapping[tuple, type]) -> list[tuple[str, str, str, str]]:
    """(dotted key, default as TOML, unit, reason) of every field of every section, in file order."""
    rows = []
    for path, cls in sections.items():
        for f in settings_of(cls):
            v = file_value(f.default)
            shown = f'"{v}"' if isinstance(v, str) else ("true" if v is True else "false" if v is False else repr(v))
            rows.append((".".join((*path, f.name)), shown, f.metadata["unit"], f.metadata["reason"]))
    return rows


def replaced(settings, changes: Mapping[str, object]):
    """``settings`` (a frozen settings dataclass) with each field named in ``changes`` set to its value; a dotted
    name (``bootstrap.refits``) sets a field of an inner table."""
    inner: dict[str, dict] = {}
    flat = {}
    for name, value in changes.items():
        head, _, rest = name.partition(".")
        if rest:
            inner.setdefault(head, {})[rest] = value
        else:
            flat[name] = value
    flat.update({head: replaced(getattr(settings, head), sub) for head, sub in inner.items()})
    return dataclasses.replace(settings, **flat)
