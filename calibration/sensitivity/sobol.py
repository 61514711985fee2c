"""Sobol global sensitivity (Section 3): the problem as plain data, then sampling, evaluation and analysis.

Like SALib, the three steps are separate: :func:`problem` builds the names and bounds from the press
file's ``[parameters]``; :func:`sample` draws a Sobol design; an evaluator (any callable mapping a
(n, D) block of parameter rows to (n, 4) responses) runs the model; :func:`analyze` computes the
indices with bootstrap intervals. :func:`key_parameters` applies the paper's screening rule.
"""
from __future__ import annotations

import multiprocessing
import os
import sys
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

from press_io.errors import PressDataError
from press_io.forked import warm_process
from press_io.progress import progress as show_progress
from press_model.press_data import PressData, check_parameter_ranges
from calibration.responses import RESPONSES

CORE_RESPONSES = ("Y_RMSE", "Y_PR")  # Section 3.3: the core decision functions
SCREEN_THRESHOLD = 0.05  # S_T above this on a core function makes a key parameter
PLOT_THRESHOLD = 0.01  # Figure 3 shows parameters with S_T >= 0.01


def problem(press: PressData) -> dict:
    """SALib problem dict: names and [low, high] bounds of every sensitivity parameter, SI units."""
    params = list(press.parameters.values())
    if not params:
        raise PressDataError(press.source, "parameters", {}, "needs at least one sensitivity parameter to analyse")
    check_parameter_ranges(press)  # the sampler runs the model at every end of every range
    return {"num_vars": len(params), "names": [p.name for p in params], "bounds": [[p.low, p.high] for p in params]}


def _salib():
    """SALib's Sobol analyser, imported on first use (with scipy.stats and pandas, ~0.9 s)."""
    from SALib.analyze import sobol as sobol_analyze

    return sobol_analyze


def sample(prob: dict, n: int, seed: int, second_order: bool = False) -> np.ndarray:
    """Sobol design of n (D + 2) rows, or n (2 D + 2) with second order; n must be a power of two.

    SALib's ``SALib.sample.sobol.sample`` (uniform bounds, no groups), the same matrix to the bit (tests): Saltelli's
    scheme on the scrambled Sobol' sequence of scipy.stats.qmc, rows [A, A with column k from B (k = 1..D),
    (second order: B with column k from A), B] per base point, scaled to the bounds by SALib's two ufuncs. Built
    here with numpy: SALib's loop over the N (D + 2) D entries in Python took ~0.4 s at N = 2048, D = 28, and
    its import ~0.5 s more (pandas) than the sampler's own (scipy.stats).
    """
    _check_n(n)
    from scipy.stats import qmc

    d = prob["num_vars"]
    base = qmc.Sobol(d=2 * d, scramble=True, seed=seed).random(n)
    a, b = base[:, :d], base[:, d:]
    blocks = [a]
    for k in range(d):
        blocks.append(a.copy())
        blocks[-1][:, k] = b[:, k]
    if second_order:
        for k in range(d):
            blocks.append(b.copy())
            blocks[-1][:, k] = a[:, k]
    blocks.append(b)
    X = np.stack(blocks, axis=1).reshape(-1, d)
    bounds = np.array(prob["bounds"])
    lower, upper = bounds[:, 0], bounds[:, 1]
    np.add(np.multiply(X, upper - lower, out=X), lower, out=X)
    return X


def _check_n(n: int) -> None:
    if n < 2 or n & (n - 1):
        raise PressDataError("--n", "n", n, "must be a power of two (e.g. 1024, 2048, 4096) for Sobol sequences")


def sample_later(prob: dict, n: int, seed: int, second_order: bool = False, workers: ProcessPoolExecutor | None = None) -> Future:
    """:func:`sample` in one of ``workers`` (see :func:`salib_workers`) while the caller goes on; without workers, now.

    Returns a Future of the design (the same array as :func:`sample`).
    """
    if workers is None:
        done = Future()
        done.set_result(sample(prob, n, seed, second_order))
        return done
    _check_n(n)  # here, as a one-line error, not as an exception pickled back from the process
    design = workers.submit(sample, prob, n, seed, second_order)
    workers.submit(_warm_analysis)  # next in the process, once the design is on its way back
    return design


def _warm_worker() -> None:
    from scipy.stats import qmc  # noqa: F401 (the sampler's import, at once: the design is wanted first)

    _reuse_freed_memory()


def _warm_analysis() -> None:
    from press_model.plots import pyplot

    _salib()
    pyplot()  # the Sobol figure is drawn here too, beside the command writing its tables


