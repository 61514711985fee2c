#!/usr/bin/env python
"""Benchmark: batch motor-torque curves (press_model.batch) for the cushion-test cycle with friction.

Prints the precomputation time (PressModel, then BatchModel), the first-call time of the compiled
kernel (numba JIT, or loading numba's disk cache), and the amortised time of one 360-point cycle over a
batch of parameter sets drawn uniformly over the 28 parameters' ranges, for each backend (with the COM
fits of link 4, one per set here as every random set is distinct), and the compiled kernel alone.
Each CPU target (scripts/cpu_targets.py: AVX2 and this machine's own CPU by default) runs in its own process with the
kernel compiled for it; ``--cold`` gives each an empty numba cache, so that the first call is the compile
a new user waits for, and prints the packed instructions of the compiled kernel by register width
(ymm: 4 doubles, AVX2; zmm: 8 doubles, AVX-512).
``--against FILE``: a generated kernel of another version (``friction_*.py`` in its cache folder's ``kernels``, made
for the reference press with this CPU's lanes) runs beside this version's on the same sets, one thread, calls
alternating, ``--repeat`` rounds: the CPU per cycle of each, the ratio per round, and whether they give the same bytes.
Targets: kernel <= 0.1 ms per cycle amortised (issue 11); the first compile <= 15 s on a 2-core AVX2
machine (issue 25).
Usage: python scripts/bench_batch.py [--cpu avx2,host] [--cold] [--sets 4096] [--chunk 256] [--repeat 3] [--numpy-sets 512]
       [--against FILE]
"""
import argparse
import importlib.util
import os
import sys
import re
import statistics
import tempfile
import time

import numpy as np

import cpu_targets

from press_model import batch as BT
from press_model import batch_kernel as BK
from press_model.cycle import simulate_cycle
from press_model.jobs import load_job, make_motion
from press_model.model import PressModel
from press_model.press_data import load_press


