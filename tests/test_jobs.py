"""Job files: every misspelled key is refused, in whichever section (each section's own reader checks it)."""
from importlib import resources

import pytest

from calibration.synthetic.experiment import ExperimentSettings
from calibration.identification.settings import CalibrationSettings
from press_model.errors import PressDataError
from planning.settings import read_planning
from press_model.jobs import load_job


def _text(name):
    return resources.files("press_model.data").joinpath(name).read_text(encoding="utf-8")


@pytest.mark.parametrize("name, old, new, use, key", [
    ("door_panel.toml", "contact_height_m", "contact_heigth_m = 0.2\ncontact_height_m", load_job, "process.contact_heigth_m"),
    ("door_panel.toml", "[process]", "[proces]", load_job, "proces"),
    # a key added beside the right one (a typo'd copy): only the unknown-key check can catch it
    ("door_panel.toml", "grid_step_deg", "grid_stp_deg = 2.0\ngrid_step_deg", lambda p: read_planning(load_job(p)), "planning.grid_stp_deg"),
    ("door_panel.toml", "bandwidth_Hz", "bandwidth_hz = 1.0\nbandwidth_Hz", lambda p: read_planning(load_job(p)), "playback.bandwidth_hz"),
    ("cushion_test.toml", "speed_depth", "speed_dept = 0.3\nspeed_depth", load_job, "motion.speed_dept"),
    ("cushion_test.toml", "noise_sigma_Nm", "noise_Nm = 1.0\nnoise_sigma_Nm", lambda p: ExperimentSettings.from_job(load_job(p)), "experiment.noise_Nm"),
    ("cushion_test.toml", "interval_level", "interval_lvl = 0.9\ninterval_level", lambda p: CalibrationSettings.from_job(load_job(p)), "calibration.interval_lvl"),
])
def test_misspelled_job_keys_are_refused(tmp_path, name, old, new, use, key):
    text = _text(name)
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(PressDataError) as exc:
        use(str(path))
    assert key in str(exc.value) and "job files" in str(exc.value)


def test_shipped_jobs_read_whole():
    for name in ("cushion-test", "door-panel"):
        job = load_job(name)
        if "planning" in job.raw:
            read_planning(job)
        if "calibration" in job.raw:
            CalibrationSettings.from_job(job)
            ExperimentSettings.from_job(job)
