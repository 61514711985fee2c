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