def timed(fn, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return times


def packed_instructions(kernel) -> str:
    """The compiled kernel's packed FMAs and square roots by register width (its assembly, after a compile)."""
    try:
        asm = "\n".join(kernel.inspect_asm().values())
    except Exception as exc:  # noqa: BLE001 (a kernel loaded from the cache may not keep its assembly)
        return f"assembly not available ({type(exc).__name__})"
    count = {"x": 0, "y": 0, "z": 0}
    for line in asm.splitlines():  # AT&T syntax: the destination register is the last operand
        if re.match(r"\s*(?:vfn?m(?:add|sub)\d*pd|vsqrtpd)\s", line):
            count[re.findall(r"%([xyz])mm\d+", line)[-1]] += 1
    return (f"packed FMA and sqrt instructions in the kernel: {count['z']} on zmm (8 doubles), {count['y']} on ymm "
            f"(4 doubles), {count['x']} on xmm (2 doubles)")


def kernel_from_file(path):
    """``kern_blocks`` of a generated kernel file, under the module name its numba cache records."""
    name = f"_servo_press_{os.path.splitext(os.path.basename(path))[0]}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module.kern_blocks


def against(bm, X, path, rounds):
    """This version's kernel and the one in ``path`` on the sets X, one thread, calls alternating (which goes first
    alternates too): prints the CPU per cycle of each, the per-round ratio and whether the outputs are the same bytes."""
    lanes, B = BK.LANES, len(X) - len(X) % BK.LANES
    feats = BT.features(bm, X[:B])[0]
    rows = np.column_stack([bm.c_r.take(X[:B]), bm.c_s.take(X[:B]), bm.mu_r.take(X[:B]), bm.mu_s.take(X[:B]), feats])
    sets = np.ascontiguousarray(rows.reshape(B // lanes, lanes, -1).transpose(0, 2, 1)).reshape(B // lanes, -1)

    def run(kern):
        out = (np.empty((B, bm.n_points)), np.empty((B, bm.n_points), dtype=np.int64), np.empty((B, bm.n_points), dtype=np.bool_))
        c0 = time.process_time()
        kern(sets, lanes, bm.base_pt, bm.visc_pt, bm.coul_lam, bm.coul_tau, bm.friction_tolerance, bm.friction_max_iterations,
             *out, 0, B // lanes)
        return (time.process_time() - c0) / B * 1e3, out

    kernels = {"this": BK._compiled_kernel(bm), "other": kernel_from_file(path)}
    first = {name: run(k)[1] for name, k in kernels.items()}  # compiles or loads; the outputs compared
    same = all(a.tobytes() == b.tobytes() for a, b in zip(first["this"], first["other"]))
    cpu = {"this": [], "other": []}
    for i in range(rounds):
        for name in ("this", "other") if i % 2 == 0 else ("other", "this"):
            cpu[name].append(run(kernels[name])[0])
    ratios = [a / b for a, b in zip(cpu["this"], cpu["other"])]
    print(f"[against] {B} sets, one thread, {rounds} rounds: CPU per cycle this {statistics.median(cpu['this']):.4f} ms, "
          f"other {statistics.median(cpu['other']):.4f} ms (medians); this/other per round median {statistics.median(ratios):.3f} "
          f"({min(ratios):.3f}-{max(ratios):.3f}); same bytes: {same}; load average {os.getloadavg()[0]:.1f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sets", type=int, default=4096, help="parameter sets in the batch (numba backend)")
    ap.add_argument("--numpy-sets", type=int, default=512, help="parameter sets for the numpy backend (0: skip)")
    ap.add_argument("--chunk", type=int, default=BT.DEFAULT_CHUNK)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cold", action="store_true", help="empty numba caches: the first call compiles everything")
    ap.add_argument("--against", metavar="FILE", help="a generated kernel file of another version, run beside this one")
    cpu_targets.add_cpu_argument(ap)
    args = ap.parse_args()
    if cpu_targets.current() is None:
        with tempfile.TemporaryDirectory() as tmp:
            cold = {"XDG_CACHE_HOME": os.path.join(tmp, "xdg"), "NUMBA_CACHE_DIR": os.path.join(tmp, "numba")} if args.cold else {}
            return cpu_targets.run_per_target(args.cpu, cold)

    press = load_press()
    job = load_job("cushion-test")
    motion = make_motion(job.motion, job.source)
    t0 = time.perf_counter()
    pm = PressModel(press)
    t_pm = time.perf_counter() - t0
    t0 = time.perf_counter()
    bm = BT.build_batch_model(press, motion, job.process, pm=pm)
    t_bm = time.perf_counter() - t0
    t0 = time.perf_counter()
    cyc = simulate_cycle(pm, motion, job.process)
    t_ref = time.perf_counter() - t0
    print(f"press: {press.name}; job: {job.name}; {bm.n_points} crank angles, {bm.n_params} parameters")
    print(f"precomputation: PressModel {t_pm:.3f} s + BatchModel {t_bm:.3f} s "
          f"(for comparison, one cycle on the per-point Pinocchio path: {t_ref * 1e3:.0f} ms)")

    rng = np.random.default_rng(args.seed)
    X = bm.low + (bm.high - bm.low) * rng.random((args.sets, bm.n_params))
    if args.against:
        import numba

        numba.set_num_threads(1)
        with BK._one_blas_thread():
            against(bm, X, args.against, args.repeat)
        return 0
    numba = BT.numba
    backends = (["numba"] if numba is not None else []) + (["numpy"] if args.numpy_sets > 0 else [])
    if BT.numba is None:
        print("numba is not installed: only the numpy backend runs")
    for backend in backends:
        Xb = X if backend == "numba" else X[: args.numpy_sets]
        t0, c0 = time.perf_counter(), time.process_time()
        BT.evaluate_chunk(bm, bm.nominal[None], backend=backend)
        first, first_cpu = time.perf_counter() - t0, time.process_time() - c0
        times = timed(lambda Xb=Xb, backend=backend: BT.motor_torques(bm, Xb, args.chunk, backend=backend), args.repeat)
        iters = np.concatenate([res.iterations for _, res in BT.iter_chunks(bm, Xb[:256], args.chunk, backend=backend)])
        err = np.max(np.abs(BT.motor_torques(bm, bm.nominal[None], backend=backend)[0] - cyc.motor_torque))
        print(f"[{backend}] first call ({'compile, empty cache' if args.cold else 'compile or cache load'}) {first:.2f} s wall, {first_cpu:.2f} s CPU; "
              f"{len(Xb)} sets, chunk {args.chunk}: best {min(times):.3f} s, median {statistics.median(times):.3f} s ({args.repeat} runs)")
        if backend == "numba" and args.cold:
            print(f"[numba]   {packed_instructions(BK._compiled_kernel(bm))}")
        if backend == "numba":  # the compiled fixed point alone, features (COM fits) computed beforehand
            fx = BT.features(bm, Xb)
            fric = (bm.c_r.take(Xb), bm.c_s.take(Xb), bm.mu_r.take(Xb), bm.mu_s.take(Xb))
            kt, kc = [], []
            for _ in range(args.repeat):
                t0, c0 = time.perf_counter(), time.process_time()
                for s in range(0, len(Xb), args.chunk):
                    BK.fixed_point_numba(bm, fx[0][s : s + args.chunk], *(f[s : s + args.chunk] for f in fric))
                kt.append(time.perf_counter() - t0)
                kc.append(time.process_time() - c0)
            # on a shared machine the wall time swings with the other load; the CPU time (all threads) much less
            print(f"[numba]   kernel only (friction fixed point, {BK.LANES} sets per block, two interleaved SIMD registers, {numba.get_num_threads()} threads): "
                  f"wall min {min(kt) / len(Xb) * 1e3:.4f} ms, max {max(kt) / len(Xb) * 1e3:.4f} ms per 360-point cycle "
                  f"(CPU {statistics.median(kc) / len(Xb) * 1e3:.4f} ms, median; {args.repeat} runs; target <= 0.1 ms wall); "
                  f"load average {os.getloadavg()[0]:.1f}")
        print(f"[{backend}]   amortised: {min(times) / len(Xb) * 1e3:.4f} ms per 360-point cycle with friction "
              f"({min(times) / len(Xb) / bm.n_points * 1e9:.0f} ns per point); "
              f"fixed point {iters.mean():.1f} iterations per point (mean, first 256 sets); "
              f"nominal curve vs simulate_cycle: {err / np.max(np.abs(cyc.motor_torque)):.1e} relative")


if __name__ == "__main__":
    raise SystemExit(main())
