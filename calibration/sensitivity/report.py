"""The 'sensitivity' command: Sobol indices of the four responses on a load case's cycle, written to a folder.

The load case is a job's process force (Eq. 14) and crank motion: the job's ``[motion]``, or one turn of a
planned profile (:func:`press_model.profile_motion.read_profile_motion`). The default is the cushion test,
the calibration experiment's cycle; the key set depends on the load (the paper does not state its own).

Outputs: sobol.csv, key_parameters.json, sobol_indices.png (Figure 3 analogue), paper_comparison.csv/.md,
run.json (provenance), and with second order sobol_second_order.csv; the convergence study writes
convergence.csv and convergence.png.
"""
from __future__ import annotations

import copy
import math
import time
import tomllib
from contextlib import nullcontext
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from calibration.sensitivity import sobol as S
from press_io.errors import PressDataError
from press_model.jobs import Job, load_job, make_motion
from press_model.limits import check_sobol_n
from press_io.outputs import atomic_write_text, output_folder, versions, write_json, write_table
from press_model.params import load_model
from press_model.plots import save, save_later
from press_model.press_data import is_reference_press
from calibration.responses import RESPONSES, all_responses

if TYPE_CHECKING:  # the batch model (numba, Pinocchio; ~0.3 s) is imported where used: after the SALib process forks
    from press_model.batch import BatchModel
    from press_model.model import PressModel

JOB = "cushion-test"  # the default load case: the calibration experiment's cycle (Section 4.1)
MOTION_OF_JOB = "[motion] of the job"
# design rows per evaluator call: a Sobol design repeats link 4's COM distances within each base row's
# D + 2 rows, and the batch evaluator fits each distinct row once per call; 4 progress steps at N = 2048
EVAL_BLOCK = 16384
KERNEL_CHUNK = 1024  # sets per compiled-kernel call: fewer calls (thread start-up, padding) than batch's default 256


@dataclass(frozen=True)
class LoadCase:
    """The cycle the responses are evaluated on: a job's process force and a crank motion."""

    job: Job
    motion: object  # a motion of press_model.motion
    motion_source: str  # MOTION_OF_JOB or the profile's path

    @property
    def label(self) -> str:
        """One line for titles and reports: the job's name and where the motion came from."""
        return self.job.name if self.motion_source == MOTION_OF_JOB else f"{self.job.name}, motion of {self.motion_source}"

    def record(self) -> dict:
        """The load case as plain data for run.json (SI units)."""
        forces = np.asarray(self.job.process.forces, dtype=float)
        return {"job": self.job.name, "job_source": self.job.source, "motion": self.motion_source,
                "period_s": float(self.motion.period), "peak_process_force_N": float(np.max(np.abs(forces)))}


def load_case(job: str | Path | Job = JOB, profile: str | Path | None = None) -> LoadCase:
    """The load case of a job (built-in name or file, or the job read already) with its own ``[motion]`` or, if given,
    a profile CSV's turn."""
    from press_model.profile_motion import read_profile_motion

    jb = job if isinstance(job, Job) else load_job(job)
    if profile is not None:
        return LoadCase(jb, read_profile_motion(profile), str(profile))
    if jb.motion is None:
        raise PressDataError(jb.source, "motion", None, "is missing: the sensitivity cycle needs the job's [motion] table "
                             "(kind = \"constant\" or \"modulated\"), or give a planned profile with --profile profile.csv")
    return LoadCase(jb, make_motion(jb.motion, jb.source), MOTION_OF_JOB)


def response_evaluator(bm: BatchModel, reference=None, chunk_size: int = KERNEL_CHUNK, backend: str = "auto"):
    """A callable mapping parameter rows (B, D) to the responses (B, 4) of :mod:`calibration.responses` (Eqs. 22-25).

    ``reference``: the T_ref curve of Eqs. 22-23 (N m, per motor, on this grid); by default the curve of
    the nominal (theoretical) parameters. Fits :func:`calibration.sensitivity.sobol.evaluate`.
    """
    from press_model.batch import iter_chunks, motor_torques

    t_ref = motor_torques(bm, bm.nominal[None], backend=backend)[0] if reference is None else np.asarray(reference, dtype=float)
    if t_ref.shape != (bm.n_points,):
        raise PressDataError("batch", "reference", t_ref.shape, f"must be one torque curve of {bm.n_points} samples")

    def evaluate(X: np.ndarray) -> np.ndarray:
        # the responses chunk by chunk: the torque curves of a whole block never sit in memory at once
        out = np.empty((len(X), len(RESPONSES)))
        for rows, res in iter_chunks(bm, X, chunk_size, backend=backend):
            out[rows] = all_responses(res.motor_torque, t_ref, bm.theta_dot, bm.gear_ratio)
        return out

    return evaluate


