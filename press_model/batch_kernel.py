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

from .disk_cache import cache_dirs
from .jit import compile_lock
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
# read into scalars once per crank angle, and the constant +-1 matrix G is written out. fastmath 'contract'
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


def _terms(coefs, names) -> str:
    out = []
    for c, name in zip(coefs, names):
        if c == 0.0:
            continue
        out.append(f" + {name}" if c == 1.0 else f" - {name}" if c == -1.0 else f" + {float(c)!r} * {name}")
    return "".join(out)


def _kernel_source(G: np.ndarray, r: int, n_feat: int, lanes: int = LANES) -> str:
    """Python source of the fixed-point kernel for r reactions (the last has one component) and G.

    Arguments of the generated ``kern_blocks``: sets (B / lanes, (4 + n_feat) * lanes), per block of lanes the
    rows c_r, c_s, mu_r, mu_s and the n_feat features, lane last; base_pt, visc_pt, coul_lam, coul_tau of
    :class:`BatchModel`; tol, max_it; outputs tau (B, n) in N m, iters (B, n) and done (B, n), one row per
    set (the padded sets too); blk_start, blk_stop: the blocks of lanes this call fills (each thread of
    :func:`fixed_point_numba` its own range, so its own rows).
    """
    n_rows, n_lam = G.shape  # reaction columns 1 .. 2r - 1
    K = n_rows + 2  # output columns: tau_d, the 2r - 1 reaction columns, the zero column
    comp = [(1 + j, 1 + r + j if 1 + r + j <= n_rows else None) for j in range(r)]
    Lw, Lh = lanes, lanes // 2  # the block's lanes, in two halves (see one_pass)
    if lanes % 2:
        raise ValueError(f"the kernel's lanes come in two halves: {lanes} is odd")
    # rows of the work array
    C = 0  # C + k: output column k of the set without Coulomb friction (viscous friction included)
    NR = K  # NR + j: reaction magnitude j (the fixed point's state)
    DN, IT = K + r, K + r + 1  # converged flag, iterations
    IN = K + r + 2  # IN + i: input row i of the block (c_r, c_s, mu_r, mu_s, then the features)
    MR, MS = IN + 2, IN + 3
    FP = IN + 4 + n_feat  # FP + j: the previous pass's residual F(x) - x (Anderson acceleration)
    GP = FP + r  # GP + j: the previous pass's F(x)
    rows = GP + r

    def at(row):
        return f"w[{row * Lw} + l]"

    def norm(val, j):
        x, y = comp[j]
        return f"math.sqrt({val(x)} * {val(x)} + {val(y)} * {val(y)})" if y else f"abs({val(x)})"

    def visc(k):
        return f"{at(IN)} * v0_{k} + {at(IN + 1)} * v1_{k}"

    mu = [at(MR)] * (r - 1) + [at(MS)]
    # the loop over the lanes has a run-time trip count (``lanes``, = LANES): with a literal LLVM unrolls it
    # fully and then does not vectorise it. Everything the lanes read or write sits in w or in scalars, so
    # LLVM needs no run-time alias checks.
    L = ["def kern_blocks(sets, lanes, base_pt, visc_pt, coul_lam, coul_tau, tol, max_it, tau, iters, done, blk_start, blk_stop):",
         f"    n_in = {(4 + n_feat) * Lw}",
         f"    GAMMA_MAX = {GAMMA_MAX!r}",
         f"    w = np.empty({rows * Lw})",
         "    for p in range(base_pt.shape[0]):"]
    L += [f"        v{i}_{k} = visc_pt[p, {i}, {k}]" for i in range(2) for k in range(K - 1)]
    L += [f"        q{c}_{i} = coul_lam[p, {c}, {i}]" for c in range(n_lam) for i in range(r)]
    L += [f"        t{j} = coul_tau[p, {j}]" for j in range(r)]
    L += ["        for blk in range(blk_start, blk_stop):",
          f"            b0 = blk * {Lw}",
          "            for i in range(n_in):",
          f"                w[{IN * Lw} + i] = sets[blk, i]",
          "            for l in range(lanes):",
          f"                {at(DN)} = 0.0",
          f"                {at(IT)} = max_it + 1.0"]
    # the setup, summed in the order of the one-set loop: viscous part, then the features one by one
    # (the last output column, zero, is never read). A loop over the output columns, not written out per
    # column: the written-out form (n_feat * (K - 1) products, 440 for the reference press) took LLVM 49 s of
    # CPU to compile (5.8 s so, same bytes) and ran 3 % faster on AVX2, 2 % slower on AVX-512
    L += [f"                {at(C + k)} = {visc(k)}" for k in range(K - 1)]
    L += [f"            for k in range({K - 1}):",
          "                " + ", ".join(f"c{f}" for f in range(n_feat)) + " = "
          + ", ".join(f"base_pt[p, {f}, k]" for f in range(n_feat)),
          "                for l in range(lanes):",
          f"                    w[(k + {C}) * {Lw} + l] = w[(k + {C}) * {Lw} + l]"
          + "".join(f" + {at(IN + 4 + f)} * c{f}" for f in range(n_feat)),
          "            for l in range(lanes):"]
    # no friction at all to start with, as inverse_dynamics: the viscous part is taken out again
    L += [f"                {at(NR + j)} = {norm(lambda k: f'({at(C + k)} - {at(IN)} * v0_{k} - {at(IN + 1)} * v1_{k})', j)}"
          for j in range(r)]
    L += [f"                {at(FP + j)} = 0.0" for j in range(r)] + [f"                {at(GP + j)} = 0.0" for j in range(r)]
    L += ["            it = 2",
          "            while it <= max_it:",
          "                for l in range(lanes // 2):"]
    # one pass of the fixed point, for the lanes of one half of the block (its work-array offset ``half``, its
    # names suffixed ``_{half}``). Its dependency chains are long (the sums over the reactions, the square
    # roots, the Anderson weight): the two halves' statements alternate, so each pass has two independent
    # chains for the CPU to overlap (one register of lanes each). Measured on AVX2 (one thread): 0.0695 ms of CPU
    # per cycle against 0.0933 for the whole block at once; every value is the same to the bit (tests)
    def one_pass(half):
        def a(row):
            return f"w[{row * Lw + half * Lh} + l]"

        def v(name):
            return f"{name}_{half}"

        mu_h = [a(MR)] * (r - 1) + [a(MS)]
        P = []
        P += [f"{v(f'h{j}')} = {mu_h[j]} * {a(NR + j)}" for j in range(r)]
        P += [f"{v(f'l{c}')} = " + " + ".join(f"q{c}_{i} * {v(f'h{i}')}" for i in range(r)) for c in range(n_lam)]
        P += [f"{v(f'z{k}')} = {a(C + k)}" + _terms(G[k - 1], [v(f"l{c}") for c in range(n_lam)]) for k in range(1, n_rows + 1)]
        P += [f"{v(f'm{j}')} = {norm(lambda k: v(f'z{k}'), j)}" for j in range(r)]
        P += [f"{v(f'f{j}')} = {v(f'm{j}')} - {a(NR + j)}" for j in range(r)]
        P += [f"{v('change')} = max(" + ", ".join(f"abs({v(f'f{j}')})" for j in range(r)) + ")",
              f"{v('scale')} = max(1.0, " + ", ".join(v(f"m{j}") for j in range(r)) + ")",
              f"{v('old')} = {a(DN)} != 0.0",
              f"{v('conv')} = {v('change')} <= tol * {v('scale')}"]
        # Anderson(1): x = F(x) - gamma (F(x) - F(x_prev)), gamma from the last two residuals (0 on the first
        # pass, which has no previous one); clipped where the residuals barely moved, since a contraction of
        # rate c gives gamma = c / (c - 1), about -0.1 here
        P += [f"{v(f'd{j}')} = {v(f'f{j}')} - {a(FP + j)}" for j in range(r)]
        P += [f"{v('den')} = " + " + ".join(f"{v(f'd{j}')} * {v(f'd{j}')}" for j in range(r)),
              f"{v('num')} = " + " + ".join(f"{v(f'f{j}')} * {v(f'd{j}')}" for j in range(r)),
              f"{v('gam')} = min(max({v('num')} / {v('den')}, -GAMMA_MAX), GAMMA_MAX) if {v('den')} > 0.0 and it > 2 else 0.0"]
        P += [f"{a(FP + j)} = {v(f'f{j}')}" for j in range(r)]
        P += [f"{v(f'x{j}')} = {v(f'm{j}')} - {v('gam')} * ({v(f'm{j}')} - {a(GP + j)})" for j in range(r)]
        P += [f"{a(GP + j)} = {v(f'm{j}')}" for j in range(r)]
        # a lane that converged in an earlier pass keeps its reactions and its count; one that converges now
        # keeps F(x), as the plain iteration does
        P += [f"{a(NR + j)} = {a(NR + j)} if {v('old')} else ({v(f'm{j}')} if {v('conv')} else {v(f'x{j}')})" for j in range(r)]
        P += [f"{a(IT)} = {a(IT)} if {v('old')} or not {v('conv')} else it",
              f"{a(DN)} = 1.0 if {v('old')} or {v('conv')} else 0.0"]
        return P

    L += [f"                    {st}" for pair in zip(one_pass(0), one_pass(1)) for st in pair]
    L += ["                n_done = 0",
          "                for l in range(lanes):",
          f"                    n_done += 1 if {at(DN)} != 0.0 else 0",
          "                if n_done == lanes:",
          "                    break",
          "                it += 1",
          "            for l in range(lanes):",
          f"                tau[b0 + l, p] = {at(C)} + " + " + ".join(f"{mu[j]} * {at(NR + j)} * t{j}" for j in range(r)),
          f"                iters[b0 + l, p] = {at(IT)}",
          f"                done[b0 + l, p] = {at(DN)} != 0.0"]
    return "\n".join(L) + "\n"


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
    body = _kernel_source(bm.G, bm.n_rev + 1, len(bm.feature_keep), lanes)
    # the loop is compiled serial, and Python threads share the blocks (nogil): numba's parfor passes over the whole
    # unrolled loop took 41 s on first use, against 21 s with a small prange driver over ranges of blocks, and that
    # driver another 4.3 s of CPU (AVX2, load 9) against none with threads, for the same run time
    head = "import math\n\nimport numba\nimport numpy as np\n\n\n@numba.njit(error_model='numpy', fastmath={{'contract'}}, nogil=True, cache={cache})\n"

    def source(cache: bool) -> str:
        return head.format(cache=cache) + body

    key = hashlib.sha256(source(True).encode()).hexdigest()[:16]
    # the header names press_model.batch as before the kernel had its own module: the same text keeps the disk
    # cache of earlier versions valid (a changed file makes numba compile again)
    text = f"# generated by press_model.batch; do not edit\n{source(True)}"
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
        exec(compile(source(False), f"<friction kernel {key}>", "exec"), namespace)  # noqa: S102 (our own generated source)
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
    disk cache, while holding :func:`jit.compile_lock` on ``lock``: only one process compiles what several need at once."""
    from numba.core.compiler_lock import global_compiler_lock

    signature = tuple(numba.typeof(a) for a in args)
    with global_compiler_lock, compile_lock(lock, "the friction kernel"):  # numba's lock first, as jit.one_compile_at_a_time
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
