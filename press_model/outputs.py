"""Writing results: atomic CSV and JSON files that record what produced them."""
from __future__ import annotations

import csv
import io
import json
import math
import os
import platform
import shutil
import tempfile
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from typing import Callable

import numpy as np


def file_mode() -> int:
    """The mode a plainly created file gets (0666 less the umask): mkstemp's temp files are 0600, and a
    result renamed into place should be as readable as any other file the user writes."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def atomic_write(path: Path, write: Callable[[str], None], suffix: str = "") -> None:
    """Make ``path`` by ``write(temporary_path)`` in the same folder, then rename it into place, so that a
    reader never sees a half-written file and a failed write leaves nothing behind."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        os.chmod(tmp, file_mode())
        write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def atomic_write_text(path: Path, text: str) -> None:
    """Write text (UTF-8, LF line ends) atomically; see :func:`atomic_write`."""
    atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8", newline="\n"))


_PACKAGES = ("servo-press-twin", "pin", "numpy", "scipy", "SALib", "toppra", "matplotlib")


def versions() -> dict:
    """Versions of Python and of every package that shapes a result."""
    out = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def _clean(obj):
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    return obj


def write_json(path: Path, obj) -> None:
    """Write ``obj`` as indented, key-ordered JSON, atomically."""
    atomic_write_text(Path(path), json.dumps(_clean(obj), indent=2, sort_keys=False) + "\n")


