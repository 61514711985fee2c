"""The record a run folder holds of what servo-press wrote there, and what in the folder a rerun may replace.

A finished run folder holds :data:`MARKER`: the command that wrote it, the size and SHA-256 of every file it wrote
and every folder it made. The record is not trusted as written: a rerun replaces the folder only when everything in
it is in the record and every file still has its recorded size and hash, so a file the user added or changed
(or a record made by hand that lists a user's file) is refused, never deleted.
"""
from __future__ import annotations

import hashlib
import json
import os
import stat
from pathlib import Path

MARKER = ".servo-press-run.json"
WHAT = ("servo-press run folder: the command that wrote it, the size and SHA-256 of every file it wrote and the folders it "
        "made; a rerun of the same command replaces them when they are unchanged, nothing else here is ever deleted")


def file_sha256(path: Path) -> str:
    """The SHA-256 of the file's bytes, as 64 hex digits."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def walk(folder: Path) -> tuple[list[str], list[str]]:
    """Everything under ``folder`` as sorted relative POSIX paths: (files, folders). Links are not followed: a link
    (to a folder too) counts as a file; the top-level :data:`MARKER` is left out."""
    folder = Path(folder)
    files, folders = [], []
    for root, dirs, names in os.walk(folder, followlinks=False):
        rel = Path(root).relative_to(folder)
        for d in list(dirs):
            if os.path.islink(os.path.join(root, d)):
                dirs.remove(d)
                names.append(d)
            else:
                folders.append((rel / d).as_posix())
        files += [(rel / n).as_posix() for n in names]
    return sorted(f for f in files if f != MARKER), sorted(folders)


def describe(folder: Path, command: str) -> dict:
    """The record of ``folder`` as ``command`` leaves it: ``{"what", "command", "files": [{"path", "bytes",
    "sha256"}], "folders"}`` (bytes: the file's size)."""
    folder = Path(folder)
    files, folders = walk(folder)
    return {"what": WHAT, "command": command,
            "files": [{"path": f, "bytes": (folder / f).stat().st_size, "sha256": file_sha256(folder / f)} for f in files],
            "folders": folders}


def _entry(e) -> tuple[str, int, str] | None:
    if not isinstance(e, dict):
        return None
    path, size, digest = e.get("path"), e.get("bytes"), e.get("sha256")
    if not (isinstance(path, str) and isinstance(size, int) and not isinstance(size, bool) and size >= 0
            and isinstance(digest, str) and len(digest) == 64):
        return None
    return path, size, digest.lower()


def read_marker(folder: Path) -> dict | None:
    """The MARKER of ``folder`` as ``{"command", "files", "hashes", "folders"}``, or None when it has none (or one that
    is not a servo-press record). ``files``: the names it lists; ``hashes``: name -> (bytes, sha256), and ``folders``,
    None in a record of an earlier version that listed names alone."""
    try:
        rec = json.loads((Path(folder) / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not (isinstance(rec, dict) and isinstance(rec.get("command"), str) and isinstance(rec.get("files"), list)):
        return None
    files, folders = rec["files"], rec.get("folders")
    if folders is None:  # an earlier version's record: names alone
        if not all(isinstance(f, str) for f in files):
            return None
        return {"command": rec["command"], "files": list(files), "hashes": None, "folders": None}
    entries = [_entry(e) for e in files]
    if None in entries or not (isinstance(folders, list) and all(isinstance(d, str) for d in folders)):
        return None
    return {"command": rec["command"], "files": [e[0] for e in entries], "hashes": {e[0]: e[1:] for e in entries},
            "folders": list(folders)}


def _unchanged(path: Path, size: int, digest: str) -> bool:
    try:
        st = os.lstat(path)
        if not stat.S_ISREG(st.st_mode) or st.st_size != size:
            return False
        return file_sha256(path) == digest
    except OSError:
        return False


def foreign(folder: Path, marker: dict) -> tuple[list[str], list[str]]:
    """What in ``folder`` the run recorded in ``marker`` (with hashes) did not write as it is now: (entries not in the
    record, folders with a trailing '/'; recorded files whose size or SHA-256 differ, or that are no longer plain
    files). Both empty: the folder may be replaced whole."""
    files, folders = walk(folder)
    hashes, made = marker["hashes"], set(marker["folders"])
    extra = [d + "/" for d in folders if d not in made] + [f for f in files if f not in hashes]
    changed = [f for f in files if f in hashes and not _unchanged(Path(folder) / f, *hashes[f])]
    return sorted(extra), changed
