"""A solver run is remembered in the process by the content of its inputs (calibration/identification/solvers.py
``solve``): the same method, settings of that method, seed and Eq. 28 give the run made before; any of them changed, a
new run. A stand-in solver counts the runs (the real ones are deterministic for their seed: tests/test_aco.py)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calibration.identification import solvers
from calibration.identification.settings import CalibrationSettings
from press_model.jobs import load_job


@dataclasses.dataclass(frozen=True)
class _Eq28:  # what solve() reads of an objective: its fields, by content
    measured: np.ndarray
    weight: float


@pytest.fixture
def counted(monkeypatch):
    calls = []

    def fake(obj, cs, seed, progress=None):
        calls.append(seed)
        return solvers.SolverRun("aco", obj.measured[:2] * (1 + seed), float(obj.measured.sum()), 7, 0.1, "stand-in")

    monkeypatch.setitem(solvers.SOLVERS, "aco", fake)
    monkeypatch.setattr(solvers, "_RUNS", {})
    return calls


def test_a_run_is_made_once_for_the_same_inputs_and_again_for_any_other(counted):
    cs = CalibrationSettings.from_job(load_job("cushion-test"))
    obj = _Eq28(np.linspace(1.0, 2.0, 5), 0.5)
    first = solvers.solve("aco", obj, cs, 0)
    again = solvers.solve("aco", _Eq28(np.linspace(1.0, 2.0, 5), 0.5), cs, 0)  # another object, the same content
    assert counted == [0]
    assert again.x.tobytes() == first.x.tobytes() and (again.objective, again.cycles) == (first.objective, first.cycles)
    again.x[0] = -1.0  # the caller's own copy: the remembered run keeps its x
    assert solvers.solve("aco", obj, cs, 0).x.tobytes() == first.x.tobytes() and counted == [0]
    # the job's settings outside the method's own section are not read by it: the same run
    other_refits = dataclasses.replace(cs, bootstrap=dataclasses.replace(cs.bootstrap, refits=3))
    solvers.solve("aco", obj, other_refits, 0)
    assert counted == [0]
    moved = obj.measured.copy()
    moved[3] = np.nextafter(moved[3], 9.0)  # one bit of the measured curve
    solvers.solve("aco", _Eq28(moved, 0.5), cs, 0)
    solvers.solve("aco", obj, cs, 1)  # another seed
    solvers.solve("aco", obj, dataclasses.replace(cs, aco=dataclasses.replace(cs.aco, ants=20)), 0)  # another colony
    solvers.solve("aco", _Eq28(obj.measured, 0.25), cs, 0)  # another field
    assert counted == [0, 0, 1, 0, 0]


def test_a_run_whose_inputs_are_not_known_by_content_is_never_remembered(counted):
    cs = CalibrationSettings.from_job(load_job("cushion-test"))
    obj = _Eq28(np.ones(3), object())  # an object's repr names its address, not its content
    solvers.solve("aco", obj, cs, 0)
    solvers.solve("aco", obj, cs, 0)
    assert counted == [0, 0] and not solvers._RUNS
