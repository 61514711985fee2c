import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))


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
