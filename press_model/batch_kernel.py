"""The compiled friction fixed point of :mod:`batch`: a numba kernel generated for the press's loop structure,
its disk cache (compiled by one process while the others wait), and the thread handling around it (one BLAS thread
while it runs, Python threads sharing its blocks of sets).

:func:`fixed_point_numba` is the one entry; it gives the same results as the numpy fixed point of
:func:`batch.evaluate_chunk` (to rounding of fused multiply-adds, see below) for the constants of a
:class:`batch.BatchModel`.
"""
from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

try:  # optional: compiles the friction fixed point (about 10x faster than the numpy path)
    import numba
except ImportError:  # pragma: no cover
    numba = None

from . import kernel_ir
from .disk_cache import cache_dirs
from .jit import compile_lock, compiling
from .kernel_ir import work_rows
from press_io.outputs import atomic_write_text

# ``BatchModel`` in the annotations is press_model.batch's, named not imported: batch imports this module.

# --- the compiled fixed point ----------------------------------------------------------------------
#
# The kernel is generated for the press's loop structure. Per crank angle it takes the parameter sets in
# blocks of LANES and keeps every per-set quantity in one work array, row-major with the lane last
# (w[row * LANES + lane]): the loops over the lanes then touch consecutive doubles at compile-time offsets
# and LLVM turns them into packed SIMD instructions (``python scripts/bench_batch.py --cold`` counts them in the
# assembly: vfmadd...pd and vsqrtpd on ymm for AVX2, on zmm for AVX-512). The setup (the friction-free outputs of
# the block, one small matrix product feats @ base_pt[p], a loop over its output columns) and each fixed-point
# pass run over all lanes of the block; a lane that
# has converged keeps its reactions (a select, not a branch) while the others finish, so each set sees
# exactly the passes it would see alone. The loop-force coefficients coul_lam[p] and coul_tau[p] are
# read into scalars once per crank angle, and the constant +-1 matrix G is written out. The loops are Python for
# numba, their bodies LLVM IR written by kernel_ir (numba typed and lowered ~1,500 operations one by one: ~18 s of CPU
# of a first compile, now ~2 s, the same machine code's results to the bit). fastmath 'contract'
# lets LLVM fuse a * b + c into one FMA (one rounding instead of two): the torques move by ~1e-14 of the
# peak against the unfused sums, and every run gives the same bytes.

# parameter sets per block: two SIMD registers of doubles, one per half of the block whose passes interleave
# (see _kernel_source), so 8 for AVX2 and 16 for AVX-512. Measured (one thread, 1024 sets, the reference press,
# old and new timed in turn, load average 4.7), AVX2 code: 0.0695 ms of CPU per cycle with 8 lanes, 0.0674 with 16
# (but small batches, a calibration's population or a design's draws, pad more), against 0.0933 before the halves
# interleaved (8 lanes); AVX-512 code 0.0499 with 16, 0.0532 with 8, against 0.0556.
_AVX512_CPUS = ("skylake-avx512", "cascadelake", "cooperlake", "cannonlake", "icelake", "tigerlake", "rocketlake",
                "sapphirerapids", "emeraldrapids", "graniterapids", "diamondrapids", "znver4", "znver5", "x86-64-v4")


def _vector_doubles() -> int:
    """Doubles in one SIMD register of the CPU numba compiles for: 8 with AVX-512, else 4 (AVX2).

    numba's target: the host, or ``NUMBA_CPU_NAME`` with the host's features, or with ``NUMBA_CPU_FEATURES``
    (empty: the named CPU's own, scripts/cpu_targets.py)."""
    if numba is None:  # pragma: no cover
        return 4
    import llvmlite.binding as ll
    from numba.core import config

    if config.CPU_FEATURES is None:
        return 8 if ll.get_host_cpu_features().get("avx512f") else 4
    if config.CPU_FEATURES:
        return 8 if "+avx512f" in config.CPU_FEATURES.split(",") else 4
    return 8 if (config.CPU_NAME or ll.get_host_cpu_name()).startswith(_AVX512_CPUS) else 4


LANES = 2 * _vector_doubles()
GAMMA_MAX = 2.0  # bound of the Anderson(1) weight: |gamma| = 2 is a contraction rate of 2/3, far slower than this press's ~0.1

