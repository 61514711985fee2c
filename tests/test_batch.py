"""Batch torque curves (press_model.batch) against the per-point Pinocchio path, and the response functions."""
import math
import re
import time

import numpy as np
import pytest

from press_model import batch as BT
from press_model import batch_kernel as BK
from calibration import responses as R
from calibration.sensitivity.report import response_evaluator
from press_model.cycle import simulate_cycle
from press_io.errors import PressDataError
from press_model.model import PressModel

SEED = 20250917
BACKENDS = ["numpy"] + (["numba"] if BT.numba is not None else [])


@pytest.fixture(scope="module")
def bm(ref_model, cushion):
    job, motion = cushion
    return BT.build_batch_model(ref_model.press, motion, job.process, pm=ref_model)


@pytest.fixture(scope="module")
def nominal_cycle(ref_model, cushion):
    job, motion = cushion
    return simulate_cycle(ref_model, motion, job.process)


@pytest.fixture(scope="module")
def random_sets(bm):
    """Uniform over each parameter's [low, high] (as SALib's uniform bounds), explicit seed."""
    rng = np.random.default_rng(SEED)
    return bm.low + (bm.high - bm.low) * rng.random((8, bm.n_params))


@pytest.fixture(scope="module")
def pinocchio_curves(ref_model, cushion, bm, random_sets):
    job, motion = cushion
    out = []
    for x in random_sets:
        press = ref_model.press.with_overrides(dict(zip(bm.names, map(float, x))))
        out.append(simulate_cycle(PressModel(press), motion, job.process))
    return out


def rel_err(T, ref):
    return np.max(np.abs(T - ref)) / np.max(np.abs(ref))


@pytest.mark.parametrize("backend", BACKENDS)
def test_nominal_curve_matches_simulate_cycle(bm, nominal_cycle, backend):
    res = BT.evaluate_chunk(bm, bm.nominal[None], backend=backend)
    assert rel_err(res.motor_torque[0], nominal_cycle.motor_torque) < 1e-12
    assert rel_err(res.crank_torque[0], nominal_cycle.crank_torque) < 1e-12
    # the same fixed point, reached in fewer passes by the Anderson(1) step than by the plain iteration
    assert np.mean(res.iterations[0]) < 0.8 * np.mean(nominal_cycle.iterations)
    assert np.all(res.iterations[0] <= nominal_cycle.iterations + 1)


def test_backends_take_the_same_accelerated_passes(bm, random_sets):
    """numpy and the compiled kernel run one algorithm: the same passes (to a rounding tie) and torques."""
    if "numba" not in BACKENDS:
        pytest.skip("numba is not installed")
    a, b = (BT.evaluate_chunk(bm, random_sets, backend=k) for k in ("numpy", "numba"))
    assert np.mean(a.iterations != b.iterations) < 0.01 and np.max(np.abs(a.iterations - b.iterations)) <= 1
    assert rel_err(a.motor_torque, b.motor_torque) < 1e-12


@pytest.mark.parametrize("backend", BACKENDS)
def test_random_sets_match_pinocchio_path(bm, random_sets, pinocchio_curves, backend):
    """Full ranges of all 28 parameters: 1e-9 of the curve's peak (the rest is the COM fit of link 4)."""
    T = BT.motor_torques(bm, random_sets, chunk_size=4, backend=backend)
    for k, cyc in enumerate(pinocchio_curves):
        assert rel_err(T[k], cyc.motor_torque) < 1e-9, f"set {k}"


