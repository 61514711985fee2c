"""The 'compare' command: plans with the theoretical and the calibrated parameters, each evaluated under both models.

For each plan the production rate, and its peak torque ratio (peak |T_m| / T_max) and cycle RMS (Eq. 24,
dwell included) under the theoretical *and* the calibrated parameters: the plan's knot profile (crank speed
and acceleration) is run through the other model's full inverse dynamics (friction fixed point, Eq. 16).
That shows whether the theoretical plan was conservative or unsafe for the press as calibrated, and
whether the calibrated plan keeps the margin. The paper reports 11.4 -> 11.6 spm for its press: set beside ours on the
reference press only, labelled as the paper's.
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import io
import math
import pickle
from concurrent.futures import wait
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from press_io.errors import ServoPressError, one_line
from press_io.forked import SECOND_PROCESS, beside
from press_io.outputs import atomic_write_text, check_output_folder, output_folder, versions, write_json, write_table
from press_io.progress import Progress
from press_model.jobs import Job, load_job
from press_model.model import PressModel
from press_model.motor import motor_torque
from press_model.params import apply_overrides, joint_box_of, overrides_of, read_json
from press_model.plots import save_later
from press_model.press_data import PressData, is_reference_press, load_press

from .cams import CamSettings
from .evaluation import Evaluation, cycle_rms, evaluate_profile
from .figures import Drawing, comparison_figure, figure_worker, speed_figure, torque_figure
from .hold import equivalent_rest, static_stop_torque
from .modes import MODES, keep_fastest, plan_in_mode, plan_modes
from .optimal import clear_solvers
from .path_dynamics import build_path_dynamics, full_crank_torque
from .planner import Plan, StrokeProblem
from .profile import rate_text, reference
from .report import modes_line, robust_line, write_plan_outputs
from .settings import PlanningSpec, read_planning
from .settings import limiting_line, motor_sharing

PAPER_SPM = (11.4, 11.6)  # Section 4.3: theoretical -> calibrated production rate, strokes per minute


def _same_geometry(pm: PressModel, plan: Plan) -> bool:
    """Whether ``pm`` and the plan's own model differ only in parameters that move no joint (a named target: masses,
    inertias, centres of mass, balance, drive, friction; a target without a field may be a length): then the plan's
    knot kinematics serve ``pm`` too (``build_path_dynamics(like=...)``)."""
    own = plan.pd.pm.press.parameter_values()
    changed = [n for n, v in pm.press.parameter_values().items() if own.get(n) != v]
    return all(pm.press.parameters[n].target.field for n in changed)


def evaluate_under(pm: PressModel, plan: Plan, process) -> tuple[Evaluation, float, float, float]:
    """A plan's knot profile through another model ``pm``: (evaluation, peak |T_m| N m, cycle RMS N m, holding torque N m)."""
    pd = build_path_dynamics(pm, plan.grid.theta, process, plan.grid.contact_index, like=plan.pd if _same_geometry(pm, plan) else None)
    ev = evaluate_profile(pm, pd, plan.profile)
    hold = float(motor_torque(pm.press.drive, full_crank_torque(pd, np.zeros(pd.n), np.zeros(pd.n)).crank_torque[0], 0.0, 0.0))
    peak = float(max(np.max(np.abs(ev.motor_right)), np.max(np.abs(ev.motor_left))))
    # the stops on the way (planning.hold) at this model's static torque, in the RMS and the peak
    stops = [dataclasses.replace(st, torque=static_stop_torque(pd, pm.press.drive, None, st.index)[0]) for st in plan.stops]
    peak = max([peak] + [abs(st.torque) for st in stops])
    rest_torque, rest_time = equivalent_rest(hold, plan.dwell, stops)
    return ev, peak, cycle_rms(ev, plan.profile, rest_time, rest_torque), hold