_KERNELS: dict = {}
_CALLED: set = set()  # the kernels called at least once in this process
_LOCKS: dict = {}  # kernel -> the lock file beside its source in the cache folder (None: no folder)


def _kernel_source(G: np.ndarray, r: int, n_feat: int, lanes: int = LANES, cache: bool = True) -> str:
    """Python source of the fixed-point kernel for r reactions (the last has one component) and G, after its imports:
    the intrinsics of its loop bodies (:func:`kernel_ir.kernel_intrinsics`) and ``kern_blocks`` (numba's disk cache if
    ``cache``).

    Arguments of the generated ``kern_blocks``: sets (B / lanes, (4 + n_feat) * lanes), per block of lanes the
    rows c_r, c_s, mu_r, mu_s and the n_feat features, lane last; base_pt, visc_pt, coul_lam, coul_tau of
    :class:`BatchModel`; tol, max_it; outputs tau (B, n) in N m, iters (B, n) and done (B, n), one row per
    set (the padded sets too); blk_start, blk_stop: the blocks of lanes this call fills (each thread of
    :func:`fixed_point_numba` its own range, so its own rows).
    """
    n_rows = G.shape[0]  # reaction columns 1 .. 2r - 1
    if lanes % 2:
        raise ValueError(f"the kernel's lanes come in two halves: {lanes} is odd")
    rw = work_rows(n_rows, r, n_feat)
    G_rows = tuple(tuple(float(c) for c in row) for row in G)
    names = ("point_constants", "setup_lane", "base_row", "column_lane", "start_lane", "one_pass", "finish_lane")
    # the loops stay Python for numba; their bodies are kernel_ir's intrinsics. Every loop over the lanes has a run-time
    # trip count (``lanes``, = LANES): with a literal LLVM unrolls it fully and then does not vectorise it. Everything
    # the lanes read or write sits in w at compile-time offsets or in scalars, so LLVM needs no run-time alias checks
    L = [f"_ir = kernel_intrinsics({G_rows!r}, {r}, {n_feat}, {lanes}, {GAMMA_MAX!r})",
         "\n".join(f"{name} = _ir[{name!r}]" for name in names),
         "",
         "",
         f"@numba.njit(error_model='numpy', fastmath={{'contract'}}, nogil=True, cache={cache})",
         "def kern_blocks(sets, lanes, base_pt, visc_pt, coul_lam, coul_tau, tol, max_it, tau, iters, done, blk_start, blk_stop):",
         f"    w = np.empty({rw['rows'] * lanes})",
         "    outputs = (tau, iters, done)",
         "    for p in range(base_pt.shape[0]):",
         "        consts = point_constants(visc_pt, coul_lam, coul_tau, p)",  # read once per crank angle
         "        for blk in range(blk_start, blk_stop):",
         f"            for i in range({(4 + n_feat) * lanes}):",
         f"                w[{rw['IN'] * lanes} + i] = sets[blk, i]",
         "            for l in range(lanes):",
         "                setup_lane(w, l, max_it, consts)",
         # the setup (features @ base) a loop over the output columns, summed in the order of the one-set loop:
         # written out per (feature, column) product it took LLVM 49 s of CPU to compile (5.8 s so, the same bytes)
         f"            for k in range({n_rows + 1}):",
         "                row = base_row(base_pt, p, k)",
         "                for l in range(lanes):",
         "                    column_lane(w, l, k, row)",
         "            for l in range(lanes):",
         "                start_lane(w, l, consts)",
         "            it = 2",
         "            while it <= max_it:",
         # one pass over each half of the block at once (see kernel_ir): two independent dependency chains in the
         # loop body for the CPU to overlap. Measured on AVX2 (one thread): 0.0695 ms of CPU per cycle against 0.0933
         # for the whole block in one chain; every value is the same to the bit (tests)
         "                for l in range(lanes // 2):",
         "                    one_pass(w, l, it, tol, consts)",
         "                n_done = 0",
         "                for l in range(lanes):",
         f"                    n_done += 1 if w[{rw['DN'] * lanes} + l] != 0.0 else 0",
         "                if n_done == lanes:",
         "                    break",
         "                it += 1",
         "            for l in range(lanes):",
         f"                finish_lane(w, l, consts, outputs, blk * {lanes}, p)"]
    return "\n".join(L) + "\n"


