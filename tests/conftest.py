import math
import signal
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

pytest_plugins = ["fixtures_suitecal", "fixtures_suiteident", "fixtures_suiteplan", "fixtures_min_energy"]  # fixtures shared by the calibration-input, identification and planning tests

# A suite started in the background of a non-interactive shell (`pytest &` in a script) inherits Ctrl-C ignored, and
# so would every command it starts; the interrupt tests send Ctrl-C as a terminal does to a job it runs in front
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


# --- the order the modules are handed to the xdist workers ------------------------------------------------------
# Each module runs on one worker (--dist loadfile), handed out in collection order (--no-loadscope-reorder in
# pyproject.toml; xdist's own order, most tests first, left the modules of a few long tests, `reproduce` and the robust
# plans, to the end, one worker finishing them while the other idled). The longest go first, so what is left at the
# end is short whichever worker takes it: the seconds each module took in the last run this checkout made (pytest's
# cache), else those measured when the suite was balanced (module_seconds.json); a module measured by neither (a new
# one) goes first, as if it were the longest: a short one costs nothing there, a long one at the end would.
MODULE_SECONDS = "suite/module-seconds"


def _module_seconds(config) -> dict[str, float]:
    import json

    seconds = json.loads((Path(__file__).parent / "module_seconds.json").read_text(encoding="utf-8"))
    cache = getattr(config, "cache", None)
    return {**seconds, **(cache.get(MODULE_SECONDS, {}) if cache is not None else {})}


def pytest_collection_modifyitems(config, items):
    seconds = _module_seconds(config)
    items.sort(key=lambda item: -seconds.get(item.nodeid.split("::")[0], math.inf))  # stable: a module's tests keep their order


class _ModuleSeconds:
    """Sums each module's seconds (setup, call and teardown) where the reports arrive, the xdist controller, and keeps
    them in pytest's cache at the end of a passing run of whole modules (no -k, -m or single test named); sums each
    xdist worker's seconds too and prints them under the run's summary."""

    def __init__(self, cache):
        self.cache, self.seconds, self.workers = cache, {}, {}

    def pytest_runtest_logreport(self, report):
        module = report.nodeid.split("::")[0]
        self.seconds[module] = self.seconds.get(module, 0.0) + report.duration
        node = getattr(report, "node", None)  # the xdist worker that ran it (absent in a run on one process)
        if node is not None:
            worker = node.gateway.id
            self.workers[worker] = self.workers.get(worker, 0.0) + report.duration

    def pytest_terminal_summary(self, terminalreporter):
        # the balance of the workers: each one's sum of its tests' seconds (a run ends when the busier one does)
        if len(self.workers) > 1:
            terminalreporter.write_line("seconds of tests per worker: " + ", ".join(f"{w} {s:.0f} s" for w, s in sorted(self.workers.items())))

    def pytest_sessionfinish(self, session, exitstatus):
        o = session.config.option
        if exitstatus == 0 and self.seconds and not (o.keyword or o.markexpr or any("::" in a for a in session.config.args)):
            kept = self.cache.get(MODULE_SECONDS, {})
            self.cache.set(MODULE_SECONDS, {**kept, **{k: round(v, 1) for k, v in self.seconds.items()}})


def pytest_configure(config):
    if getattr(config, "cache", None) is not None and not hasattr(config, "workerinput"):  # not in an xdist worker
        config.pluginmanager.register(_ModuleSeconds(config.cache), "suite-module-seconds")


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
def heavy_results(request, tmp_path_factory):
    """The store of heavy results (heavy_results.py) under pytest's cache directory: each computed once for both
    xdist workers and kept while the code it depends on is unchanged (in this process alone without the cache)."""
    from heavy_results import HeavyResults

    cache = getattr(request.config, "cache", None)  # None under -p no:cacheprovider
    return HeavyResults(cache.mkdir("heavy-results") if cache is not None else None, tmp_path_factory.mktemp("heavy-results"))


def _experiment_seed_0(folder):
    from servo_press.cli import main

    assert main(["experiment", "--seed", "0", "--out", str(folder / "log.csv")]) == 0


@pytest.fixture(scope="session")
def synthetic_log(heavy_results):
    """The SYNTHETIC drive log of ``servo-press experiment --out FOLDER/log.csv`` (the cushion test, seed 0), written once
    for the suite (heavy_results.py): its path (its truth sidecar beside it, nothing else in FOLDER). Read only: copy it
    to change it."""
    folder, _ = heavy_results.get("experiment-seed-0", _experiment_seed_0)
    return folder / "log.csv"


@pytest.fixture(scope="session")
def synthetic_log_calibrated(heavy_results, synthetic_log):
    """`servo-press calibrate --log LOG --out FOLDER` on the SYNTHETIC seed-0 log (synthetic_log) with every default
    (the cushion test's job, its method and bootstrap), run once for the suite (heavy_results.py) in the process of the
    worker that runs it: (FOLDER, its stdout, its stderr); FOLDER/calibrated.json is the record. Read only."""
    def calibrate(folder):
        from in_process import servo_press

        r = servo_press("calibrate", "--log", synthetic_log, "--out", folder / "cal")
        assert r.returncode == 0, r.stderr
        return r.stdout, r.stderr

    folder, (stdout, stderr) = heavy_results.get("synthetic-log-calibrated", calibrate, synthetic_log)
    return folder / "cal", stdout, stderr


