import signal
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

# A suite started in the background of a non-interactive shell (`pytest &` in a script) inherits Ctrl-C ignored, and
# so would every command it starts; the interrupt tests send Ctrl-C as a terminal does to a job it runs in front
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session")
def ref_model():
    from press_model.model import PressModel
    from press_model.press_data import load_press

    return PressModel(load_press())


@pytest.fixture(scope="session")
def cushion():
    from press_model.jobs import load_job, make_motion

    job = load_job("cushion-test")
    return job, make_motion(job.motion, job.source)


@pytest.fixture(scope="module")
def press():
    """The reference press (press_model/data/reference_press.toml), read once per test module."""
    from press_model.press_data import load_press

    return load_press()


@pytest.fixture(scope="module")
def job(request):
    """The shipped job named by the test module's ``JOB`` (e.g. "cushion-test"), read once per test module."""
    from press_model.jobs import load_job

    return load_job(request.module.JOB)


# --- the bad-input tests (test_*_errors.py) ---------------------------------------------------------------
@pytest.fixture
def work(tmp_path):
    """A folder for one case: ``work.out`` is the output path, ``work.snap()`` records what exists before the run
    and ``work.unchanged()`` checks that the run added nothing (no output, no temp file) and changed no input."""
    from bad_input_helpers import files

    class Work:
        root = tmp_path
        out = tmp_path / "out"

        def snap(self):
            self.before = files(tmp_path)
            self.bytes = {p: (tmp_path / p).read_bytes() for p in self.before if (tmp_path / p).is_file()}

        def unchanged(self):
            assert files(tmp_path) == self.before, sorted(files(tmp_path) - self.before)
            assert all((tmp_path / p).read_bytes() == b for p, b in self.bytes.items())

    w = Work()
    w.snap()
    return w


@pytest.fixture(scope="session")
def synthetic_log(tmp_path_factory):
    """The SYNTHETIC drive log of ``servo-press experiment --out FOLDER/log.csv`` (the cushion test, seed 0), written once
    a session: its path (its truth sidecar beside it, nothing else in FOLDER). Read only: copy it to change it."""
    from servo_press.cli import main

    path = tmp_path_factory.mktemp("experiment") / "log.csv"
    assert main(["experiment", "--seed", "0", "--out", str(path)]) == 0
    return path


@pytest.fixture(scope="session")
def log_lines(synthetic_log):
    """The lines of the SYNTHETIC drive log of ``servo-press experiment`` (seed 0), and its header index. Read only: the
    tests build their edited logs as new lists."""
    lines = synthetic_log.read_text(encoding="utf-8").splitlines()
    return lines, next(i for i, s in enumerate(lines) if s.startswith("time_s"))


# --- heavy results computed once a session (once a worker under pytest-xdist) ---------------------------------------
# The shipped door-panel plan (toppra, then IPOPT's jerk-limited stage) was computed again in six modules and its
# `plan` command run in three; each fixture below is the one copy the modules read. A test that would change one of
# them works on its own copy (dataclasses.replace, shutil.copytree).
@pytest.fixture(scope="session")
def door_panel_plan(ref_model):
    """The shipped door panel (press_model/data/door_panel.toml) planned as shipped on the reference press: the Plan of
    planning.planner.plan_stroke. Read only."""
    from planning.planner import StrokeProblem, plan_stroke
    from planning.settings import read_planning
    from press_model.jobs import load_job

    job = load_job("door-panel")
    return plan_stroke(StrokeProblem.build(ref_model, job.process, read_planning(job)))


@pytest.fixture(scope="session")
def door_panel_written(ref_model, door_panel_plan, tmp_path_factory):
    """That plan's outputs as planning.report.write_plan_outputs writes them (command label "test"): (the folder, the
    info dict it returns). Read only."""
    from planning.report import write_plan_outputs
    from press_model.jobs import load_job

    out = tmp_path_factory.mktemp("door_panel_written")
    info = write_plan_outputs(ref_model, load_job("door-panel"), door_panel_plan, out, {}, "test")
    return out, info


@pytest.fixture(scope="session")
def door_panel_plan_run(tmp_path_factory):
    """`servo-press plan --job door-panel --out FOLDER`, run once in this process: (FOLDER, its stdout, its stderr).
    Read only: a test that changes the folder copies it first."""
    from in_process import servo_press

    out = tmp_path_factory.mktemp("door_panel_plan_run") / "plan"
    r = servo_press("plan", "--job", "door-panel", "--out", out)
    assert r.returncode == 0, r.stderr
    return out, r.stdout, r.stderr