def test_kernel_threads_split_the_sets_and_give_the_same_bytes(bm):
    """Threads share the sets of a chunk; each (set, angle) is computed alone, so any thread count gives the same bytes."""
    if "numba" not in BACKENDS:
        pytest.skip("numba is not installed")
    import numba

    X = bm.low + (bm.high - bm.low) * np.random.default_rng(SEED + 1).random((256, bm.n_params))
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(2)
        blocks = 256 // BK.LANES
        assert BK._block_edges(blocks, bm.n_points).tolist() == [0, blocks // 2, blocks]
        assert BK._block_edges(2, bm.n_points).tolist() == [0, 2]  # too little work to wake a second thread
        two = BT.evaluate_chunk(bm, X)
        numba.set_num_threads(1)
        one = BT.evaluate_chunk(bm, X)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(two.motor_torque, one.motor_torque) and np.array_equal(two.iterations, one.iterations)


def test_each_set_gives_the_same_bytes_whatever_the_lanes_per_block(cushion):
    """A set's fixed point never mixes with its block's other lanes, and the two halves of a block, whose passes
    interleave, are two copies of one computation: so this CPU's LANES (8 for AVX2, 16 for AVX-512) and 4 sets per block
    give every set's torque, iterations and flags to the bit. On the crank-slider (a small kernel, ~3 s of compile)."""
    if "numba" not in BACKENDS:
        pytest.skip("numba is not installed")
    from press_model.press_data import load_press

    job, motion = cushion
    press = load_press("crank-slider")
    small = BT.build_batch_model(press, motion, job.process)
    X = small.low + (small.high - small.low) * np.random.default_rng(SEED + 2).random((21, small.n_params))  # pads the last block
    feats = BT.features(small, X)[0]
    fric = (small.c_r.take(X), small.c_s.take(X), small.mu_r.take(X), small.mu_s.take(X))
    import numba

    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)  # one range of blocks: the whole padded batch in one call
        runs = [BK.fixed_point_numba(small, feats, *fric, lanes=lanes) for lanes in (4, BK.LANES)]
    finally:
        numba.set_num_threads(before)
    assert np.all(runs[0][2]) and np.ptp(runs[0][1]) > 0  # converged, with sets that need different pass counts
    for other in runs[1:]:
        assert all(np.array_equal(a, b) for a, b in zip(runs[0], other))
    with pytest.raises(ValueError, match="odd"):
        BK._kernel_source(small.G, small.n_rev + 1, feats.shape[1], 7)


def test_kernel_source_does_not_grow_with_features_times_columns(bm):
    """The setup (features @ base) is a loop over the output columns: written out per (feature, column) the
    generated kernel took LLVM ~50 s to compile (issue: first run on an AVX2 machine), as a loop ~6 s."""
    r, n_feat = bm.n_rev + 1, len(bm.feature_keep)
    lines = [len(BK._kernel_source(bm.G, r, f).splitlines()) for f in (n_feat, 2 * n_feat)]
    assert lines[0] == lines[1], lines


class _Dispatcher:  # what the first call reads of a numba dispatcher (its stats), and its compile, a no-op here
    def __init__(self, misses):
        self.stats = type("Stats", (), {"cache_misses": {"sig": misses} if misses else {}})()

    def compile(self, signature):
        pass


@pytest.mark.parametrize("misses", [0, 1])
def test_first_kernel_call_says_how_long_a_compile_took(misses, capsys, monkeypatch):
    if "numba" not in BACKENDS:
        pytest.skip("numba is not installed")
    monkeypatch.setattr(BK, "_CALLED", set())
    kern = _Dispatcher(misses)
    BK._first_call(kern, (1.0,), None)
    err = capsys.readouterr().err
    if misses:  # compiled: the measured time, no guess
        assert re.fullmatch(r"compiling the friction kernel .*\ncompiled the friction kernel in \d+\.\d s\n", err), err
    else:  # no cache folder: the compile is announced, no time is claimed
        assert re.fullmatch(r"compiling the friction kernel [^\n]*\n", err), err
    assert kern in BK._CALLED


_TINY_KERNEL = """import numba


@numba.njit(cache=True)
def f(x):
    s = 0.0
    for i in range(100):
        s += (x + i) ** 0.5 if i % 3 else x * i
    return s
"""


