"""Plans shared by the planning tests' modules (conftest.py's ``pytest_plugins``; tests/ is on sys.path), each planned
once for the suite in the store of heavy results (heavy_results.py): packed as compare packs a plan for another process
(planning.compare.pack_plan: a Plan holds Pinocchio and CasADi objects that do not pickle) and unpacked on the worker's
reference model."""
from __future__ import annotations

import pytest

CONTINUOUS_JOB = "continuous.toml"  # job_variants.continuous_door_panel's default name


def _plan_continuous(ref_model, extra: str):
    """make(folder) for the store: the shipped door panel in continuous mode with ``extra`` (job_variants), planned as
    its file says on the reference press; its job file written into the folder, the packed Plan returned."""

    def make(folder):
        from job_variants import continuous_door_panel
        from planning.compare import pack_plan
        from planning.planner import StrokeProblem, plan_stroke
        from planning.settings import read_planning

        job = continuous_door_panel(folder, extra, CONTINUOUS_JOB)
        return pack_plan(plan_stroke(StrokeProblem.build(ref_model, job.process, read_planning(job))), ref_model)

    return make


@pytest.fixture(scope="session")
def continuous_door_panel_plan(ref_model, heavy_results):
    """``get(extra="")``: (the job, its Plan on ref_model) of the shipped door panel in continuous mode (no dwell, no
    [planning.transfer]: job_variants.continuous_door_panel) with the TOML text ``extra`` appended, planned once for
    the suite. The same plan as ``plan_stroke(StrokeProblem.build(ref_model, job.process, read_planning(job)))`` but
    without its IPOPT stage (compare's packing leaves it out). Read only."""
    import hashlib
    import inspect

    from job_variants import continuous_door_panel
    from planning.compare import unpack_plan
    from press_model.jobs import load_job

    kept: dict[str, tuple] = {}

    def get(extra: str = ""):
        if extra not in kept:
            # a name of its own per extra: the store keeps one result per name
            name = "continuous-door-panel" + (f"-{hashlib.sha256(extra.encode()).hexdigest()[:8]}" if extra else "")
            # the job's making is in job_variants.py, which the store's key does not read: its source is an input
            folder, packed = heavy_results.get(name, _plan_continuous(ref_model, extra), extra, inspect.getsource(continuous_door_panel))
            kept[extra] = load_job(folder / CONTINUOUS_JOB), unpack_plan(packed, ref_model)
        return kept[extra]

    return get


COARSE_DEG = 5.0  # the coarsest knots a job may state


def _plan_coarse(ref_model, mode: str | None):
    """make(folder) for the store: the shipped door panel on COARSE_DEG knots on the reference press, in its own mode
    (``mode`` None: planning.planner.plan_stroke) or in mode = "auto" ("auto": planning.modes.plan_fastest), planned with
    no IPOPT solver built before it (planning.optimal.clear_solvers: the same plan, to the bit, whichever process plans
    it, as compare plans its rows); the packed Plan (an auto plan's ``modes`` record; its ``mode_plans`` left out)."""

    def make(folder):
        import dataclasses
        import math

        from planning.compare import pack_plan
        from planning.modes import plan_fastest
        from planning.optimal import clear_solvers
        from planning.planner import StrokeProblem, plan_stroke
        from planning.settings import read_planning
        from press_model.jobs import load_job

        job = load_job("door-panel")
        spec = dataclasses.replace(read_planning(job), grid_step=math.radians(COARSE_DEG))
        clear_solvers()
        if mode is None:
            return pack_plan(plan_stroke(StrokeProblem.build(ref_model, job.process, spec)), ref_model)
        return pack_plan(plan_fastest(StrokeProblem.build(ref_model, job.process, dataclasses.replace(spec, mode=mode))), ref_model)

    return make


@pytest.fixture(scope="session")
def coarse_door_panel_plan(ref_model, heavy_results):
    """The shipped door panel (its mode, stop-at-top, and its [planning.transfer]) on COARSE_DEG knots on ref_model: the
    Plan of planning.planner.plan_stroke, planned once for the suite (heavy_results.py) from a clean IPOPT state, for the
    tests whose checks hold on any knots (test_planning_modes' stop-at-top alone, test_min_energy_under_transfer_window's
    window against a fixed dwell, test_grid_limit_second_formulation's lower bound). Without its IPOPT stage (compare's
    packing leaves it out). Read only."""
    from planning.compare import unpack_plan

    _, packed = heavy_results.get("door-panel-coarse", _plan_coarse(ref_model, None), COARSE_DEG)
    return unpack_plan(packed, ref_model)


@pytest.fixture(scope="session")
def coarse_door_panel_auto(ref_model, heavy_results):
    """The same job in mode = "auto" on COARSE_DEG knots on ref_model: the Plan of planning.modes.plan_fastest, planned
    once for the suite (heavy_results.py) from a clean IPOPT state. test_planning_modes reads its modes' record against
    each mode planned alone, test_compare_theoretical_beside its rate and record against the modes planned apart.
    Without its IPOPT stage and ``mode_plans`` (compare's packing leaves them out). Read only."""
    from planning.compare import unpack_plan

    _, packed = heavy_results.get("door-panel-auto-coarse", _plan_coarse(ref_model, "auto"), COARSE_DEG)
    return unpack_plan(packed, ref_model)


# a calibration at the press file's own values that says it is not adequate: a plan with it is the plan without it, and
# carries its verdict (test_pendulum_energy_and_verdict reads that, test_planning_pendulum the plan)
INADEQUATE = {"adequacy": {"adequate": False}, "warnings": ["MODEL NOT ADEQUATE for the log: a drive loss the model lacks"]}


def _verified_pendulum(folder):
    """make(folder) for the store: `plan --verify` of the door panel in pendulum mode on COARSE_DEG knots with
    ``--params`` INADEQUATE at the reference press's slide mass; job.toml and calibrated.json written into the folder,
    the plan into its plan/; returns (exit code, stdout, stderr)."""
    import json
    from importlib import resources

    from in_process import servo_press
    from press_model.press_data import load_press

    text = resources.files("press_model.data").joinpath("door_panel.toml").read_text(encoding="utf-8")
    assert '# mode = "pendulum" plans' in text
    (folder / "job.toml").write_text(text.replace('# mode = "pendulum" plans', f'mode = "pendulum"\ngrid_step_deg = {COARSE_DEG}\n# plans', 1),
                                     encoding="utf-8")
    cal = {"parameters": {"m8": load_press().parameter_values()["m8"]}, **INADEQUATE}
    (folder / "calibrated.json").write_text(json.dumps(cal), encoding="utf-8")
    r = servo_press("plan", "--job", folder / "job.toml", "--params", folder / "calibrated.json", "--verify", "--out", folder / "plan")
    return r.returncode, r.stdout, r.stderr


@pytest.fixture(scope="session")
def verified_coarse_pendulum(heavy_results):
    """(folder, exit code, stdout, stderr) of the suite's one `plan --job job.toml --params calibrated.json --verify
    --out plan` of the door panel in pendulum mode on COARSE_DEG knots (the folder holds job.toml, calibrated.json and
    plan/), the calibration at the press file's own slide mass (so the plan is the one without it) and not adequate.
    test_planning_pendulum reads the plan and its playback, test_pendulum_energy_and_verdict its verdict and energy.
    Read only."""
    folder, (code, out, err) = heavy_results.get("pendulum-coarse-verified", _verified_pendulum, COARSE_DEG, INADEQUATE)
    return folder, code, out, err
