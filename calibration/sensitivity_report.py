"""The 'sensitivity' command: Sobol indices of the four responses on the cushion-test cycle, written to a folder.

Outputs: sobol.csv, key_parameters.json, sobol_indices.png (Figure 3 analogue), paper_comparison.csv/.md,
run.json (provenance), and with second order sobol_second_order.csv; the convergence study writes
convergence.csv and convergence.png.
"""
from __future__ import annotations

import math
import time
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np

from . import sensitivity as S
from press_model.batch import DEFAULT_CHUNK, BatchModel, build_batch_model, motor_torques
from press_model.errors import PressDataError
from press_model.jobs import load_job, make_motion
from press_model.model import PressModel
from press_model.outputs import atomic_write_text, versions, write_json, write_table
from press_model.plots import save
from .responses import RESPONSES, all_responses

JOB = "cushion-test"  # Section 3: the responses are defined on the calibration experiment's cycle


def response_evaluator(bm: BatchModel, reference=None, chunk_size: int = DEFAULT_CHUNK, backend: str = "auto"):
    """A callable mapping parameter rows (B, D) to the responses (B, 4) of :mod:`calibration.responses` (Eqs. 22-25).

    ``reference``: the T_ref curve of Eqs. 22-23 (N m, per motor, on this grid); by default the curve of
    the nominal (theoretical) parameters. Fits :func:`calibration.sensitivity.evaluate`.
    """
    t_ref = motor_torques(bm, bm.nominal[None], backend=backend)[0] if reference is None else np.asarray(reference, dtype=float)
    if t_ref.shape != (bm.n_points,):
        raise PressDataError("batch", "reference", t_ref.shape, f"must be one torque curve of {bm.n_points} samples")

    def evaluate(X: np.ndarray) -> np.ndarray:
        T = motor_torques(bm, X, chunk_size, backend=backend)
        return all_responses(T, t_ref, bm.theta_dot, bm.gear_ratio)

    return evaluate


def paper_figures() -> dict:
    """The paper's quoted S_T values and key set (data file, for comparison only)."""
    return tomllib.loads(resources.files("press_model.data").joinpath("paper_figures.toml").read_text(encoding="utf-8"))


def _evaluator(pm: PressModel):
    job = load_job(JOB)
    motion = make_motion(job.motion, job.source)
    bm = build_batch_model(pm.press, motion, job.process, pm=pm)
    return response_evaluator(bm), job


def run_sensitivity(pm: PressModel, n: int, seed: int, second_order: bool, out: Path, progress: bool = True) -> dict:
    """Sample, evaluate, analyse and write the results; returns the run record (also in run.json)."""
    t0 = time.perf_counter()
    prob = S.problem(pm.press)
    X = S.sample(prob, n, seed, second_order)
    evaluate, job = _evaluator(pm)
    t1 = time.perf_counter()
    Y = S.evaluate(evaluate, X, progress=progress)
    t2 = time.perf_counter()
    indices = S.analyze(prob, Y, seed, second_order)
    t3 = time.perf_counter()
    keys = S.key_parameters(indices)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_table(out / "sobol.csv", ["response", "parameter", "S1", "S1_conf", "ST", "ST_conf"], S.table_rows(indices))
    if second_order:
        rows = []
        for ind in indices:
            d = len(ind.names)
            for i in range(d):
                for j in range(i + 1, d):
                    rows.append({"response": ind.response, "parameter_1": ind.names[i], "parameter_2": ind.names[j],
                                 "S2": float(ind.S2[i, j]), "S2_conf": float(ind.S2_conf[i, j])})
        write_table(out / "sobol_second_order.csv", ["response", "parameter_1", "parameter_2", "S2", "S2_conf"], rows)
    record = {
        "press": pm.press.name,
        "press_source": pm.press.source,
        "press_fingerprint": pm.press.fingerprint,
        "job": job.name,
        "method": "Sobol (SALib sobol sampling and analysis), bootstrap 95 % intervals, 100 resamples",
        "n": n,
        "seed": seed,
        "second_order": second_order,
        "model_cycles": int(len(X)),
        "responses": list(RESPONSES),
        "parameters": {p.name: {"nominal": p.nominal, "low": p.low, "high": p.high, "unit": p.unit} for p in pm.press.parameters.values()},
        "versions": versions(),
    }
    write_json(out / "key_parameters.json", {"key_parameters": keys, "rule": S.rule_text(), "provenance": record})
    title = f"Sobol indices, {pm.press.name}, cushion-test cycle, N = {n}, seed {seed}"
    save(S.figure(indices, title), out / "sobol_indices.png")
    _write_comparison(out, indices, keys)
    write_json(out / "run.json", record)
    # wall times are printed, not written: the same seed must give the same bytes
    return {**record, "key_parameters": keys, "timing_s": {"setup": t1 - t0, "evaluation": t2 - t1, "analysis": t3 - t2, "total": t3 - t0}}