def salib_workers() -> AbstractContextManager[ProcessPoolExecutor | None]:
    """A process, forked now, that imports the Sobol sampler at once, then samples (:func:`sample_later`), imports
    SALib and matplotlib, analyses and draws the figure (None without fork).

    Started before the caller's own heavy imports and model build, so that the sampler's import (scipy.stats,
    ~0.6 s) and the sampling run beside them on the other core, and then SALib's import (pandas) and
    matplotlib's beside the caller's evaluation; the caller never imports SALib, scipy.stats or matplotlib
    itself. For the analysis it forks its own second process (:func:`analyze`).
    """
    return warm_process(_warm_worker)


def evaluate(evaluator: Callable[[np.ndarray], np.ndarray], X: np.ndarray, chunk: int = 4096,
             progress: bool = True, columns: int = len(RESPONSES)) -> np.ndarray:
    """Responses (len(X), ``columns``) of the design, evaluated chunk by chunk so memory stays bounded (``columns``: 4, or
    4 per load case of an evaluator of several)."""
    _reuse_freed_memory()
    out = np.empty((len(X), columns))
    for start in range(0, len(X), chunk):
        stop = min(start + chunk, len(X))
        out[start:stop] = evaluator(X[start:stop])
        if progress:
            _bar(stop, len(X))
    if not np.all(np.isfinite(out)):
        bad = int(np.argmax(~np.all(np.isfinite(out), axis=1)))
        raise PressDataError("sensitivity", "design row", bad, "gave a non-finite response; check the parameter ranges")
    return out


def _bar(done: int, total: int) -> None:
    show_progress("model cycles", done, total)


@dataclass(frozen=True)
class Indices:
    """Sobol indices of one response: arrays over the parameters, with 95 % bootstrap half-widths."""

    response: str
    names: tuple
    S1: np.ndarray
    S1_conf: np.ndarray
    ST: np.ndarray
    ST_conf: np.ndarray
    S2: np.ndarray | None = None
    S2_conf: np.ndarray | None = None


PARALLEL_ROWS = 8192  # from this many design rows the four analyses run in two forked processes


CONF_LEVEL = 0.95  # the bootstrap intervals' level
# :func:`_first_and_total` repeats ``sobol.analyze``'s steps (its resample draws among them) and gives its numbers to the
# bit on these SALib releases; on any other the steps may have changed, so ``analyze`` itself runs: slower, never other
CHECKED_SALIB = ((1, 6),)


def salib_release() -> tuple[int, ...]:
    """The installed SALib's (major, minor) release, () if its version string is not numbers."""
    from importlib.metadata import version

    try:
        return tuple(int(part) for part in version("SALib").split(".")[:2])
    except ValueError:  # pragma: no cover - an unusual version string: SALib's own analyze
        return ()


def _analyze_one(args) -> dict:
    """SALib's analysis of one response column, as plain arrays (picklable): first and total order by
    :func:`_first_and_total`, with second order SALib's ``sobol.analyze`` itself."""
    prob, y, second_order, resamples, boot_seed = args
    if not second_order:
        return _first_and_total(prob, y, resamples, boot_seed)
    r = _salib().analyze(prob, y, calc_second_order=True, num_resamples=resamples, conf_level=CONF_LEVEL, seed=boot_seed)
    return {k: np.asarray(r[k]) for k in ("S1", "S1_conf", "ST", "ST_conf", "S2", "S2_conf")}