def _compile_tiny_kernel(folder, who, how, queue):
    """In a forked child: load the tiny kernel's module, wait for the common start, compile or load it under the lock,
    as the friction kernel is (``how`` 'kernel') or as every :func:`jit.compiled` function ('jit': at its first call)."""
    from press_model.jit import compiled

    import importlib.util
    import sys
    import time

    spec = importlib.util.spec_from_file_location("_tiny_kernel_for_lock", folder / "tiny.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    (folder / f"ready_{who}").touch()
    while not (folder / "go").exists():
        time.sleep(0.005)
    if how == "kernel":
        f = module.f
        BK.compile_or_load(f, (1.0,), folder / "tiny.lock")
    else:
        f = compiled(module.f.py_func)
        f(1.0)
    queue.put((sum(f.stats.cache_misses.values()), sum(f.stats.cache_hits.values())))


@pytest.mark.parametrize("how", ["kernel", "jit"])
def test_two_processes_on_an_empty_cache_compile_a_kernel_once(tmp_path, how):
    """Started at the same moment on an empty numba cache (the suite's two workers, reproduce's two processes), one
    process compiles and saves while the other waits on the lock file, then loads the machine code from the cache."""
    import multiprocessing

    if "numba" not in BACKENDS or "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("needs numba and fork")
    (tmp_path / "tiny.py").write_text(_TINY_KERNEL, encoding="utf-8")
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    children = [ctx.Process(target=_compile_tiny_kernel, args=(tmp_path, who, how, queue)) for who in "ab"]
    for child in children:
        child.start()
    try:
        deadline = time.monotonic() + 60
        while not all((tmp_path / f"ready_{who}").exists() for who in "ab") and time.monotonic() < deadline:
            time.sleep(0.005)
        (tmp_path / "go").touch()
        stats = sorted(queue.get(timeout=60) for _ in children)
        for child in children:
            child.join(30)
    finally:
        for child in children:
            if child.is_alive():
                child.kill()
    assert stats == [(0, 1), (1, 0)], stats  # (cache misses, cache hits): one compiled, the other loaded


def _evaluate_in_child(bm, X, queue):
    queue.put(BT.evaluate_chunk(bm, X).motor_torque)


def test_a_forked_child_runs_the_kernel(bm):
    """The monitor's local workers and the Sobol analysis fork after the parent ran the kernel's threads."""
    import multiprocessing

    if "numba" not in BACKENDS or "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("needs numba and fork")
    X = bm.low + (bm.high - bm.low) * np.random.default_rng(SEED + 2).random((256, bm.n_params))
    here = BT.evaluate_chunk(bm, X).motor_torque  # the kernel's threads now run in this process
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_evaluate_in_child, args=(bm, X, queue))
    child.start()
    try:
        there = queue.get(timeout=120)
        child.join(30)
    finally:
        if child.is_alive():
            child.kill()
    assert child.exitcode == 0 and np.array_equal(here, there)


