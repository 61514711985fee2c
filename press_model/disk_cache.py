"""What this package computes once per machine and keeps between processes: the folders, and the assembly sweeps.

Compiled kernels (:mod:`press_model.batch`) and assembly sweeps live under ``$XDG_CACHE_HOME/servo-press-twin``
(``~/.cache`` without it), else under the system's temporary folder. Nothing here is a result a user asked
for: deleting the folders costs one recomputation.

The full-turn assembly sweep (:func:`kinematics.assembly_sweep`) is a pure function of the press data and of
this package's code. Its own work is ~0.07 s of CPU, but its BDC/TDC search needs scipy.optimize, whose
import cost 0.33 s of CPU of the 1.6 s of a whole ``simulate`` (measured on a 2-core AMD EPYC). A sweep
that passed is stored in a file named by a hash of the press data, of the package's source and of the
numpy, scipy and Pinocchio versions, so that any change to one of them reads another file; a press that
fails is swept (and refused) every time. The batch model's per-crank-angle constants
(:func:`batch.build_batch_model`: about half a second of CPU of Pinocchio runs, before every Sobol run and
calibration) are kept the same way, by the press data and the motion and process force they were built for, and so
are the per-point model torque tables of a synthetic log or a designed run's profile (``calibration.synthetic.experiment``,
~1.2 s of CPU each on the per-point Pinocchio path), and so are a pendulum's turning knots (``planning.pendulum``: a
golden-section search of toppra's swings, ~1.5 s of CPU, by the press data, the job's settings and the planning
modules' source, :func:`source_hash`), and so are a synthetic log's grid kinematics (``kinematic_tables``:
positions, speeds, heights and force steps, by the press geometry alone, so that a new truth reruns only the dynamics), and so are a plan's knot kinematics (its path dynamics' ~60 %, by the geometry and the knots). Of each kind the most recently used files are kept, at most
:data:`FILES_KEPT` of them and :data:`BYTES_KEPT` bytes: a file read is used (its time refreshed), so a file that every
run reads outlives the one-off files of tests and other presses written after it (one full `reproduce` reads 13 batch
models; with a cap on the newest written, runs of two releases or a test suite in between evicted them all).
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .kinematics import Assembly
from press_io.outputs import atomic_write, versions
from .press_data import PressData, without_electrical
from .readers import data_fingerprint

FILES_KEPT = {"assembly": 256, "batch": 128, "torque": 256, "turning": 256, "kinematics": 128}  # files of each kind: a sweep is ~20 kB, a batch model ~2.4 MB at 1 deg (the design's 0.25-deg run family: 4 of ~10 MB), a torque table ~25 kB, a pendulum's turning knots ~0.5 kB, a synthetic log's grid kinematics ~0.3 MB at 0.25 deg
BYTES_KEPT = {"assembly": 16 << 20, "batch": 384 << 20, "torque": 16 << 20, "turning": 1 << 20, "kinematics": 64 << 20}  # and at most these bytes of each kind (the count bounds the many small files, the bytes the few large)
_ARRAYS = ("thetas", "qs")
_SCALARS = ("s_bdc", "stroke", "theta_bdc", "theta_tdc")


def cache_dirs(kind: str) -> list[Path]:
    """Folders for ``kind`` ('kernels', 'assembly'), the first that can be written is used."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return [Path(base) / "servo-press-twin" / kind, Path(tempfile.gettempdir()) / f"servo-press-twin-{kind}"]


def _code_hash() -> str:
    """Hash of this package's modules (the sweep's code and everything it reads the press with)."""
    return source_hash(str(Path(__file__).parent))


@functools.cache
def source_hash(folder: str) -> str:
    """Hash of the modules (``*.py``) in ``folder``: a key's ``code`` for a result computed by a package above this one
    (whose own modules this package cannot name)."""
    h = hashlib.sha256()
    for path in sorted(Path(folder).glob("*.py")):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def _versions() -> list[str]:
    installed = versions()  # read once a process (press_io.outputs)
    return [f"{name} {installed[name]}" for name in ("numpy", "scipy", "pin")]


def array_digest(a: np.ndarray) -> str:
    """A short hash of an array of doubles, for the keys of :func:`cached_arrays`."""
    return hashlib.sha256(np.ascontiguousarray(a, dtype=float).tobytes()).hexdigest()[:24]


def code_key() -> dict:
    """What every cached result depends on besides its inputs: this package's code and the numpy, scipy and Pinocchio
    versions (JSON-able)."""
    return {"code": _code_hash(), "versions": list(_versions())}


def press_key(press: PressData) -> dict:
    """What every cached result of a press depends on: its data (with any overrides; without [drive.electrical], which
    changes no mechanical result), the code, the versions."""
    return {"data": data_fingerprint(without_electrical(press.raw())), **code_key()}


def cached_arrays(kind: str, key: dict, names: tuple[str, ...], compute: Callable[[], dict]) -> dict[str, np.ndarray]:
    """The arrays ``names`` stored for ``key`` (JSON-able), else ``compute()`` (stored when it returns).

    An unreadable file, or one without every name, counts as absent; a cache folder that cannot be written
    only costs the computation again in the next process.
    """
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:24]
    name = f"{kind}_{digest}.npz"
    for folder in cache_dirs(kind):
        found = _read(folder / name, names)
        if found is not None:
            _touch(folder / name)
            return found
    arrays = compute()
    for folder in cache_dirs(kind):
        try:
            atomic_write(folder / name, lambda tmp: _write(tmp, {k: arrays[k] for k in names}), suffix=".npz")
        except OSError:
            continue
        _prune(folder, kind)
        break
    return arrays


def cached_assembly(press: PressData, sweep: Callable[[], Assembly]) -> Assembly:
    """The press's assembly sweep from the disk cache, else ``sweep()`` (stored when it returns)."""
    def arrays() -> dict:
        asm = sweep()
        return {k: np.asarray(getattr(asm, k)) for k in _ARRAYS + _SCALARS}

    z = cached_arrays("assembly", press_key(press), _ARRAYS + _SCALARS, arrays)
    return Assembly(**{k: np.array(z[k], dtype=float) for k in _ARRAYS}, **{k: float(z[k]) for k in _SCALARS})


def _write(path: str, arrays: dict) -> None:
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def _read(path: Path, names: tuple[str, ...]) -> dict[str, np.ndarray] | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in names}
    except (OSError, KeyError, ValueError, TypeError, EOFError):
        return None


def _touch(path: Path) -> None:
    """Mark ``path`` used now (its modification time, which :func:`_prune` ranks by); a file that cannot be touched (a
    read-only cache, a file another process just pruned) is only pruned sooner."""
    try:
        os.utime(path)
    except OSError:
        pass


def _prune(folder: Path, kind: str) -> None:
    """Keep the most recently used files of ``kind`` (written or read, :func:`_touch`): at most FILES_KEPT[kind] of them
    and BYTES_KEPT[kind] bytes, the most recent always."""
    try:  # another process may prune the same folder at the same time: a file gone is fine
        stats = []
        for p in folder.glob(f"{kind}_*.npz"):
            try:
                st = p.stat()
            except FileNotFoundError:
                continue
            stats.append((st.st_mtime, st.st_size, p))
        stats.sort(key=lambda t: t[0], reverse=True)
        total = 0
        for rank, (_, size, p) in enumerate(stats):
            total += size
            if rank >= FILES_KEPT[kind] or (rank > 0 and total > BYTES_KEPT[kind]):
                p.unlink(missing_ok=True)
    except OSError:
        pass