@pytest.fixture(scope="session")
def no_bootstrap_job(tmp_path_factory):
    """The shipped cushion-test job with ``[calibration.bootstrap] refits = 0``, for `calibrate --job` in tests that
    check what a six-parameter calibration warns, refuses, prints or writes but not its intervals: the refits give the
    intervals and their statements alone, never a warning (calibration/identification/run.py; on the seed-0 log and on
    it with its force doubled, the same warnings and estimate with and without them), and cost 0.6-1.2 s of a warm
    calibration's 4.8-5.8 s of CPU. Read only."""
    from importlib import resources

    text = resources.files("press_model.data").joinpath("cushion_test.toml").read_text(encoding="utf-8")
    assert "[calibration.bootstrap]" not in text  # the shipped job takes the defaults' refits
    path = tmp_path_factory.mktemp("no-bootstrap") / "cushion_test.toml"
    path.write_text(text + "\n[calibration.bootstrap]\nrefits = 0\n", encoding="utf-8")
    return path


def _sensitivity(heavy_results, name: str, *argv: str):
    """`servo-press sensitivity ARGV --out FOLDER/sobol`, run once for the suite (heavy_results.py, under ``name``) in the
    process of the worker that asks first: (FOLDER/sobol, its stdout, its stderr)."""
    def make(folder):
        from in_process import servo_press

        r = servo_press("sensitivity", *argv, "--out", folder / "sobol")
        assert r.returncode == 0, r.stderr
        return r.stdout, r.stderr

    folder, (stdout, stderr) = heavy_results.get(name, make, argv)
    return folder / "sobol", stdout, stderr


@pytest.fixture(scope="session")
def crank_slider_sensitivity(heavy_results):
    """`servo-press sensitivity --press crank-slider --n 64` (the default load case, the reference press's cushion test):
    (FOLDER, its stdout, its stderr). The worked example's step 2, the command's warning about another press's load case
    and the crank-slider's paper comparison read the same run. Read only."""
    return _sensitivity(heavy_results, "sensitivity-crank-slider-n64", "--press", "crank-slider", "--n", "64")


@pytest.fixture(scope="session")
def reference_sensitivity(heavy_results):
    """`servo-press sensitivity --n 64 --seed 5` (the reference press under its cushion test): (FOLDER, its stdout, its
    stderr). The command's files and screening rule (test_cli_sensitivity.py) and the cushion case beside the no-load
    cycle at the same N and seed (test_sensitivity_load_cases.py) read the same run. Read only."""
    return _sensitivity(heavy_results, "sensitivity-reference-n64-seed5", "--n", "64", "--seed", "5")


@pytest.fixture(scope="session")
def log_lines(synthetic_log):
    """The lines of the SYNTHETIC drive log of ``servo-press experiment`` (seed 0), and its header index. Read only: the
    tests build their edited logs as new lists."""
    lines = synthetic_log.read_text(encoding="utf-8").splitlines()
    return lines, next(i for i, s in enumerate(lines) if s.startswith("time_s"))


# --- heavy results computed once ------------------------------------------------------------------------------------
# The shipped door-panel plan (toppra, then IPOPT's jerk-limited stage) was computed again in six modules and its
# `plan` command run in three; each fixture below is the one copy the modules read: the Plan once a worker (it holds
# the Pinocchio and CasADi objects it was planned with, which do not pickle), its written folders once for the suite
# (heavy_results.py). A test that would change one of them works on its own copy (dataclasses.replace, shutil.copytree).
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
def door_panel_written(request, heavy_results):
    """That plan's outputs as planning.report.write_plan_outputs writes them (command label "test"): (the folder, the
    info dict it returns), written once for the suite (heavy_results.py; the plan computed only where they are
    written). Read only."""

    def write(folder):
        from planning.report import write_plan_outputs
        from press_model.jobs import load_job

        return write_plan_outputs(request.getfixturevalue("ref_model"), load_job("door-panel"),
                                  request.getfixturevalue("door_panel_plan"), folder, {}, "test")

    return heavy_results.get("door-panel-written", write)


def _plan_door_panel(folder):
    from in_process import servo_press

    r = servo_press("plan", "--job", "door-panel", "--out", folder / "plan")
    assert r.returncode == 0, r.stderr
    return r.stdout, r.stderr


@pytest.fixture(scope="session")
def door_panel_plan_run(heavy_results):
    """`servo-press plan --job door-panel --out FOLDER`, run once for the suite (heavy_results.py), in the process of
    the worker that runs it: (FOLDER, its stdout, its stderr). Read only: a test that changes the folder copies it
    first."""
    folder, (stdout, stderr) = heavy_results.get("door-panel-plan-run", _plan_door_panel)
    return folder / "plan", stdout, stderr