def kernel_text(G: np.ndarray, r: int, n_feat: int, lanes: int = LANES, cache: bool = True) -> str:
    """The generated kernel module's whole text (see :func:`_kernel_source`).

    The loop is compiled serial, and Python threads share the blocks (nogil): numba's parfor passes over the whole
    unrolled loop took 41 s on first use, against 21 s with a small prange driver over ranges of blocks, and that
    driver another 4.3 s of CPU (AVX2, load 9) against none with threads, for the same run time. The loop bodies' IR
    comes from kernel_ir.py, not from this text: its digest in the text makes a changed emitter a new file, which numba
    compiles anew (its disk cache is keyed by the file alone)."""
    return ("# generated by press_model.batch_kernel; do not edit\n"
            "import numba\nimport numpy as np\n\nfrom press_model.kernel_ir import kernel_intrinsics\n\n"
            f"# the loop bodies' emitter: {_emitter_digest()}\n" + _kernel_source(G, r, n_feat, lanes, cache))


def _emitter_digest() -> str:
    """The first 16 hex digits of kernel_ir.py's SHA-256."""
    return hashlib.sha256(Path(kernel_ir.__file__).read_bytes()).hexdigest()[:16]


def _compiled_kernel(bm: BatchModel, lanes: int = LANES):
    """The kernel for this press's structure and ``lanes`` sets per block, compiled once per process and cached on disk
    by numba.

    Returns ``kern_blocks``, the loop over a range of blocks of sets, which releases the GIL: threads run it on ranges
    of their own.
    """
    shape_key = (bm.G.tobytes(), bm.G.shape, bm.n_rev + 1, len(bm.feature_keep), lanes)
    kern = _KERNELS.get(shape_key)  # generating the source costs ~2 ms: not once per chunk
    if kern is not None:
        return kern
    text = kernel_text(bm.G, bm.n_rev + 1, len(bm.feature_keep), lanes, cache=True)
    key = hashlib.sha256(text.encode()).hexdigest()[:16]
    for folder in cache_dirs("kernels"):  # a file lets numba keep the machine code between processes
        try:
            folder.mkdir(parents=True, exist_ok=True)
            path, lock = folder / f"friction_{key}.py", folder / f"friction_{key}.lock"
            # under the lock: numba stamps its cache with the file's modification time, so a second process writing
            # the same file while the first compiles would make the first one's cache stale for it
            with compile_lock(lock, "the friction kernel"):
                if not path.is_file() or path.read_text(encoding="utf-8") != text:
                    atomic_write_text(path, text)
                name = f"_servo_press_friction_{key}"
                spec = importlib.util.spec_from_file_location(name, path)
                module = importlib.util.module_from_spec(spec)
                sys.modules[name] = module  # numba's cache finds the module again by name
                spec.loader.exec_module(module)
            kern = module.kern_blocks
            _LOCKS[kern] = lock
            break
        except OSError:
            continue
    else:  # no writable folder: compile without the disk cache
        namespace = {}
        source = kernel_text(bm.G, bm.n_rev + 1, len(bm.feature_keep), lanes, cache=False)
        exec(compile(source, f"<friction kernel {key}>", "exec"), namespace)  # noqa: S102 (our own generated source)
        kern = namespace["kern_blocks"]
        _LOCKS[kern] = None
    _KERNELS[shape_key] = kern
    return kern


def _announce_compile(folder: Path | None) -> None:
    # the one long silence of a first run: say what it is rather than look hung; the time follows once measured
    where = f"cached in {folder} for the next runs" if folder else "no writable cache folder: again in every process"
    print(f"compiling the friction kernel for this press's loop structure, once ({where}) ...", file=sys.stderr, flush=True)


def _index_exists(dispatcher) -> bool:
    """Whether numba's cache index of ``dispatcher`` exists (its disk cache holds machine code for some target)."""
    try:
        return os.path.isfile(dispatcher._cache._cache_file._index_path)
    except AttributeError:  # numba's internals moved: say nothing rather than guess
        return True


def compile_or_load(dispatcher, args, lock: Path | None) -> None:
    """Compile ``dispatcher`` (a numba function with ``cache=True``) for the types of ``args``, or load it from numba's
    disk cache, inside :func:`jit.compiling` on ``lock``: only one process compiles what several need at once."""
    signature = tuple(numba.typeof(a) for a in args)
    with compiling(lock, "the friction kernel"):
        if lock is None or not _index_exists(dispatcher):
            _announce_compile(None if lock is None else lock.parent)
        dispatcher.compile(signature)