COLUMNS = ["plan", "strokes_per_min", "cycle_time_s", "stroke_time_s", "dwell_s",
           "peak_ratio_theoretical_model", "peak_ratio_calibrated_model",
           "rms_theoretical_model_Nm", "rms_calibrated_model_Nm",
           "within_margin_theoretical_model", "within_margin_calibrated_model",
           "thermal_ok_theoretical_model", "thermal_ok_calibrated_model"]


NOMINAL_ROW = "calibrated-nominal"  # the plan at the calibrated values alone (the point estimate), beside a robust calibrated row


@dataclass(frozen=True)
class Calibrated:
    """A calibration's result as compare takes it: ``values`` (name -> SI value: the calibrated row's overrides), its 95 %
    box ``intervals`` (name -> (low, high); None: no robust row) with ``box_label`` saying which box that is ("joint
    region" or "per-parameter intervals"), and its ``verdict`` (:func:`press_model.calibration_verdict.calibration_verdict`,
    recorded as ``calibration_verdict``; None: none)."""

    values: dict
    intervals: dict | None = None
    box_label: str | None = None
    verdict: dict | None = None

    def __post_init__(self):
        if self.intervals and self.box_label is None:  # the label goes into the table and summary: never guess which box
            raise ValueError("Calibrated: intervals given without box_label ('joint region' or 'per-parameter intervals')")