def _first_and_total(prob: dict, y: np.ndarray, resamples: int, seed: int) -> dict:
    """S1, S1_conf, ST, ST_conf (arrays over the parameters, dimensionless) of one response column ``y`` of a design of
    :func:`sample` without second order: SALib's ``sobol.analyze(prob, y, calc_second_order=False, num_resamples=
    resamples, conf_level=CONF_LEVEL, seed=seed)`` to the bit (tests), for ``seed`` > 0.

    The same steps as SALib's (``separate_output_values``, the estimators of ``first_order`` and ``total_order``,
    scipy's normal quantile) on the same arrays, in the same order, but each bootstrap resample of A and B gathered once
    for all parameters where ``analyze`` gathers it three times per parameter, their spread (whether the intervals are
    zero) measured once, and the variance of [A; B] both estimators divide by computed once per A and B
    (:class:`_Estimators`) where SALib's recompute it per parameter and estimator: that was 40 %, then half of the rest.
    """
    sal = _salib()
    d = prob["num_vars"]
    # SALib's own: unseeded resamples, its error for a design of another shape, or a SALib release whose steps (the
    # order it draws its resamples in, its estimators) were not checked against these (tests/test_sobol_analysis_is_salibs.py)
    if not seed or y.size % (d + 2) or salib_release() not in CHECKED_SALIB:
        r = sal.analyze(prob, y, calc_second_order=False, num_resamples=resamples, conf_level=CONF_LEVEL, seed=seed)
        return {k: np.asarray(r[k]) for k in ("S1", "S1_conf", "ST", "ST_conf")}
    n = y.size // (d + 2)
    y = (y - y.mean()) / y.std()
    A, B, AB, _ = sal.separate_output_values(y, d, n, False)
    r = np.random.default_rng(seed).integers(n, size=(n, resamples))
    z = sal.norm.ppf(0.5 + CONF_LEVEL / 2)
    A_r, B_r = A[r], B[r]
    spread = np.ptp(np.r_[A_r, B_r]) != 0.0
    whole, resampled = _Estimators(sal, A, B), _Estimators(sal, A_r, B_r)
    out = {k: np.zeros(d) for k in ("S1", "S1_conf", "ST", "ST_conf")}
    for j in range(d):
        AB_r = AB[r, j]
        out["S1"][j] = whole.first_order(AB[:, j])
        s1 = resampled.first_order(AB_r)
        out["S1_conf"][j] = z * s1.std(ddof=1) if spread else 0.0
        out["ST"][j] = whole.total_order(AB[:, j])
        st = resampled.total_order(AB_r)
        out["ST_conf"][j] = z * st.std(ddof=1) if spread else 0.0
    return out


class _Estimators:
    """SALib 1.6's ``first_order(A, AB, B)`` and ``total_order(A, AB, B)`` of one A and B (the rows of the base matrices,
    or their bootstrap resamples, (n,) or (n, resamples)) for any AB, their numbers to the bit: the same operations on
    the same arrays, but the variance of [A; B] that both divide by, and its spread, computed once here rather than in
    each call (per parameter and estimator: ~0.25 s of CPU of each analysis at N = 2048). Where [A; B] has no spread,
    SALib's own estimators (which warn and give zeros)."""

    def __init__(self, sal, A: np.ndarray, B: np.ndarray):
        self.sal, self.A, self.B = sal, A, B
        y = np.r_[A, B]
        self.constant = np.ptp(y) <= np.finfo(float).eps
        self.y_var = np.var(y, axis=0)
        self.divides = self.y_var > np.finfo(float).eps

    def first_order(self, AB: np.ndarray):
        """S1 (dimensionless; an array over the resamples of 2-D A and B) of the parameter whose column AB takes."""
        if self.constant:
            return self.sal.first_order(self.A, AB, self.B)
        return np.divide(np.mean(self.B * (AB - self.A), axis=0), self.y_var, out=np.zeros_like(self.y_var, dtype=np.float64),
                         where=self.divides)

    def total_order(self, AB: np.ndarray):
        """ST (dimensionless), as :meth:`first_order`."""
        if self.constant:
            return self.sal.total_order(self.A, AB, self.B)
        return np.divide(0.5 * np.mean((self.A - AB) ** 2, axis=0), self.y_var, out=np.zeros_like(self.y_var, dtype=np.float64),
                         where=self.divides)


_HEAP_SET = []


def _reuse_freed_memory() -> None:
    """Let glibc keep freed blocks of up to 64 MB for reuse (once per process; elsewhere a no-op).

    SALib's bootstrap allocates and frees arrays of a few MB per parameter and resample set; by default
    glibc maps each from the system afresh and returns it, and the page faults cost as much system time as
    the analysis itself (measured: 1.1 s user + 1.1 s system for N = 2048, 28 parameters; 0.0 s system
    with this). The memory is returned to the system when the process ends.
    """
    if _HEAP_SET:
        return
    _HEAP_SET.append(True)
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 64 << 20)  # M_MMAP_THRESHOLD: blocks below 64 MB come from the heap
        libc.mallopt(-1, 128 << 20)  # M_TRIM_THRESHOLD: keep up to 128 MB of freed heap for reuse
    except (OSError, AttributeError):  # not glibc
        pass


def _workers(rows: int, workers: int | None) -> int:
    if workers is not None:
        return workers
    if rows < PARALLEL_ROWS or "fork" not in multiprocessing.get_all_start_methods():
        return 1
    return min(2, os.cpu_count() or 1)