def test_batch_eq16_compiled_and_numpy_agree(bm, random_sets):
    """The batch path's Eq. 16 (compiled from EQ16_COMPILED_ROWS sets on) equals motor.eq16 on the same crank torques."""
    X = np.repeat(random_sets, BT.EQ16_COMPILED_ROWS // len(random_sets) + 1, axis=0)
    res = BT.evaluate_chunk(bm, X)
    from press_model.motor import eq16

    ref = eq16(res.crank_torque, bm.theta_dot[None], bm.theta_ddot[None], bm.gear_inertia.take(X)[:, None],
               bm.efficiency.take(X)[:, None], bm.gear_ratio, bm.motors, bm.standstill == "motoring")
    assert res.motor_torque.tobytes() == ref.tobytes()


def test_without_friction_matches(bm, cushion, ref_model, nominal_cycle):
    job, motion = cushion
    ref = simulate_cycle(ref_model, motion, job.process, friction=False)
    res = BT.evaluate_chunk(bm, bm.nominal[None], friction=False)
    assert rel_err(res.crank_torque[0], ref.crank_torque) < 1e-12


@pytest.mark.parametrize("backend", BACKENDS)
def test_chunks_and_input_forms_agree(bm, random_sets, backend):
    whole = BT.motor_torques(bm, random_sets, chunk_size=64, backend=backend)
    same = {"rtol": 1e-13, "atol": 1e-13 * np.max(np.abs(whole))}  # BLAS may sum in another order per chunk size
    assert np.allclose(whole, BT.motor_torques(bm, random_sets, chunk_size=1, backend=backend), **same)
    as_dicts = [dict(zip(bm.names, x)) for x in random_sets]
    assert np.array_equal(whole, BT.motor_torques(bm, as_dicts, chunk_size=64, backend=backend))
    as_columns = {name: random_sets[:, i] for i, name in enumerate(bm.names)}
    assert np.array_equal(whole, BT.motor_torques(bm, as_columns, chunk_size=64, backend=backend))
    rows = [r for r, _ in BT.iter_chunks(bm, random_sets, chunk_size=4)]
    assert rows == [slice(0, 4), slice(4, 8)]


@pytest.mark.parametrize("backend", BACKENDS)
def test_sets_differing_only_in_the_drive_share_one_fixed_point(bm, random_sets, backend, monkeypatch):
    """Rows that differ only in the gear inertia or the efficiency (a Sobol design's A_B rows of those columns) have one
    crank torque: it is computed once, and every row gets the bytes it gets alone, its own Eq. 16 after it."""
    col = {k: i for i, k in enumerate(bm.names)}
    X = np.repeat(random_sets[:3], 3, axis=0)
    X[1::3, col["J_gear"]] = bm.low[col["J_gear"]]
    X[2::3, col["eta_gear"]] = bm.high[col["eta_gear"]]
    X = np.vstack([X, random_sets[3:5]])  # and rows with nothing in common
    alone = [BT.evaluate_chunk(bm, x[None], backend=backend) for x in X]
    sizes = []
    inner = BT.fixed_point_numba if backend == "numba" else BT._fixed_point_numpy

    def counted(bm_, first, *rest):
        sizes.append(len(first))
        return inner(bm_, first, *rest)

    monkeypatch.setattr(BT, "fixed_point_numba" if backend == "numba" else "_fixed_point_numpy", counted)
    together = BT.evaluate_chunk(bm, X, backend=backend)
    assert sizes == [5]  # 3 groups of 3 rows, 2 single rows
    # the compiled kernel computes each set alone: the same bytes; numpy's matrix products round by the batch's size
    same = np.array_equal if backend == "numba" else (lambda a, b: rel_err(a, b) < 1e-13)
    for k, one in enumerate(alone):
        assert same(together.crank_torque[k], one.crank_torque[0]), k
        assert same(together.motor_torque[k], one.motor_torque[0]), k
        assert np.array_equal(together.iterations[k], one.iterations[0]), k
    assert np.array_equal(together.crank_torque[0], together.crank_torque[2])
    assert not np.array_equal(together.motor_torque[0], together.motor_torque[2])  # Eq. 16 of each row's own drive


def test_missing_names_take_nominal_and_unknown_names_raise(bm):
    X = BT.parameter_array(bm, [{"m8": 32940.0}])
    assert X[0, bm.names.index("m8")] == 32940.0
    assert np.array_equal(np.delete(X[0], bm.names.index("m8")), np.delete(bm.nominal, bm.names.index("m8")))
    with pytest.raises(PressDataError, match="not a parameter"):
        BT.parameter_array(bm, [{"m9": 1.0}])
    with pytest.raises(PressDataError, match="finite"):
        BT.parameter_array(bm, np.full((1, bm.n_params), np.nan))


def test_trilateration_is_the_least_squares_point(ref_model, bm):
    """The vectorised fit: exact at nominal distances, and a stationary point of the squared misfit."""
    body = next(b for b in bm.bodies if b.com_kind == "trilateration")
    nominal = np.array([s.value for s in body.distances])
    com, g = BT.trilaterate(body.points, nominal[None])
    assert np.allclose(com[0], ref_model.press.bodies[body.name].com, atol=1e-12)
    rng = np.random.default_rng(SEED)
    d = nominal * rng.uniform(0.7, 1.3, (500, len(nominal)))
    com, g = BT.trilaterate(body.points, d)
    assert np.all(g < 1e-12)
    # and it is the point press_data's reader finds (that one stops at about 1e-7 m)
    for k in range(5):
        paths = {s.index: v for s, v in zip(body.distances, d[k])}
        press = ref_model.press.with_overrides({bm.names[i]: float(v) for i, v in paths.items()})
        assert np.allclose(com[k], press.bodies[body.name].com, atol=1e-6)


def test_a_one_row_trilateration_is_remembered_as_fitted(bm, monkeypatch):
    """Sets that share the COM's distances fit one row per model call: the fit is remembered, the same numbers."""
    body = next(b for b in bm.bodies if b.com_kind == "trilateration")
    row = np.array([[s.value for s in body.distances]]) * 1.01  # a row no other test fits
    fresh = BT.trilaterate(body.points, row)
    calls = []
    monkeypatch.setattr(BT, "trilaterate", lambda p, d: calls.append(len(d)) or fresh)
    first, again = BT._trilaterated(body.points, row), BT._trilaterated(body.points, row.copy())
    assert calls == [1] and again is first
    assert np.array_equal(first[0], fresh[0]) and np.array_equal(first[1], fresh[1])
    BT._trilaterated(body.points, np.vstack([row, row * 1.01]))
    assert calls == [1, 2]  # several rows: fitted each time (a Sobol design's rows differ)


def test_parameters_outside_the_batch_model_are_refused(ref_model, cushion):
    job, motion = cushion
    raw = ref_model.press.raw()
    raw["parameters"]["V_vess"] = {"path": "balance.tank_volume_m3"}
    from press_model.press_data import read_press

    press = read_press(raw, "<test>")
    with pytest.raises(PressDataError, match="batch evaluator varies only"):
        BT.build_batch_model(press, motion, job.process, pm=ref_model)


# --- responses ------------------------------------------------------------------------------------


def test_responses_on_a_small_hand_example():
    T = np.array([1.0, -3.0, 2.0, 4.0])
    ref = np.array([2.0, -1.0, 0.0, 1.0])
    w = np.array([1.0, 2.0, 1.0, 2.0])  # rad/s; dt = (pi/2) / w
    assert R.y_rmse(T, ref) == pytest.approx(math.sqrt((1 + 4 + 4 + 9) / 4))
    assert R.y_rmse(ref, ref) == 0.0
    assert R.y_pr(T, ref) == pytest.approx((4 - 2) / 2)
    assert R.y_pr(ref, ref) == 0.0
    dt = (math.pi / 2) / w
    assert R.y_tl(T, w) == pytest.approx(math.sqrt(np.sum(dt * T**2) / np.sum(dt)))
    assert R.y_tl(T, np.ones(4)) == pytest.approx(math.sqrt(np.mean(T**2)))
    assert R.y_work(T, w, 32.0) == pytest.approx(32.0 * (math.pi / 2) * T.sum())  # u dtheta sum(T)


def test_responses_are_vectorised(nominal_cycle):
    rng = np.random.default_rng(SEED)
    ref = nominal_cycle.motor_torque
    T = ref[None] * rng.uniform(0.8, 1.2, (5, 1)) + rng.normal(0, 100, (5, ref.size))
    Y = R.all_responses(T, ref, nominal_cycle.theta_dot, 32.0)
    assert Y.shape == (5, 4)
    for k in range(5):
        single = [R.y_rmse(T[k], ref), R.y_pr(T[k], ref), R.y_tl(T[k], nominal_cycle.theta_dot),
                  R.y_work(T[k], nominal_cycle.theta_dot, 32.0)]
        assert np.allclose(Y[k], single, rtol=1e-14)


def test_compiled_responses_equal_the_equations_one_by_one(nominal_cycle):
    """Many curves go through one compiled pass (another summation order): the same four numbers to rounding."""
    rng = np.random.default_rng(SEED)
    ref = nominal_cycle.motor_torque
    n = R.FUSED_ROWS + 3
    T = ref[None] * rng.uniform(0.8, 1.2, (n, 1)) + rng.normal(0, 100, (n, ref.size))
    T[4, 17] = np.nan  # a curve with a gap gives NaN everywhere, as numpy's max and sums do
    w, u = nominal_cycle.theta_dot, 32.0
    Y = R.all_responses(T, ref, w, u)
    one_by_one = np.column_stack([R.y_rmse(T, ref), R.y_pr(T, ref), R.y_tl(T, w), R.y_work(T, w, u)])
    assert np.array_equal(np.isnan(Y), np.isnan(one_by_one)) and np.isnan(Y[4]).all()
    ok = ~np.isnan(Y[:, 0])
    scale = np.max(np.abs(one_by_one[ok]), axis=0)  # Y_Work sums terms of both signs: compare with its scale
    assert np.all(np.abs(Y[ok] - one_by_one[ok]) <= 1e-13 * scale)
    if R.compiled(R._fused) is not None:  # the few-curve path is numpy's: the compiled one really ran above
        assert not np.array_equal(Y[ok], one_by_one[ok])


def test_responses_match_the_cycle_methods(nominal_cycle, ref_model):
    c = nominal_cycle
    u = ref_model.press.drive.gear_ratio
    assert R.y_tl(c.motor_torque, c.theta_dot) == pytest.approx(c.rms_motor_torque(), rel=1e-14)
    assert R.y_work(c.motor_torque, c.theta_dot, u) == pytest.approx(c.motor_work_per_motor(u), rel=1e-14)
    assert R.y_rmse(c.motor_torque, c.motor_torque) == 0.0
    assert R.y_pr(c.motor_torque, c.motor_torque) == 0.0
    assert R.y_pr(-1.1 * c.motor_torque, c.motor_torque) == pytest.approx(0.1)


def test_response_evaluator(bm, random_sets, nominal_cycle):
    ev = response_evaluator(bm)
    Y = ev(np.vstack([bm.nominal, random_sets]))
    assert Y.shape == (9, 4) and np.all(np.isfinite(Y))
    assert Y[0, 0] == pytest.approx(0.0, abs=1e-9) and Y[0, 1] == pytest.approx(0.0, abs=1e-15)
    assert Y[0, 2] == pytest.approx(nominal_cycle.rms_motor_torque(), rel=1e-12)


def test_sets_whose_com_cannot_be_fitted_raise_or_are_masked(bm, random_sets, monkeypatch):
    monkeypatch.setattr(BT, "GRADIENT_TOL", -1.0)  # make every fit count as failed
    with pytest.raises(PressDataError, match="set 0: bodies.link4.com.distances_m"):
        BT.motor_torques(bm, random_sets[:2])
    T = BT.motor_torques(bm, random_sets[:2], invalid="mask")
    assert np.all(np.isnan(T))