def run_compare(press: PressData, job: Job, spec: PlanningSpec, calibration: Calibrated, out: Path, verify: bool = True,
                progress: Progress | None = None, figures=None, theoretical=None, theoretical_here: tuple[str, ...] = ()) -> dict:
    """Plan with both parameter sets, cross-evaluate, write the table, figures and each plan's outputs; returns the record.

    ``calibration``: the calibrated values and, with its 95 % box (:class:`Calibrated` ``intervals``), the ``calibrated``
    row is then the plan robust over it (the one a user gets from `plan`),
    and the plan at the calibrated values alone is the row ``calibrated-nominal`` (its outputs in ``out/calibrated-nominal``),
    with the rate the margin over the box costs against it. ``figures``: a :func:`planning.figures.figure_worker` that
    draws the figures while the playback runs (None: drawn here; the same bytes).

    The theoretical row needs nothing of the calibration: it is planned in a process forked here
    (:func:`press_io.forked.beside`, :func:`plan_theoretical`) while this one plans the calibrated rows, or, given
    ``theoretical`` (an object whose ``result()`` returns what :func:`plan_theoretical` returns: `reproduce` plans it in
    its second process), taken from there; with mode = "auto", the modes named in ``theoretical_here`` are planned here
    after the calibrated rows instead (:func:`planning.modes.plan_modes`: each mode's plan reads no other's; `reproduce`
    so evens out its two processes) and the fastest kept (:func:`planning.modes.keep_fastest`). Each row is planned from
    toppra's stroke with no IPOPT solver built before it in its process, so the rows are the same whichever process plans
    them and whatever ran before.
    """
    calibrated, intervals, box_label, verdict = calibration.values, calibration.intervals, calibration.box_label, calibration.verdict
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    progress = progress or Progress("compare", enabled=False)
    models = {"theoretical": PressModel(press), "calibrated": PressModel(apply_overrides(press, calibrated, "--calibrated"))}
    CamSettings.from_job(job)  # the cam's settings checked before the planning (each plan writes its cam files)
    with contextlib.ExitStack() as stack:
        if theoretical is None:  # the theoretical row needs nothing of the calibration: planned beside the calibrated rows
            theoretical = stack.enter_context(beside(functools.partial(plan_theoretical, models["theoretical"], job, spec, progress,
                                                                       theoretical_modes(theoretical_here))))

        def theoretical_plan():
            part, problem = unpack_plan(theoretical.result(), models["theoretical"])
            if spec.mode != "auto":
                return part
            record, kept = part
            if theoretical_here:
                with progress.phase(f"theoretical plan, {', '.join(theoretical_here)}"):
                    clear_solvers()  # as in a process of its own (the same plan whichever process plans it)
                    # on the problem the other process built (its knots, path dynamics and torques at rest): not built twice
                    here = plan_modes(problem, names=theoretical_here)
                record, kept = {**record, **here[0]}, {**kept, **here[1]}
            return keep_fastest(spec, record, kept)

        with progress.phase("calibrated plan" + (" at the calibrated values alone" if intervals else "")):
            calibrated_plan = plan_in_mode(StrokeProblem.build(models["calibrated"], job.process, spec))
        if calibrated_plan.spec.mode == "pendulum":
            _refuse_pendulum(job, {"theoretical": theoretical_plan(), "calibrated": calibrated_plan})
        robust = None
        if intervals:
            from .robust import Box, plan_robust

            box = Box.from_calibration(press, calibrated, intervals, "--calibrated", box_label)
            with progress.phase(f"calibrated plan robust over the calibration's {box_label} ({2 ** len(box.bounds)} corners checked)"):
                robust = plan_robust(models["calibrated"], job.process, spec, box, nominal=calibrated_plan)
        plans = {"theoretical": theoretical_plan(), "calibrated": calibrated_plan}
    _refuse_pendulum(job, plans)
    if robust is not None:
        plans = {"theoretical": plans["theoretical"], "calibrated": robust.plan, NOMINAL_ROW: calibrated_plan}
    motor = press.motor
    limit = spec.torque_limits(motor.peak_torque).verdict
    rows, evals, holds = [], {}, {}
    for pname, plan in plans.items():
        row = {"plan": pname, "strokes_per_min": plan.strokes_per_min, "cycle_time_s": plan.cycle_time,
               "stroke_time_s": plan.stroke_time, "dwell_s": plan.dwell}
        for mname, pm in models.items():
            if mname == pname or (pname == NOMINAL_ROW and mname == "calibrated"):  # the plan's own (centre) model
                ev, rms, hold = plan.evaluation, plan.rms_torque, plan.hold_torque
                peak = float(max(np.max(np.abs(ev.motor_right)), np.max(np.abs(ev.motor_left))))
            else:
                ev, peak, rms, hold = evaluate_under(pm, plan, job.process)
            evals[(pname, mname)], holds[(pname, mname)] = ev, hold
            row[f"peak_ratio_{mname}_model"] = peak / motor.peak_torque
            row[f"rms_{mname}_model_Nm"] = rms
            row[f"within_margin_{mname}_model"] = "yes" if peak <= limit * (1 + 1e-9) else "NO"
            row[f"thermal_ok_{mname}_model"] = "yes" if rms <= motor.rated_torque else "NO"
        rows.append(row)
    gain = 100.0 * (rows[1]["strokes_per_min"] / rows[0]["strokes_per_min"] - 1.0)
    paper = paper_record(press)
    rows_are = ({"theoretical": "planned with the press file's values",
                 "calibrated": f"planned to keep the margin over the calibration's {box_label} (the plan `servo-press plan --params` gives)",
                 NOMINAL_ROW: "planned at the calibrated values alone (the point estimate: `plan --nominal`)"}
                if robust is not None else
                {"theoretical": "planned with the press file's values", "calibrated": "planned at the calibrated values (no region to be robust over)"})
    write_table(out / "comparison.csv", COLUMNS, rows)
    atomic_write_text(out / "comparison.md", _markdown(rows, gain, paper, spec, rows_are)
                      + (modes_markdown(rec_modes) if (rec_modes := {p: pl.modes for p, pl in plans.items() if pl.modes is not None}) else ""))
    rec = {
        "job": job.name, "job_source": job.source, **press.identity(),
        "rows": rows, "rows_are": rows_are, "rate_gain_percent": gain,
        "overloads": overload_lines(rows, spec.torque_margin),
        **({"paper": paper} if paper is not None else {}),
        "peak_torque_limit_Nm": limit, "rated_torque_Nm": motor.rated_torque, "peak_torque_Nm": motor.peak_torque,
        "limiting_motor": spec.sharing.record(plans["calibrated"].peak_torque, motor.peak_torque),  # of the calibrated row
        "binding_constraints": {p: plan.binding for p, plan in plans.items()},
        "parameters": {name: pm.press.parameter_values() for name, pm in models.items()},
        "calibrated_overrides": calibrated,
        "versions": versions(),
    }
    if any(plan.modes is not None for plan in plans.values()):  # planning.mode = "auto": every mode's rate per parameter set
        rec["modes"] = {p: plan.modes for p, plan in plans.items()}
    if robust is not None:
        rec["rate_gain_nominal_percent"] = 100.0 * (rows[2]["strokes_per_min"] / rows[0]["strokes_per_min"] - 1.0)
        rec["robust"] = robust.summary(motor.peak_torque)
    if verdict is not None:
        rec["calibration_verdict"] = verdict
    drawn = []
    try:
        with progress.phase("outputs and figures"):
            energy = {}
            for name, plan in plans.items():
                pm = models["theoretical" if name == "theoretical" else "calibrated"]
                extra = {**({"robust": rec["robust"]} if name == "calibrated" and robust is not None else {}),
                         **({"calibration_verdict": verdict} if verdict is not None and name != "theoretical" else {})}
                info = write_plan_outputs(pm, job, plan, out / name, calibrated if name != "theoretical" else {},
                                          f"{press.name}, {job.name}: {name} parameters" + (" (robust)" if name == "calibrated" and robust is not None else "")
                                          + f", {rate_text(plan.strokes_per_min)}", extra or None, Drawing(figures, drawn))
                energy[name] = _energy_row(plan, info["energy"])
            rec["energy"] = energy
            drawn += _figures(plans, evals, holds, models, spec, rows, out, figures)
        if verify:
            from .playback import run_playback

            with progress.phase("playback of the calibrated plan on the calibrated model (FF + PD)"):
                rec["playback"] = run_playback(models["calibrated"], job, spec, plans["calibrated"], out / "calibrated",
                                               progress=progress.bar("playback"))
    finally:
        wait(drawn)  # no figure is still being written when the folder is swapped in (or removed after an error)
    for f in drawn:
        f.result()
    write_json(out / "comparison.json", rec)
    return rec