def paper_figures() -> dict:
    """The paper's quoted S_T values and key set (data file, for comparison only); a fresh copy each call."""
    return copy.deepcopy(_paper_figures())


@lru_cache(maxsize=1)
def _paper_figures() -> dict:
    """paper_figures.toml, read once a process (it ships with the package; a report, a calibration and reproduce take it)."""
    return tomllib.loads(resources.files("press_model.data").joinpath("paper_figures.toml").read_text(encoding="utf-8"))


def _batch_model(pm: PressModel, case: LoadCase) -> BatchModel:
    """The batch model of the press under the load case, refused (one line) where the crank does not turn at some grid angle."""
    from press_model.batch import build_batch_model

    bm = build_batch_model(pm.press, case.motion, case.job.process, pm=pm)
    if not np.all(bm.theta_dot > 0):
        p = int(np.argmax(~(bm.theta_dot > 0)))
        raise PressDataError(case.motion_source, "crank speed", float(bm.theta_dot[p]),
                             f"is not positive at crank angle {math.degrees(bm.theta[p]):.6g} deg of the 1-degree grid: Eqs. 24-25 "
                             "weight each grid angle by the time the crank takes to pass it, so the crank must turn at every grid angle")
    return bm


def _evaluator(pm: PressModel, cases: list[LoadCase]):
    """The response evaluator of the load cases: one case's (B, 4) responses, or several side by side (B, 4 k)
    (:func:`load_cases.cases_evaluator`: what the cases share computed once)."""
    bms = [_batch_model(pm, case) for case in cases]
    if len(bms) == 1:
        return response_evaluator(bms[0])
    from calibration.sensitivity.load_cases import cases_evaluator

    return cases_evaluator(bms, KERNEL_CHUNK)


def run_sensitivity(pm: PressModel, n: int, seed: int, second_order: bool, out: Path, progress: bool = True,
                    case: LoadCase | None = None, workers=None) -> dict:
    """Sample, evaluate, analyse and write the results; returns the run record (also in run.json).

    ``case``: the load case (default: the cushion test with its own motion, :func:`load_case`); ``workers``:
    :func:`sensitivity.salib_workers` to sample while the batch model is built and to analyse (default:
    sample here, analyse in processes forked for it). The same files either way.
    """
    return run_sensitivities(pm, n, seed, second_order, [(load_case() if case is None else case, out)], progress, workers)[0]


def run_sensitivities(pm: PressModel, n: int, seed: int, second_order: bool, runs: list[tuple[LoadCase, Path]],
                      progress: bool = True, workers=None) -> list[dict]:
    """:func:`run_sensitivity` of one design under each load case of ``runs`` ((case, output folder) pairs): the same
    files in each folder, the design sampled once and the cases' model cycles evaluated together (the work they share
    done once, :mod:`load_cases`). Returns the run records in the order of ``runs``."""
    t0 = time.perf_counter()
    prob = S.problem(pm.press)
    design = S.sample_later(prob, n, seed, second_order, workers)
    evaluate = _evaluator(pm, [case for case, _ in runs])
    X = design.result()
    t1 = time.perf_counter()
    Y = S.evaluate(evaluate, X, chunk=EVAL_BLOCK, progress=progress, columns=len(RESPONSES) * len(runs))
    t2 = time.perf_counter()
    records = []
    for k, (case, out) in enumerate(runs):
        t = time.perf_counter()
        indices = S.analyze(prob, Y[:, len(RESPONSES) * k : len(RESPONSES) * (k + 1)], seed, second_order, pool=workers)
        t3 = time.perf_counter()
        sampling = {"n": n, "seed": seed, "second_order": second_order, "model_cycles": int(len(X))}
        record = _write_run(pm, Path(out), case, indices, sampling, workers)
        records.append({**record, "timing_s": {"setup": t1 - t0, "evaluation": t2 - t1, "analysis": t3 - t, "total": t3 - t0}})
    return records