def _first_call(kern, args, lock: Path | None) -> None:
    """Before the first call of the kernel ``kern`` in this process: compiles or loads it (:func:`compile_or_load`),
    and says how long numba took if it compiled it (rather than load it from its disk cache), measured, not guessed."""
    t0 = time.perf_counter()
    compile_or_load(kern, args, lock)
    seconds = time.perf_counter() - t0
    _CALLED.add(kern)
    if sum(kern.stats.cache_misses.values()):
        print(f"compiled the friction kernel in {seconds:.1f} s", file=sys.stderr, flush=True)


_BLAS = []  # the threadpoolctl controller, made on first use (after numpy's BLAS is loaded)


def _one_blas_thread():
    """Context in which BLAS runs on one thread, so that its idle workers do not compete with numba's.

    On 2 cores a parallel numba kernel beside OpenBLAS's spinning threads ran at half speed (library_facts.md).
    Without threadpoolctl (a declared dependency), a no-op.
    """
    if not _BLAS:
        try:
            from threadpoolctl import ThreadpoolController
            _BLAS.append(ThreadpoolController())
        except ImportError:  # pragma: no cover
            _BLAS.append(None)
    return contextlib.nullcontext() if _BLAS[0] is None else _BLAS[0].limit(limits=1, user_api="blas")


def fixed_point_numba(bm: BatchModel, feats, cr, cs, mu_r, mu_s, lanes: int = LANES):
    """Friction fixed point of B sets (features ``feats`` (B, F), friction rows (B,)) in the compiled kernel;
    returns tau_d (B, n) in N m, iterations (B, n) and converged flags (B, n), as the numpy path. ``lanes``: sets per
    block (even; the same results for any, tests)."""
    B, n = len(feats), bm.n_points
    Bp = -(-B // lanes) * lanes  # pad the last block with copies of the last set
    rows = np.empty((Bp, 4 + feats.shape[1]))
    rows[:B, :4] = np.column_stack([cr, cs, mu_r, mu_s])
    rows[:B, 4:] = feats
    rows[B:] = rows[B - 1]
    sets = np.ascontiguousarray(rows.reshape(Bp // lanes, lanes, -1).transpose(0, 2, 1)).reshape(Bp // lanes, -1)
    tau = np.empty((Bp, n))
    iters = np.empty((Bp, n), dtype=np.int64)
    done = np.empty((Bp, n), dtype=np.bool_)
    kern = _compiled_kernel(bm, lanes)
    args = (sets, lanes, bm.base_pt, bm.visc_pt, bm.coul_lam, bm.coul_tau, bm.friction_tolerance, bm.friction_max_iterations,
            tau, iters, done)
    edges = [int(e) for e in _block_edges(Bp // lanes, n)]
    with _one_blas_thread():
        if kern not in _CALLED:
            _first_call(kern, (*args, edges[0], edges[1]), _LOCKS[kern])
        # the kernel releases the GIL: one range of blocks per thread, the first on this one. Threads started per call
        # (~0.1 ms, against ~15 ms of a 256-set chunk) rather than a pool: a forked worker then finds none broken
        others = [threading.Thread(target=kern, args=(*args, edges[t], edges[t + 1])) for t in range(1, len(edges) - 1)]
        for thread in others:
            thread.start()
        kern(*args, edges[0], edges[1])
        for thread in others:
            thread.join()
    return tau[:B], iters[:B], done[:B]


MIN_BLOCK_ANGLES = 1024  # blocks of LANES sets times crank angles per thread (~0.6 us each): below, fewer threads


def _block_edges(blocks: int, n: int) -> np.ndarray:
    """Edges of contiguous ranges of blocks of sets, one range per thread (numba's thread count, see
    numba.set_num_threads), fewer when the work would not pay for waking a thread. Split by sets, not by
    crank angles: each thread then writes whole rows of the outputs, and no cache line goes back and forth
    between the cores (split by angles, 2 threads ran 1.65x, not 2x, one thread's speed)."""
    threads = max(1, min(numba.get_num_threads(), blocks, (n * blocks) // MIN_BLOCK_ANGLES))
    return np.array([round(i * blocks / threads) for i in range(threads + 1)], dtype=np.int64)