def plan_theoretical(pm: PressModel, job: Job, spec: PlanningSpec, progress: Progress | None = None,
                     modes: tuple[str, ...] | None = None) -> bytes:
    """The theoretical row's plan (``pm``: the press file's values) and its problem packed for the process that compares
    (:func:`unpack_plan`); with mode = "auto" the modes ``modes`` (None: every one) as :func:`planning.modes.plan_modes`
    gives them, (record, kept plans), for :func:`planning.modes.keep_fastest` there, packed with the
    :class:`planning.planner.StrokeProblem` they were planned on (the modes planned there take it: built once). Planned
    with no IPOPT solver kept from before (the same plan whichever process plans it)."""
    clear_solvers()
    what = "" if spec.mode != "auto" or modes is None else f", {', '.join(modes)}"
    with (progress or Progress("compare", enabled=False)).phase(f"theoretical plan{what}{SECOND_PROCESS}"):
        problem = StrokeProblem.build(pm, job.process, spec)
        part = plan_modes(problem, names=modes) if spec.mode == "auto" else plan_in_mode(problem)
    return pack_plan((part, problem), pm)


def theoretical_modes(here: tuple[str, ...]) -> tuple[str, ...] | None:
    """The modes of the theoretical row planned in the other process when those in ``here`` are planned in the one that
    compares (None: every mode)."""
    return tuple(n for n in MODES if n not in here) if here else None


