"""Writing results: atomic CSV and JSON files that record what produced them."""
from __future__ import annotations

import csv
import ctypes
import errno
import functools
import io
import json
import math
import os
import platform
import shutil
import stat
import sys
import tempfile
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from typing import Callable

import numpy as np

from .run_record import MARKER, describe, foreign, read_marker, walk  # noqa: F401 (MARKER, read_marker: this module's API)


def file_mode() -> int:
    """The mode a plainly created file gets (0666 less the umask): mkstemp's temp files are 0600, and a
    result renamed into place should be as readable as any other file the user writes."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def atomic_write(path: Path, write: Callable[[str], None], suffix: str = "") -> None:
    """Make ``path`` by ``write(temporary_path)`` in the same folder, then rename it into place, so that a
    reader never sees a half-written file and a failed write leaves nothing behind. ``path`` a link: the file it
    points to is written, the link stays (a rename would put a file in the link's place)."""
    path = Path(path)
    if path.is_symlink():
        path = Path(os.path.realpath(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        os.chmod(tmp, file_mode())
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        if exc.filename is None:  # a write that failed (a full disk) names no file: the one being written is ``path``
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def atomic_write_text(path: Path, text: str) -> None:
    """Write text (UTF-8, LF line ends) atomically; see :func:`atomic_write`."""
    atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8", newline="\n"))


_PACKAGES = ("servo-press-twin", "pin", "numpy", "scipy", "SALib", "toppra", "matplotlib")


def versions() -> dict:
    """Versions of Python and of every package that shapes a result (a new dict each call)."""
    return dict(_installed_versions())


@functools.cache  # the installed packages do not change in a process; the metadata look-ups cost ~10 ms of CPU a call
def _installed_versions() -> tuple[tuple[str, str], ...]:
    out = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return tuple(out.items())


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
# Every run folder holds MARKER, written last: the command that wrote the folder, the size and SHA-256 of every file
# it wrote and the folders it made (press_io.run_record). A rerun of the same command replaces the folder whole
# when all in it is as recorded; anything else in it (another command's result, a file the user added or changed)
# is refused, never deleted.
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
    """Every file under ``folder`` (subfolders included, links not followed), as sorted relative POSIX paths, the
    MARKER left out."""
    return walk(folder)[0]


def write_marker(folder: Path, command: str) -> None:
    """Record in ``folder`` that ``command`` wrote it, with every file it holds now (its size and SHA-256) and every
    folder (see :data:`MARKER`)."""
    write_json(Path(folder) / MARKER, describe(folder, command))


def _listed(names: list[str]) -> str:
    from .errors import one_line

    return one_line(", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else ""))


def check_replaceable(out: Path, command: str, shown: str) -> None:
    """Refuse an existing non-empty folder that ``command`` may not replace whole: one without a MARKER (the user's
    folder, or a result of an earlier version that did not record its files), another command's, one whose record
    has no sizes and hashes (an earlier version's: its files cannot be told from changed ones), and one holding a
    file or folder the record does not list or a file whose size or SHA-256 is not the recorded one."""
    from .errors import ServoPressError, one_line

    try:
        names = sorted(p.name for p in out.iterdir())
    except (FileNotFoundError, NotADirectoryError):
        return
    if not names:
        return
    marker = read_marker(out)
    if marker is None:
        if (out / MARKER).is_file():  # a record that is there but unreadable: cut short or edited, not an earlier version's
            raise ServoPressError(f"--out {shown}: its {MARKER} (the record of the files a servo-press run wrote there) is not "
                                  "a record servo-press can read (cut short, e.g. by a full disk, or edited), so a rerun cannot "
                                  "tell the run's files from yours and deletes none of them: delete or move the folder yourself, "
                                  "or choose another --out")
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
    if marker["hashes"] is None:
        raise ServoPressError(f"--out {shown}: its {MARKER} lists files without their sizes and SHA-256 (an earlier servo-press "
                              "version wrote it), so a rerun cannot tell them from files changed since and deletes none of them: "
                              "move the folder yourself, or choose another --out")
    extra, changed = foreign(out, marker)
    if extra:
        raise ServoPressError(f"--out {shown}: holds files that servo-press did not write there ({_listed(extra)}); a run replaces "
                              "its output folder whole: move them out, or choose another --out")
    if changed:
        raise ServoPressError(f"--out {shown}: {_listed(changed)} {'was' if len(changed) == 1 else 'were'} not written by servo-press "
                              f"or changed since (size or SHA-256 not the one in its {MARKER}); a run replaces its output folder "
                              f"whole: move {'it' if len(changed) == 1 else 'them'} out, or choose another --out")


def refuse_overwrite_input(out: Path, inputs) -> None:
    """Refuse an output path that is one of the user's input files."""
    from .errors import ServoPressError

    for i in inputs:
        if i is not None and Path(str(i)).exists() and Path(str(i)).resolve() == Path(out).resolve():
            raise ServoPressError(f"--out {out} is the input file {i}: choose another output path (inputs are never overwritten)")


def check_output_folder(path, inputs=(), command: str | None = None) -> Path:
    """Refuse an output folder that the run could not replace safely; returns it as a Path.

    Refused: an empty path (it would mean the current folder), an existing file, a link to nothing, a folder that is
    or holds the current folder or one of ``inputs`` (replacing it would delete them), a folder inside another run's
    result folder (one holding :data:`MARKER`), and a non-empty folder that ``command`` may not replace (:func:`check_replaceable`; ``command`` None: only the checks before it).

    ``path`` a symbolic link to a folder: returns the folder it points to, which the run then writes as its result;
    the link stays as the user made it (replacing the link by a folder would leave the folder it pointed to stale).
    """
    from .errors import ServoPressError, one_line

    text = str(path) if path is not None else ""
    if not text.strip():
        raise ServoPressError(f"--out = {text!r} is not valid: give an output folder, e.g. --out out/run1 "
                              "(an empty path would mean the current folder)")
    out = Path(text)
    shown = one_line(text)
    try:
        if out.is_symlink():
            target = Path(os.path.realpath(out))
            if not target.exists():
                raise ServoPressError(f"--out {shown}: is a symbolic link to {one_line(target)}, which does not exist: make that "
                                      "folder, or choose another --out")
            out = target
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
    for folder in resolved.parents:  # a folder inside a run's result would be deleted (or block) its rerun
        if (folder / MARKER).is_file():
            marker = read_marker(folder)
            whose = f"`servo-press {one_line(marker['command'])}`" if marker is not None else "a servo-press run"
            raise ServoPressError(f"--out {shown}: lies inside {one_line(folder)}, the result folder of {whose}, which a rerun "
                                  "of that command replaces whole (and refuses while a folder it did not write is in it): "
                                  "choose an --out outside it")
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


LOCK_SUFFIX = ".servo-press.lock"  # beside --out: a name no user's file plausibly has
_LOCK_TAG = b"servo-press lock of process "  # a lock file's first bytes, then the holder's pid: what makes it ours


def lock_path(path) -> Path:
    """The lock of a run's folder or file ``path``: ``.<name>.servo-press.lock`` beside it."""
    path = Path(path)
    return path.parent / f".{_short(path.name)}{LOCK_SUFFIX}"


def _ours(fd: int) -> bool:
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_size > 64:
        return False
    return os.pread(fd, 64, 0).startswith(_LOCK_TAG)


def _same_file(fd: int, path: Path) -> bool:
    try:
        return os.fstat(fd).st_ino == os.stat(path, follow_symlinks=False).st_ino
    except FileNotFoundError:
        return False


def _new_lock(lock: Path, fcntl) -> int | None:
    """A new lock file at ``lock``, whole and held from its first moment (written beside it, locked, then linked to its
    name, which fails if the name exists): its descriptor, or None when another run made one first."""
    part = lock.with_name(f"{lock.name}.{os.getpid()}")
    fd = os.open(part, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, file_mode())
    try:
        os.write(fd, _LOCK_TAG + f"{os.getpid()}\n".encode("ascii"))
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.link(part, lock)
        return fd
    except BaseException as exc:
        os.close(fd)
        if isinstance(exc, FileExistsError):
            return None
        raise
    finally:
        os.unlink(part)


def _remove_dead_parts(lock: Path) -> None:
    """Remove the lock files that runs killed inside :func:`_new_lock` left half made (``<lock>.<pid>``, ours by their
    first bytes, their process gone). Called with the lock held."""
    try:
        entries = list(os.scandir(lock.parent))
    except OSError:
        return
    for e in entries:
        pid = e.name[len(lock.name) + 1:]
        if not (e.name.startswith(lock.name + ".") and pid.isdigit() and e.is_file(follow_symlinks=False)) or _alive(int(pid)):
            continue
        try:
            with open(e.path, "rb") as fh:
                if fh.read(64).startswith(_LOCK_TAG):
                    os.unlink(e.path)
        except OSError:
            pass


@contextmanager
def claim(path, shown: str | None = None):
    """Hold the lock ``.<name>.servo-press.lock`` beside ``path`` (a run's folder or file) while the block runs, so
    that a second servo-press run on the same path is refused instead of both finishing and one result silently
    replacing the other. The lock is the operating system's (``flock``): a killed run leaves none held, and its lock
    file, ours by its first bytes, is taken by the next run. A file of that name that servo-press did not make is
    refused, never written or removed. Systems without ``fcntl`` (Windows) run unlocked."""
    from .errors import ServoPressError, one_line

    try:
        import fcntl
    except ImportError:  # pragma: no cover - not on Linux or macOS
        yield
        return
    path = Path(path)
    lock = lock_path(path)
    shown_ = one_line(shown or str(path))
    created = [p for p in [path.parent, *path.parent.parents] if not p.exists()]
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = None
    try:
        while fd is None:
            try:
                fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
            except FileNotFoundError:
                try:
                    fd = _new_lock(lock, fcntl)
                except OSError as exc:  # a read-only folder, a full disk: the user's folder, not our lock file's name
                    raise OSError(exc.errno, exc.strerror, str(path.parent)) from None
                continue
            except OSError:  # a link, or a name the system will not open: not a lock servo-press made
                fd = -1
            if fd < 0 or not _ours(fd):
                if fd >= 0:
                    os.close(fd)
                fd = None
                raise ServoPressError(f"--out {shown_}: {one_line(lock)} is in the way: a file servo-press did not make (its lock "
                                      "while it writes --out has that name): move that file, or choose another --out")
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.pread(fd, 64, 0)[len(_LOCK_TAG):].decode("ascii", "replace").strip() or "?"
                os.close(fd)
                fd = None
                raise ServoPressError(f"--out {shown_}: another servo-press run (process {one_line(holder)}) is writing it now: "
                                      "wait for it to finish, or choose another --out") from None
            # held: the lock of a run that was killed (or one its holder is removing now): take it over by a fresh one
            if _same_file(fd, lock) and _ours(fd):
                os.unlink(lock)
            os.close(fd)
            fd = None
        _remove_dead_parts(lock)
        yield
    finally:
        if fd is not None:
            if _same_file(fd, lock):  # ours, made above: removed while still held
                os.unlink(lock)
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


_RENAME_EXCHANGE = 2  # renameat2(2) flag, <linux/fs.h>
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap the folders ``a`` and ``b`` in one step (Linux ``renameat2`` with RENAME_EXCHANGE): True when done, False
    where the system or its file system cannot (the caller then renames twice)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = (ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint)
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EPERM):
        return False
    raise OSError(err, os.strerror(err), str(a), None, str(b))


def _remove_run_folder(folder: Path) -> None:
    """Remove a temporary (or replaced) run folder, its MARKER last: a removal cut short by SIGKILL still leaves a
    folder that the next run knows for one of ours (:func:`_remove_dead_temporaries`)."""
    try:
        names = os.listdir(folder)
    except FileNotFoundError:
        return
    for name in names:
        if name == MARKER:
            continue
        p = folder / name
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            try:
                p.unlink()
            except FileNotFoundError:
                pass
    try:
        (folder / MARKER).unlink()
    except FileNotFoundError:
        pass
    shutil.rmtree(folder, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _remove_dead_temporaries(out: Path) -> list[Path]:
    """Remove the temporary siblings ``.<name>.tmp-<pid>`` of ``out`` left by runs that were killed (SIGKILL, a power
    cut): only those whose process is gone and that hold a servo-press MARKER (a folder of the user's that merely has
    such a name stays). Called under the lock of ``out``. Returns the folders removed."""
    prefix = f".{_short(out.name)}.tmp-"
    removed = []
    try:
        entries = list(os.scandir(out.parent))
    except OSError:
        return removed
    for e in entries:
        pid = e.name[len(prefix):]
        if not (e.name.startswith(prefix) and pid.isdigit() and e.is_dir(follow_symlinks=False)):
            continue
        if int(pid) == os.getpid() or _alive(int(pid)) or read_marker(Path(e.path)) is None:
            continue
        _remove_run_folder(Path(e.path))
        removed.append(Path(e.path))
    return removed


@contextmanager
def output_folder(path, inputs, command: str):
    """Write a run's files into a temporary sibling folder and swap it in at the end.

    Yields the temporary folder (``.<name>.tmp-<pid>`` beside ``path``, marked as servo-press's from the start).
    When the block ends normally the folder, with its :data:`MARKER` naming ``command`` and every file and folder,
    replaces ``path`` whole, in one step where the system can (``renameat2``): the files of an earlier run of the same
    command there are gone, none is left stale. When it raises (an error, Ctrl-C, SIGTERM), the temporary folder is
    removed (with any parent folders this call created) and ``path`` is untouched; the swap itself is never cut in
    two (:func:`press_io.interrupts.deferred`). A second run on the same ``path`` while this one runs is refused
    (:func:`claim`); the temporary folders of killed runs are removed first. See :func:`check_output_folder` for the
    folders refused before anything runs; they are checked again just before the swap, for files added or changed
    while the run ran. ``path`` a link to a folder: that folder is the result, the link stays.
    """
    from .errors import one_line
    from .interrupts import deferred

    out = check_output_folder(path, inputs, command)
    shown = one_line(str(path))
    parent = out.parent
    created = [p for p in [parent, *parent.parents] if not p.exists()]
    tmp = parent / f".{_short(out.name)}.tmp-{os.getpid()}"
    try:
        with claim(out, str(path)):
            check_replaceable(out, command, shown)  # again, now that no other run can write it
            _remove_dead_temporaries(out)
            if tmp.exists():
                _remove_run_folder(tmp)
            tmp.mkdir()  # mode 0777 less the umask, as any folder the user makes
            write_json(tmp / MARKER, {"what": f"servo-press run folder being written by process {os.getpid()}; a later run on "
                                      "this output removes it once that process is gone", "command": command,
                                      "files": [], "folders": []})
            try:
                yield tmp
                write_marker(tmp, command)
            except OSError as exc:
                raise _outside(exc, tmp, out) from None
            with deferred():  # the swap, whole: a signal now is raised after it
                check_replaceable(out, command, shown)
                if not out.is_dir():
                    os.replace(tmp, out)
                elif not _exchange(tmp, out):  # no one-step swap here: two renames
                    old = parent / f".{_short(out.name)}.old-{os.getpid()}"
                    os.replace(out, old)
                    try:
                        os.replace(tmp, out)
                    except BaseException:
                        os.replace(old, out)
                        raise
                    os.replace(old, tmp)  # the earlier result, removed below under the temporary name
    finally:
        with deferred():  # removed whole, so that no half-removed folder is left
            if tmp.exists():
                _remove_run_folder(tmp)
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