def _write_run(pm: PressModel, out: Path, case: LoadCase, indices: list, sampling: dict, workers) -> dict:
    """Write one load case's sensitivity files into ``out`` (sobol.csv, key_parameters.json, sobol_indices.png,
    paper_comparison.csv/.md, run.json; sobol_second_order.csv with second order); returns the run record with the key
    parameters (run.json holds it without them). ``sampling``: the design's n, seed, second_order and model_cycles."""
    n, seed, second_order = sampling["n"], sampling["seed"], sampling["second_order"]
    keys = S.key_parameters(indices)
    out.mkdir(parents=True, exist_ok=True)
    # the figure in the SALib process (matplotlib imported there at its start) while this writes the tables
    title = f"Sobol indices, {pm.press.name}, {case.label}, N = {n}, seed {seed}"
    drawn = save_later(workers, S.figure, (indices, title), out / "sobol_indices.png")
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
        **pm.press.identity(),
        "job": case.job.name,
        "load_case": case.record(),
        "method": "Sobol (SALib sobol sampling and analysis), bootstrap 95 % intervals, 100 resamples",
        **sampling,
        "responses": list(RESPONSES),
        "parameters": {p.name: {"nominal": p.nominal, "low": p.low, "high": p.high, "unit": p.unit} for p in pm.press.parameters.values()},
        "versions": versions(),
    }
    write_json(out / "key_parameters.json", {"key_parameters": keys, "rule": S.rule_text(), "provenance": record})
    _write_comparison(out, indices, keys, case, is_reference_press(pm.press.fingerprint))
    drawn.result()
    write_json(out / "run.json", record)
    # wall times are printed, not written: the same seed must give the same bytes
    return {**record, "key_parameters": keys}


def _write_comparison(out: Path, indices, keys: list[str], case: LoadCase, reference: bool = True) -> None:
    """Our S_T beside the values the paper quotes for Figure 3, and the key set each selects; on a press that is not
    the reference press (``reference`` False) headed by a line saying whose press the paper's values are of.

    The paper's values are matched by parameter name; a press without some of the paper's names (the
    crank-slider, a user's press) is compared only where the names match, and the file says which are missing.
    """
    paper = paper_figures()
    quoted = paper["sobol_total_effect"]
    ours = set(indices[0].names) if indices else set()
    paper_names = sorted({nm for q in quoted.values() for nm in q} | set(paper["key_parameters"]["paper"]))
    absent = [nm for nm in paper_names if nm not in ours]
    rows, md = [], ["| response | parameter | S_T ours (95 % CI) | S_T paper |", "|---|---|---|---|"]
    for ind in indices:
        q = {nm: v for nm, v in quoted.get(ind.response, {}).items() if nm in ours}
        col = {nm: i for i, nm in enumerate(ind.names)}
        names = sorted(set(q) | {ind.names[i] for i in np.flatnonzero(ind.ST >= S.PLOT_THRESHOLD)}, key=lambda nm: (-ind.ST[col[nm]], nm))
        for nm in names:
            i = col[nm]
            rows.append({"response": ind.response, "parameter": nm, "ST_ours": float(ind.ST[i]), "ST_ours_conf": float(ind.ST_conf[i]),
                         "ST_paper": float(q[nm]) if nm in q else float("nan")})
            pv = f"{q[nm]:.3f}" if nm in q else "not quoted"
            md.append(f"| {ind.response} | {nm} | {ind.ST[i]:.3f} ± {ind.ST_conf[i]:.3f} | {pv} |")
    write_table(out / "paper_comparison.csv", ["response", "parameter", "ST_ours", "ST_ours_conf", "ST_paper"], rows)
    pk = [k for k in paper["key_parameters"]["paper"] if k in ours]
    whose = [] if reference else [
        "The paper's S_T (column 'S_T paper') are of the paper's own press, the 25,000 kN eight-bar reference press, not of "
        "this one: they stand beside ours to compare the method's ranking, and say nothing about this press.", ""]
    md = whose + [f"Load case: {case.label} (peak process force {case.record()['peak_process_force_N'] / 1e3:,.0f} kN, "
          f"cycle {case.motion.period:.4g} s). The paper does not state the load case or motion of its Figure 3, "
          "and the key set depends on it (see calibration/README.md, 'Which load case gives which key set').", ""] + md
    if absent:
        md += ["", f"This press has no parameter named {', '.join(absent)}: the paper's values for "
               f"{'them' if len(absent) > 1 else 'it'} are left out, and the comparison holds only where the names match"
               + (" (none do)." if len(absent) == len(paper_names) else ".")]
    md += ["", f"Key parameters ({S.rule_text()}):", "", f"* ours: {', '.join(keys) or 'none'}",
           f"* paper: {', '.join(paper['key_parameters']['paper'])}"
           + (f" (of which this press has {', '.join(pk) or 'none'})" if absent else ""),
           f"* in both: {', '.join(k for k in keys if k in pk) or 'none'}; only ours: {', '.join(k for k in keys if k not in pk) or 'none'};"
           f" only the paper's: {', '.join(k for k in pk if k not in keys) or 'none'}"]
    atomic_write_text(out / "paper_comparison.md", "\n".join(md) + "\n")