class _PlanPickler(pickle.Pickler):
    """Pickles a plan with its press model (Pinocchio's, which does not pickle) and its press data left out by name."""

    def __init__(self, file, pm: PressModel):
        super().__init__(file, protocol=pickle.HIGHEST_PROTOCOL)
        self.pm = pm

    def persistent_id(self, obj):
        if isinstance(obj, (PressModel, PressData)):
            if obj is not self.pm and obj is not self.pm.press:
                raise ValueError("pack_plan: the plan refers to a press model other than the one it was planned on")
            return "pm" if obj is self.pm else "press"
        return None


class _PlanUnpickler(pickle.Unpickler):
    def __init__(self, file, pm: PressModel):
        super().__init__(file)
        self.pm = pm

    def persistent_load(self, pid):
        return {"pm": self.pm, "press": self.pm.press}[pid]


def pack_plan(plan, pm: PressModel) -> bytes:
    """``plan`` (planned on ``pm``; or a tuple, list or dict holding plans) as bytes for another process, without the
    plans' built IPOPT problems (a robust plan's cuts re-solve in them; the rows compare does not) and with ``pm`` left
    out (:func:`unpack_plan` puts in its own)."""
    buf = io.BytesIO()
    _PlanPickler(buf, pm).dump(_without_stages(plan))
    return buf.getvalue()


def _without_stages(obj):
    if isinstance(obj, (tuple, list)):
        return type(obj)(_without_stages(x) for x in obj)
    if isinstance(obj, dict):
        return {k: _without_stages(v) for k, v in obj.items()}
    if hasattr(obj, "swings"):  # a pendulum plan: each swing's stage
        return dataclasses.replace(obj, forward=dataclasses.replace(obj.forward, stage=None),
                                   backward=dataclasses.replace(obj.backward, stage=None), mode_plans=None)
    if isinstance(obj, Plan):  # another row's starts (mode_plans) are this process's
        return dataclasses.replace(obj, stage=None, mode_plans=None)
    return obj


def unpack_plan(data: bytes, pm: PressModel):
    """The plan :func:`pack_plan` packed, on ``pm`` (a model of the same press and parameters as the one it was planned on)."""
    return _PlanUnpickler(io.BytesIO(data), pm).load()


def _refuse_pendulum(job: Job, plans: dict) -> None:
    """compare's rows cross-evaluate one knot profile per plan; a pendulum's two swings are not one: refused where
    mode = "auto" kept the pendulum in a row."""
    kept = [n for n, p in plans.items() if p.spec.mode == "pendulum"]
    if kept:
        raise ServoPressError(f"{job.source}: planning.mode = \"auto\" kept the pendulum with the {' and '.join(kept)} parameters "
                              f"({modes_line(plans[kept[0]].modes)}); compare cross-evaluates stop-at-top and continuous plans only: "
                              "compare with mode = \"stop-at-top\", plan the pendulum with `servo-press plan`")


ENERGY_KEYS = ("shaft_peak_W", "grid_peak_W", "grid_rms_W", "drawn_J", "returned_J", "net_J", "regenerated_J")


def _energy_row(plan: Plan, en: dict) -> dict:
    """A plan's energy per stroke beside its rate (comparison.json ``energy``): its own model's power flow
    (:mod:`planning.energy`), the figures of ``ENERGY_KEYS`` that the press file gives and ``lost_J`` by part."""
    row = {"strokes_per_min": plan.strokes_per_min, **{k: en[k] for k in ENERGY_KEYS if k in en}}
    if "lost_J" in en:
        row["lost_J"] = en["lost_J"]
    return row