def _write_comparison(out: Path, indices, keys: list[str]) -> None:
    """Our S_T beside the values the paper quotes for Figure 3, and the key set each selects."""
    paper = paper_figures()
    quoted = paper["sobol_total_effect"]
    rows, md = [], ["| response | parameter | S_T ours (95 % CI) | S_T paper |", "|---|---|---|---|"]
    for ind in indices:
        q = quoted.get(ind.response, {})
        names = sorted(set(q) | {ind.names[i] for i in np.flatnonzero(ind.ST >= S.PLOT_THRESHOLD)},
                       key=lambda nm: -ind.ST[ind.names.index(nm)])
        for nm in names:
            i = ind.names.index(nm)
            rows.append({"response": ind.response, "parameter": nm, "ST_ours": float(ind.ST[i]), "ST_ours_conf": float(ind.ST_conf[i]),
                         "ST_paper": float(q[nm]) if nm in q else float("nan")})
            pv = f"{q[nm]:.3f}" if nm in q else "not quoted"
            md.append(f"| {ind.response} | {nm} | {ind.ST[i]:.3f} ± {ind.ST_conf[i]:.3f} | {pv} |")
    write_table(out / "paper_comparison.csv", ["response", "parameter", "ST_ours", "ST_ours_conf", "ST_paper"], rows)
    pk = paper["key_parameters"]["paper"]
    md += ["", f"Key parameters ({S.rule_text()}):", "", f"* ours: {', '.join(keys) or 'none'}", f"* paper: {', '.join(pk)}",
           f"* in both: {', '.join(k for k in keys if k in pk) or 'none'}; only ours: {', '.join(k for k in keys if k not in pk) or 'none'};"
           f" only the paper's: {', '.join(k for k in pk if k not in keys) or 'none'}"]
    atomic_write_text(out / "paper_comparison.md", "\n".join(md) + "\n")


def run_convergence(pm: PressModel, ns: list[int], seed: int, out: Path, parameters: list[str] | None = None,
                    progress: bool = True) -> list[dict]:
    """S_T with intervals of the given (default: key) parameters for each N; writes convergence.csv/.png."""
    prob = S.problem(pm.press)
    evaluate, _ = _evaluator(pm)
    rows = []
    for n in ns:
        if progress:
            print(f"  N = {n}: {n * (prob['num_vars'] + 2)} model cycles", flush=True)
        X = S.sample(prob, n, seed)
        indices = S.analyze(prob, S.evaluate(evaluate, X, progress=progress), seed)
        if parameters is None:
            parameters = S.key_parameters(indices)
        for ind in indices:
            for nm in parameters:
                i = ind.names.index(nm)
                rows.append({"n": n, "response": ind.response, "parameter": nm, "ST": float(ind.ST[i]), "ST_conf": float(ind.ST_conf[i])})
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_table(out / "convergence.csv", ["n", "response", "parameter", "ST", "ST_conf"], rows)
    write_json(out / "convergence.json", {"ns": ns, "seed": seed, "parameters": parameters, "press": pm.press.name,
                                         "press_fingerprint": pm.press.fingerprint, "versions": versions()})
    save(_convergence_figure(rows, parameters), out / "convergence.png")
    return rows


def _convergence_figure(rows, parameters):
    from press_model.plots import plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    for ax, resp in zip(axes.flat, RESPONSES):
        for k, nm in enumerate(parameters):
            pts = [r for r in rows if r["response"] == resp and r["parameter"] == nm]
            n = np.array([r["n"] for r in pts])
            st = np.array([r["ST"] for r in pts])
            ci = np.array([r["ST_conf"] for r in pts])
            ax.errorbar(n * (1 + 0.03 * (k - len(parameters) / 2)), st, yerr=ci, marker="o", ms=3, capsize=2, label=nm)
        ax.set_xscale("log", base=2)
        ax.set_title(resp, fontsize=10)
        ax.set_ylabel("S_T")
        ax.grid(alpha=0.3)
    axes[1, 0].set_xlabel("N (base samples)")
    axes[1, 1].set_xlabel("N (base samples)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Convergence of the total-effect indices with N (bars: 95 % bootstrap intervals)", fontsize=10)
    fig.tight_layout()
    return fig


def powers_of_two(lo: int, hi: int) -> list[int]:
    """The powers of two from ``lo`` to ``hi`` (both powers of two, 2 <= lo <= hi): the N of a convergence study."""
    for flag, n in (("--n-min", lo), ("--n-max", hi)):
        if not isinstance(n, int) or n < 2 or n & (n - 1):
            raise PressDataError("--convergence", flag, n, "must be a power of two of at least 2 (e.g. 256, 8192)")
    if hi < lo:
        raise PressDataError("--convergence", "--n-max", hi, f"must be at least --n-min ({lo})")
    return [2**k for k in range(int(math.log2(lo)), int(math.log2(hi)) + 1)]