def write_table(path: Path, columns: list[str], rows: list[dict], digits: int = 10, comments: tuple[str, ...] = ()) -> None:
    """Write rows (dicts keyed by ``columns``) as CSV with a header row, atomically; floats to ``digits`` digits;
    ``comments``: lines written first, each after '# ' (what a reader must know before the rows)."""
    buf = io.StringIO()
    for c in comments:
        buf.write(f"# {c}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([f"{r[c]:.{digits}g}" if isinstance(r[c], (float, np.floating)) else r[c] for c in columns])
    atomic_write_text(Path(path), buf.getvalue())


def write_csv(path: Path, columns: dict[str, np.ndarray], digits: int = 10, comments: tuple[str, ...] = ()) -> None:
    """Write equal-length numeric columns with a header row, atomically (``digits`` significant digits), after the
    ``comments`` lines ('# ...')."""
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    write_table(path, names, [dict(zip(names, map(float, row))) for row in data], digits, comments)


# --- a run's folder: all of its files, or none ------------------------------------------------------------
# Every run folder holds MARKER, written last: the command that wrote the folder and every file it wrote. A rerun
# of the same command replaces the folder whole; anything else in it (another command's result, a file the
# user added) is refused, never deleted.
MARKER = ".servo-press-run.json"
# The files a finished run of an earlier version left at the top of its folder (it wrote no MARKER)
RESULT_FILES = ("summary.json", "calibrated.json", "run.json", "comparison.json", "convergence.json", "alarms.json", "fleet.json", "prediction.json",
                "logs/monitor_run.json")
_SHORT = 100  # characters of --out's name kept in the names of its temporary sibling and lock (a name may have 255)


def _short(name: str) -> str:
    """``name`` for the names of its temporary sibling and lock: cut to :data:`_SHORT` characters, with a hash of the
    whole name when cut, so that the system's 255-character limit holds and two long names never share a lock."""
    if len(name) <= _SHORT:
        return name
    import hashlib

    return f"{name[:_SHORT]}-{hashlib.sha256(name.encode('utf-8', 'surrogateescape')).hexdigest()[:12]}"


def _is_earlier_result(folder: Path) -> bool:
    for name in RESULT_FILES:
        path = folder / name
        try:
            if path.is_file() and '"versions"' in path.read_text(encoding="utf-8", errors="replace"):
                return True
        except OSError:
            pass
    return False


def folder_files(folder: Path) -> list[str]:
    """Every file under ``folder`` (subfolders included), as sorted relative POSIX paths, the MARKER left out."""
    folder = Path(folder)
    names = (p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_symlink() or not p.is_dir())
    return sorted(n for n in names if n != MARKER)


def write_marker(folder: Path, command: str) -> None:
    """Record in ``folder`` that ``command`` wrote it, with every file it holds now (see :data:`MARKER`)."""
    write_json(Path(folder) / MARKER, {"what": "servo-press run folder: the command that wrote it and its files; a rerun of the "
                                       "same command replaces them, nothing else here is ever deleted",
                                       "command": command, "files": folder_files(folder)})


def read_marker(folder: Path) -> dict | None:
    """The MARKER of ``folder`` as ``{"command", "files"}``, or None when it has none (or an unreadable one)."""
    try:
        rec = json.loads((Path(folder) / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not (isinstance(rec, dict) and isinstance(rec.get("command"), str) and isinstance(rec.get("files"), list)):
        return None
    return rec


def _listed(names: list[str]) -> str:
    from .errors import one_line

    return one_line(", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else ""))


def check_replaceable(out: Path, command: str, shown: str) -> None:
    """Refuse an existing non-empty folder that ``command`` may not replace whole: one without a MARKER (the user's
    folder, or a result of an earlier version that did not record its files), another command's, or one holding
    files its command did not write."""
    from .errors import ServoPressError, one_line

    try:
        names = sorted(p.name for p in out.iterdir())
    except (FileNotFoundError, NotADirectoryError):
        return
    if not names:
        return
    marker = read_marker(out)
    if marker is None:
        if _is_earlier_result(out):
            raise ServoPressError(f"--out {shown}: holds a result of an earlier servo-press version that did not record which files it "
                                  "wrote, so replacing it could delete files you added: delete or move it yourself, or choose "
                                  "another --out")
        raise ServoPressError(f"--out {shown}: is a folder holding files that are not a servo-press result ({_listed(names)}); "
                              "a run replaces its output folder whole: choose a new or empty folder")
    if marker["command"] != command:
        raise ServoPressError(f"--out {shown}: holds the result of `servo-press {one_line(marker['command'])}`; `servo-press "
                              f"{command}` would replace it whole: choose another --out (a command replaces only its own "
                              "earlier result)")
    written = set(marker["files"])
    extra = [f for f in folder_files(out) if f not in written]
    if extra:
        raise ServoPressError(f"--out {shown}: holds files that servo-press did not write there ({_listed(extra)}); a run replaces "
                              "its output folder whole: move them out, or choose another --out")


def refuse_overwrite_input(out: Path, inputs) -> None:
    """Refuse an output path that is one of the user's input files."""
    from .errors import ServoPressError

    for i in inputs:
        if i is not None and Path(str(i)).exists() and Path(str(i)).resolve() == Path(out).resolve():
            raise ServoPressError(f"--out {out} is the input file {i}: choose another output path (inputs are never overwritten)")


def check_output_folder(path, inputs=(), command: str | None = None) -> Path:
    """Refuse an output folder that the run could not replace safely; returns it as a Path.

    Refused: an empty path (it would mean the current folder), an existing file, a folder that is or holds the
    current folder or one of ``inputs`` (replacing it would delete them), and a non-empty folder that
    ``command`` may not replace (:func:`check_replaceable`; ``command`` None: only the checks before it).
    """
    from .errors import ServoPressError, one_line

    text = str(path) if path is not None else ""
    if not text.strip():
        raise ServoPressError(f"--out = {text!r} is not valid: give an output folder, e.g. --out out/run1 "
                              "(an empty path would mean the current folder)")
    out = Path(text)
    shown = one_line(text)
    try:
        exists, is_dir = out.exists(), out.is_dir()
    except (OSError, ValueError):
        return out  # a name the system cannot look up: creating it reports the system's reason
    if exists and not is_dir:
        raise ServoPressError(f"--out {shown}: is an existing file, not a folder: choose a folder path (a run writes several files)")
    resolved = out.resolve()
    cwd = Path.cwd().resolve()
    if resolved == cwd or resolved in cwd.parents:
        raise ServoPressError(f"--out {shown}: is the current folder or holds it; a run replaces its output folder "
                              "whole: choose a subfolder, e.g. --out out/run1")
    for i in inputs:
        if i is None:
            continue
        try:
            ip = Path(str(i)).resolve()
            given = Path(str(i)).exists()
        except (OSError, ValueError):
            continue
        if given and (ip == resolved or resolved in ip.parents):
            raise ServoPressError(f"--out {shown}: holds the input file {one_line(i)}; a run replaces its output folder whole "
                                  "(inputs are never overwritten): choose another output folder")
    if is_dir and command is not None:
        check_replaceable(out, command, shown)
    return out


@contextmanager
def claim(path, shown: str | None = None):
    """Hold the lock ``.<name>.lock`` beside ``path`` (a run's folder or file) while the block runs, so that a second
    servo-press run on the same path is refused instead of both finishing and one result silently replacing the
    other. The lock is the operating system's (``flock``): a killed run leaves none held. Systems without
    ``fcntl`` (Windows) run unlocked."""
    from .errors import ServoPressError, one_line

    try:
        import fcntl
    except ImportError:  # pragma: no cover - not on Linux or macOS
        yield
        return
    path = Path(path)
    lock = path.parent / f".{_short(path.name)}.lock"
    created = [p for p in [path.parent, *path.parent.parents] if not p.exists()]
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, file_mode())
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            raise ServoPressError(f"--out {one_line(shown or str(path))}: another servo-press run (process {holder}) is writing it now: "
                                  "wait for it to finish, or choose another --out") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:  # not a lock file that its last holder removed after this run opened it: take a fresh one
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode("ascii"))
        yield
    finally:
        try:
            os.unlink(lock)
        except OSError:
            pass
        os.close(fd)
        for p in created:  # innermost first; only while empty: a run's result stays
            try:
                p.rmdir()
            except OSError:
                break


def _outside(exc: OSError, tmp: Path, out: Path) -> OSError:
    """``exc`` with a path inside the temporary folder shown as the same path inside ``--out``."""
    def mapped(name):
        if name is None:
            return None
        try:
            return str(out / Path(name).relative_to(tmp))
        except ValueError:
            return name
    return OSError(exc.errno, exc.strerror, mapped(exc.filename), None, mapped(exc.filename2))


@contextmanager
def output_folder(path, inputs, command: str):
    """Write a run's files into a temporary sibling folder and swap it in at the end.

    Yields the temporary folder (``.<name>.tmp-<pid>`` beside ``path``). When the block ends normally the folder,
    with its :data:`MARKER` naming ``command`` and the files, replaces ``path`` whole: the files of an earlier run
    of the same command there are gone, none is left stale. When it raises, the temporary folder is removed (with
    any parent folders this call created) and ``path`` is untouched. A second run on the same ``path`` while this
    one runs is refused (:func:`claim`). See :func:`check_output_folder` for the folders refused before anything
    runs; they are checked again just before the swap, for files added while the run ran.
    """
    from .errors import one_line

    out = check_output_folder(path, inputs, command)
    shown = one_line(str(path))
    parent = out.parent
    created = [p for p in [parent, *parent.parents] if not p.exists()]
    tmp = parent / f".{_short(out.name)}.tmp-{os.getpid()}"
    old = parent / f".{_short(out.name)}.old-{os.getpid()}"
    try:
        with claim(out, str(path)):
            check_replaceable(out, command, shown)  # again, now that no other run can write it
            if tmp.exists():
                shutil.rmtree(tmp)
            tmp.mkdir()  # mode 0777 less the umask, as any folder the user makes
            try:
                yield tmp
                write_marker(tmp, command)
            except OSError as exc:
                raise _outside(exc, tmp, out) from None
            check_replaceable(out, command, shown)
            if out.is_dir():
                os.replace(out, old)
                try:
                    os.replace(tmp, out)
                except BaseException:
                    os.replace(old, out)
                    raise
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(tmp, out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
        for p in created:  # innermost first
            try:
                p.rmdir()  # only while empty: a finished run's folder stays
            except OSError:
                break


def file_out(out) -> Path | None:
    """An output file path (urdf, experiment) as a Path, None if not given; an empty one is refused."""
    from .errors import ServoPressError

    if out is not None and not str(out).strip():
        raise ServoPressError(f"--out = {str(out)!r} is not valid: give an output file path, e.g. --out out/log.csv")
    return Path(out) if out is not None else None