def compare_job(press: str, job: str, calibrated: str, out: str, verify: bool = True) -> dict:
    """The 'compare' command: :func:`run_compare` of ``job`` (file or built-in name) on ``press`` with the calibration
    result ``calibrated`` (JSON file or text) into the folder ``out`` (written whole at the end); returns the record.

    Everything is checked before the output folder is made; a calibration result with a joint region (or intervals)
    makes the calibrated row the robust plan, the plan at the calibrated values alone a third row.
    """
    from press_model.calibration_verdict import calibration_verdict

    job_ = load_job(job)
    spec = read_planning(job_)
    press_ = load_press(press)
    doc = read_json(calibrated, press_, "--calibrated")  # read once: the values and the robust box
    values = overrides_of(doc)
    if not values:
        raise ServoPressError(f"--calibrated = {one_line(calibrated)!r} is not valid: it names no parameter, so both plans "
                              "would be the theoretical one; pass the calibrated.json of `servo-press calibrate` (or a JSON "
                              'object of parameter values such as \'{"eta_gear": 0.842}\')')
    apply_overrides(press_, values, "--calibrated")  # refused here, before any output folder exists
    _, intervals, kind = joint_box_of(doc, required=False)  # none: no robust row
    verdict = calibration_verdict(doc.value, doc.source)
    # the motors' shares are the press's, measured by the calibration's log: every row holds the heaviest motor to the margin
    spec = dataclasses.replace(spec, sharing=motor_sharing(press_, doc.value, doc.source))
    # the figures are drawn in a process forked now: matplotlib's import runs beside the plans, the drawing beside the playback
    check_output_folder(out, [press, job, calibrated], "compare")  # a refused --out before the worker's fork (~1 s of CPU in a fresh process)
    with figure_worker() as figures, output_folder(out, [press, job, calibrated], "compare") as tmp:
        return run_compare(press_, job_, spec, Calibrated(values, intervals, kind, verdict), tmp, verify=verify,
                           progress=Progress("compare"), figures=figures)


def compare_lines(rec: dict, out: Path) -> list[str]:
    """The lines the 'compare' command prints: each plan's rate and torques under both models, an overload in words,
    the rate gain (beside the paper's on the reference press, labelled as the paper's), the robust row, the playback's
    verdict."""
    lines = [f"{r['plan']:>12} plan: {rate_text(r['strokes_per_min'])}; peak/T_max {r['peak_ratio_theoretical_model']:.3f} (theoretical model), "
             f"{r['peak_ratio_calibrated_model']:.3f} (calibrated model); RMS {r['rms_theoretical_model_Nm']:.0f} / {r['rms_calibrated_model_Nm']:.0f} N m"
             for r in rec["rows"]]
    lines += rec.get("overloads", [])
    lines.append(f"production rate {rate_text(rec['rows'][0]['strokes_per_min'])} -> {rate_text(rec['rows'][1]['strokes_per_min'])} "
                 f"({rec['rate_gain_percent']:+.2f} %){paper_words(rec.get('paper'))} -> {out}")
    if limiting_line(rec.get("limiting_motor", {})):
        lines.append("calibrated plan's " + limiting_line(rec["limiting_motor"]))
    for name, e in rec.get("energy", {}).items():
        if "drawn_J" in e:
            lines.append(f"{name:>12} plan: {e['drawn_J'] / 1e6:.3f} MJ drawn, {e['returned_J'] / 1e6:.3f} MJ returned a stroke; "
                         f"grid peak {e['grid_peak_W'] / 1e6:.2f} MW (shaft {e['shaft_peak_W'] / 1e6:.2f} MW)")
    if "robust" in rec:
        r = rec["robust"]
        lines.append(f"rows: calibrated = robust over the calibration's {r['box_kind']} (what `plan --params` gives); {NOMINAL_ROW} = the "
                     f"calibrated values alone (`plan --nominal`): {rec['rate_gain_nominal_percent']:+.2f} % against the theoretical plan")
        lines.append(robust_line(r))
    for name, m in rec.get("modes", {}).items():
        lines.append(f"{name:>12} plan: " + modes_line(m))
    if "playback" in rec:
        pb = rec["playback"]
        lines.append(f"calibrated plan played back on the calibrated model (FF + PD): max tracking error {pb['max_tracking_error_deg']:.4f} deg, "
                     f"peak motor torque {pb['peak_motor_torque_Nm']:.0f} N m ({pb['peak_torque_ratio']:.3f} T_max)")
        lines.append(pb["verdict"]["line"])
    return lines


