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


@pytest.fixture(scope="module")
def log_lines(tmp_path_factory):
    """The lines of a SYNTHETIC drive log written by ``servo-press experiment`` (seed 0), and its header index."""
    from servo_press.cli import main

    path = tmp_path_factory.mktemp("experiment") / "log.csv"
    assert main(["experiment", "--seed", "0", "--out", str(path)]) == 0
    lines = path.read_text(encoding="utf-8").splitlines()
    return lines, next(i for i, s in enumerate(lines) if s.startswith("time_s"))