def run_convergence(pm: PressModel, ns: list[int], seed: int, out: Path, parameters: list[str] | None = None,
                    progress: bool = True, case: LoadCase | None = None) -> list[dict]:
    """S_T with intervals of the given (default: key) parameters for each N; writes convergence.csv/.png."""
    case = load_case() if case is None else case
    prob = S.problem(pm.press)
    evaluate = _evaluator(pm, [case])
    rows = []
    for n in ns:
        if progress:
            print(f"  N = {n}: {n * (prob['num_vars'] + 2)} model cycles", flush=True)
        X = S.sample(prob, n, seed)
        indices = S.analyze(prob, S.evaluate(evaluate, X, chunk=EVAL_BLOCK, progress=progress), seed)
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
                                         "press_fingerprint": pm.press.fingerprint, "load_case": case.record(), "versions": versions()})
    save(_convergence_figure(rows, parameters), out / "convergence.png")
    return rows


def _convergence_figure(rows, parameters):
    from press_model.plots import subplots, tight_layout

    fig, axes = subplots(2, 2, figsize=(11, 7.5), sharex=True)
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
    tight_layout(fig)
    return fig


def powers_of_two(lo: int, hi: int) -> list[int]:
    """The powers of two from ``lo`` to ``hi`` (both powers of two, 2 <= lo <= hi): the N of a convergence study."""
    for flag, n in (("--n-min", lo), ("--n-max", hi)):
        if not isinstance(n, int) or n < 2 or n & (n - 1):
            raise PressDataError("--convergence", flag, n, "must be a power of two of at least 2 (e.g. 256, 8192)")
    if hi < lo:
        raise PressDataError("--convergence", "--n-max", hi, f"must be at least --n-min ({lo})")
    return [2**k for k in range(int(math.log2(lo)), int(math.log2(hi)) + 1)]


@dataclass(frozen=True)
class SobolPlan:
    """How the 'sensitivity' command samples (``--n``, ``--seed``, ``--second-order``, ``--convergence``, ``--n-min``,
    ``--n-max``): the Sobol base sample size N, the seed of the scrambled design and the bootstrap, and whether the
    second-order indices are computed too; or, with ``convergence``, S_T over the powers of two from ``n_min`` to
    ``n_max`` instead."""

    n: int = 2048
    seed: int = 0
    second_order: bool = False
    convergence: bool = False
    n_min: int = 256
    n_max: int = 8192


@lru_cache(maxsize=1)
def _reference_fingerprint() -> str:
    """The shipped reference press's fingerprint, read once a process."""
    from press_model.press_data import load_press

    return load_press(None).fingerprint


def sensitivity_job(press: str | None, job: str, profile: str | None, plan: SobolPlan, out: str,
                    warn=lambda text: None) -> list[str]:
    """The 'sensitivity' command: :func:`run_sensitivity` (or with ``plan.convergence`` :func:`run_convergence`) on the
    load case of ``job`` (and ``profile``) into the folder ``out``, written whole at the end. ``warn`` gets the warning
    of a small N before the run. Returns the lines to print.
    """
    n, seed, convergence = plan.n, plan.seed, plan.convergence
    # the SALib process starts first, before this process imports the batch model (numba, Pinocchio): its
    # imports and the sampling overlap this process's own and the batch model's build. The convergence study
    # samples and analyses here
    with (nullcontext() if convergence else S.salib_workers()) as workers:
        if convergence:
            ns = powers_of_two(plan.n_min, plan.n_max)
            check_sobol_n("--n-min", ns[0])
            check_sobol_n("--n-max", ns[-1])
        else:
            warning = check_sobol_n("--n", n)
        pm, _ = load_model(press)
        case = load_case(job, profile)
        if job == JOB and profile is None and pm.press.fingerprint != _reference_fingerprint():
            warn(f"the load case is the shipped cushion test ({case.label}, made for the reference press), not {pm.press.name}'s "
                 "own: the key set depends on the load, so give --job with the job of the run you will calibrate on (e.g. "
                 "your copy of cushion_test.toml with your cushion's [process])")
        if convergence:
            with output_folder(out, [press, job, profile], "sensitivity --convergence") as tmp:
                rows = run_convergence(pm, ns, seed, tmp, case=case)
            return [f"convergence of S_T over N = {ns[0]}..{ns[-1]} ({len(rows)} rows) -> {out}/convergence.csv, convergence.png"]
        if warning:
            warn(warning)
        with output_folder(out, [press, job, profile], "sensitivity") as tmp:
            rec = run_sensitivity(pm, n, seed, plan.second_order, tmp, case=case, workers=workers)
    t = rec["timing_s"]
    return [f"{case.label}: {rec['model_cycles']} model cycles in {t['evaluation']:.1f} s (total {t['total']:.1f} s); "
            f"key parameters: {', '.join(rec['key_parameters'])} -> {out}"]