def _figures(plans, evals, holds, models, spec, rows, out: Path, figures=None) -> list:
    """torque.png, speed.png and comparison.png of the comparison, drawn by ``figures`` (:func:`press_model.plots.save_later`),
    the paper's rates beside ours on the reference press (:func:`paper_record`). Returns their Futures."""
    press = models["theoretical"].press
    paper = paper_record(press)
    curves = []
    for pname, mname, label in (("theoretical", "theoretical", "theoretical plan, theoretical model"),
                                ("theoretical", "calibrated", "theoretical plan, calibrated model"),
                                ("calibrated", "calibrated", "calibrated plan, calibrated model")):
        plan, ev = plans[pname], evals[(pname, mname)]
        t = np.linspace(0.0, plan.cycle_time, 4001)
        ref = reference(plan, t, ev, holds[(pname, mname)])
        rms = next(r for r in rows if r["plan"] == pname)[f"rms_{mname}_model_Nm"]
        curves.append((label, t, ref["motor_torque"], rms))
    drawn = [save_later(figures, torque_figure, (curves, spec.torque_limits(press.motor.peak_torque), press.motor.rated_torque,
                                                 "Figure 6 analogue: motor torque per motor"), out / "torque.png")]
    sc = []
    for pname, plan in plans.items():
        t = np.linspace(0.0, plan.cycle_time, 4001)
        ref = reference(plan, t)
        sc.append((f"{pname} plan", t, ref["theta_dot"], ref["theta_ddot"]))
    drawn.append(save_later(figures, speed_figure, (sc, press.drive.gear_ratio, press.motor.max_speed * 60.0 / (2.0 * math.pi),
                                                    "Figure 7 analogue: motor speed and acceleration"), out / "speed.png"))
    paper_spm = (paper["strokes_per_min_theoretical"], paper["strokes_per_min_calibrated"]) if paper is not None else None
    drawn.append(save_later(figures, comparison_figure, (rows, paper_spm, spec.torque_margin,
                                                         "production rate and peak torque ratio (theoretical vs calibrated)"), out / "comparison.png"))
    return drawn


def paper_record(press: PressData) -> dict | None:
    """The paper's theoretical and calibrated rates and their gain (Section 4.3), for the reference press only (None on
    any other: the paper's figures are of its press, not the user's)."""
    if not is_reference_press(press.fingerprint):
        return None
    return {"strokes_per_min_theoretical": PAPER_SPM[0], "strokes_per_min_calibrated": PAPER_SPM[1],
            "rate_gain_percent": 100.0 * (PAPER_SPM[1] / PAPER_SPM[0] - 1.0),
            "of": "the paper's press and part (Section 4.3), not this run's"}


def paper_words(paper: dict | None) -> str:
    """'; the paper's press: 11.4 -> 11.6 spm (+1.75 %)' for :func:`paper_record`'s record, '' for None."""
    if paper is None:
        return ""
    return (f"; the paper's press: {paper['strokes_per_min_theoretical']:g} -> {paper['strokes_per_min_calibrated']:g} spm "
            f"({paper['rate_gain_percent']:+.2f} %)")