def analyze(prob: dict, Y: np.ndarray, seed: int, second_order: bool = False, resamples: int = 100,
            workers: int | None = None, pool: ProcessPoolExecutor | None = None) -> list[Indices]:
    """First-order and total indices (and second order on request) for each response column of Y.

    ``workers``: processes for the four analyses (default: 2 for a large design where the system can fork,
    else 1); ``pool``: run it all in that process instead (:func:`salib_workers`), which then forks the
    same ``workers``. Each analysis has its own seeded bootstrap, so the result depends on neither.
    """
    if pool is not None:
        return pool.submit(analyze, prob, Y, seed, second_order, resamples, workers).result()
    # SALib 1.6 seeds its bootstrap only `if seed:`, so seed 0 would silently draw unseeded resamples (the
    # intervals then change from run to run); hand it a derived seed that is never 0
    boot_seed = int(np.random.SeedSequence(seed).generate_state(1)[0]) or 1
    for k, name in enumerate(RESPONSES):
        y = Y[:, k]
        if np.ptp(y) == 0.0:
            raise PressDataError("sensitivity", name, float(y[0]), "does not vary over the design, so it has no Sobol indices")
    _reuse_freed_memory()
    jobs = [(prob, np.ascontiguousarray(Y[:, k]), second_order, resamples, boot_seed) for k in range(len(RESPONSES))]
    n_workers = _workers(len(Y), workers)
    if n_workers > 1:
        # forked children inherit the imported SALib: imported here, once (in a salib_workers process it is already),
        # rather than by each child (`reproduce`: four imports of SALib and pandas, ~0.5 s of CPU each, became two);
        # SALib's bootstrap is serial Python and numpy, so two processes halve its wall time on two cores
        _salib()
        with ProcessPoolExecutor(n_workers, mp_context=multiprocessing.get_context("fork")) as pool:
            results = list(pool.map(_analyze_one, jobs))
    else:
        results = [_analyze_one(j) for j in jobs]
    return [Indices(name, tuple(prob["names"]), r["S1"], r["S1_conf"], r["ST"], r["ST_conf"], r.get("S2"), r.get("S2_conf"))
            for name, r in zip(RESPONSES, results)]


def key_parameters(indices: Iterable[Indices], threshold: float = SCREEN_THRESHOLD) -> list[str]:
    """Section 3.3's rule: S_T > threshold on Y_RMSE or on Y_PR; ordered by the larger of the two."""
    best: dict[str, float] = {}
    for ind in indices:
        if ind.response not in CORE_RESPONSES:
            continue
        for name, st in zip(ind.names, ind.ST):
            if st > threshold:
                best[name] = max(best.get(name, 0.0), float(st))
    return sorted(best, key=lambda n: -best[n])


def rule_text(threshold: float = SCREEN_THRESHOLD) -> str:
    return f"S_T > {threshold} on Y_RMSE or on Y_PR (paper Section 3.3)"


def table_rows(indices: Iterable[Indices]) -> list[dict]:
    """Rows of sobol.csv: response, parameter, S1, S1_conf, ST, ST_conf."""
    rows = []
    for ind in indices:
        for i, name in enumerate(ind.names):
            rows.append({"response": ind.response, "parameter": name, "S1": float(ind.S1[i]), "S1_conf": float(ind.S1_conf[i]),
                         "ST": float(ind.ST[i]), "ST_conf": float(ind.ST_conf[i])})
    return rows


def figure(indices: list[Indices], title: str):
    """Four panels like the paper's Figure 3: S1 and ST bars with intervals, parameters with ST >= 0.01."""
    from press_model.plots import subplots, tight_layout

    fig, axes = subplots(2, 2, figsize=(11, 7.5))
    for ax, ind, tag in zip(axes.flat, indices, "abcd"):
        keep = np.flatnonzero(ind.ST >= PLOT_THRESHOLD)
        keep = keep[np.argsort(-ind.ST[keep])]
        x = np.arange(len(keep))
        ax.bar(x - 0.2, ind.S1[keep], 0.4, yerr=ind.S1_conf[keep], capsize=3, label="S1 (first order)", color="C0")
        ax.bar(x + 0.2, ind.ST[keep], 0.4, yerr=ind.ST_conf[keep], capsize=3, label="ST (total)", color="C1")
        ax.set_xticks(x, [ind.names[i] for i in keep], rotation=45, ha="right")
        ax.axhline(SCREEN_THRESHOLD, color="0.4", ls=":", lw=1)
        ax.set_title(f"({tag}) {ind.response}", fontsize=10)
        ax.set_ylabel("Sobol index")
        ax.grid(axis="y", alpha=0.3)
        if tag == "a":
            ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    tight_layout(fig)
    return fig