def overload_lines(rows: list[dict], margin: float) -> list[str]:
    """One sentence per plan and model whose peak torque passes the margin: above T_max, by how much the motors would be
    overloaded (in %); between the margin and T_max, that the margin is broken. Empty when every plan keeps it."""
    out = []
    for r in rows:
        for model, on in (("theoretical", "the press file's values"), ("calibrated", "the press as calibrated")):
            ratio = r[f"peak_ratio_{model}_model"]
            if ratio > 1.0:
                out.append(f"the {r['plan']} plan on {on} reaches {ratio:.3f} T_max: the motors would be overloaded by "
                           f"{100.0 * (ratio - 1.0):.0f} % (above T_max, not only the margin {margin:g} T_max)")
            elif ratio > margin * (1.0 + 1e-9):
                out.append(f"the {r['plan']} plan on {on} reaches {ratio:.3f} T_max: within T_max, but above the margin "
                           f"{margin:g} T_max it is planned to keep")
    return out


def _markdown(rows, gain, paper: dict | None, spec, rows_are: dict) -> str:
    head = ("| plan | spm | cycle s | stroke s | peak/T_max (theor. model) | peak/T_max (calib. model) | "
            "RMS N m (theor.) | RMS N m (calib.) |\n|---|---|---|---|---|---|---|---|\n")
    body = "".join(
        f"| {r['plan']} | {r['strokes_per_min']:.3f} | {r['cycle_time_s']:.4f} | {r['stroke_time_s']:.4f} | "
        f"{r['peak_ratio_theoretical_model']:.4f} ({r['within_margin_theoretical_model']}) | "
        f"{r['peak_ratio_calibrated_model']:.4f} ({r['within_margin_calibrated_model']}) | "
        f"{r['rms_theoretical_model_Nm']:.0f} | {r['rms_calibrated_model_Nm']:.0f} |\n" for r in rows)
    over = "".join(f"\n**{line[0].upper() + line[1:]}.**\n" for line in overload_lines(rows, spec.torque_margin))
    tail = (f"{over}\nProduction rate {rate_text(rows[0]['strokes_per_min'])} -> {rate_text(rows[1]['strokes_per_min'])} ({gain:+.2f} %)"
            f"{paper_words(paper)}. Margin: peak <= {spec.torque_margin:g} T_max. (yes/NO: within the margin under that model.)\n")
    what = "\nRows:\n\n" + "".join(f"* {name}: {text}\n" for name, text in rows_are.items())
    return "# Theoretical vs calibrated plan\n\n" + head + body + tail + what


def modes_markdown(modes: dict) -> str:
    """comparison.md's section of mode = "auto": per mode, its strokes per minute in each plan's parameters (``modes``:
    plan row -> its ``Plan.modes``), or why it was not allowed or kept; the mode each row planned."""
    names = list(next(iter(modes.values()))["modes"])
    head = "| mode | " + " | ".join(f"{p} spm" for p in modes) + " |\n|---|" + "---|" * len(modes) + "\n"

    def cell(r):
        if not r["allowed"]:
            return "not allowed"
        if r["strokes_per_min"] is None:
            return "not supported" if r.get("supported") is False else "infeasible"
        return f"{r['strokes_per_min']:.3f}" + ("" if r["keeps_every_limit"] else " (breaks a limit)")

    body = "".join(f"| {n} | " + " | ".join(cell(m["modes"][n]) for m in modes.values()) + " |\n" for n in names)
    why = "".join(f"* {n} ({p}): {r.get('why_not') or r.get('infeasible')}\n" for p, m in modes.items() for n, r in m["modes"].items()
                  if not r["allowed"] or r["strokes_per_min"] is None)
    planned = ", ".join(f"{p}: {m['planned']}" for p, m in modes.items())
    vs = "; ".join(f"{n} {r['vs_stop_at_top_percent']:+.1f} % ({p})" for p, m in modes.items() for n, r in m["modes"].items()
                   if "vs_stop_at_top_percent" in r)
    return (f"\n## Modes (planning.mode = \"auto\": the fastest mode the job allows that keeps every limit)\n\n{head}{body}\n"
            f"Planned: {planned}.\n" + (f"Against the stop-at-top plan: {vs}.\n" if vs else "") + (f"\nWhy not:\n\n{why}" if why else ""))
