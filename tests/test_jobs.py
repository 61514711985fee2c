"""Job files: every misspelled key is refused, in whichever section (each section's own reader checks it)."""
from importlib import resources

import pytest

from calibration.synthetic.experiment import ExperimentSettings
from calibration.identification.settings import CalibrationSettings
from press_io.errors import PressDataError
from planning.settings import read_planning
from press_model.jobs import load_job


def _text(name):
    return resources.files("press_model.data").joinpath(name).read_text(encoding="utf-8")


@pytest.mark.parametrize("name, old, new, use, key", [
    ("door_panel.toml", "contact_height_m", "contact_heigth_m = 0.2\ncontact_height_m", load_job, "process.contact_heigth_m"),
    ("door_panel.toml", "[process]", "[proces]", load_job, "proces"),
    # a key added beside the right one (a typo'd copy), or a misspelling of a key the file leaves to its default: only the
    # unknown-key check can catch it, and it names the nearest known key
    ("door_panel.toml", "\n[planning.transfer]", "grid_stp_deg = 2.0\n[planning.transfer]", lambda p: read_planning(load_job(p)), "planning.grid_stp_deg"),
    ("door_panel.toml", "[planning]", "[playback]\nbandwidth_hz = 1.0\n\n[planning]", lambda p: read_planning(load_job(p)), "playback.bandwidth_hz"),
    ("cushion_test.toml", "speed_depth", "speed_dept = 0.3\nspeed_depth", load_job, "motion.speed_dept"),
    ("cushion_test.toml", "process_force_logged = true", "noise_Nm = 1.0\nprocess_force_logged = true", lambda p: ExperimentSettings.from_job(load_job(p)), "experiment.noise_Nm"),
    ("cushion_test.toml", "parameters = ", "interval_lvl = 0.9\nparameters = ", lambda p: CalibrationSettings.from_job(load_job(p)), "calibration.interval_lvl"),
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


@pytest.mark.parametrize("name, old, new, use, nearest", [
    ("door_panel.toml", "\n[planning.transfer]", "grid_stp_deg = 2.0\n[planning.transfer]", lambda p: read_planning(load_job(p)), "grid_step_deg"),
    ("cushion_test.toml", "parameters = ", "peak_window_after_contact = 0.2\nparameters = ",
     lambda p: CalibrationSettings.from_job(load_job(p)), "peak_window_after_contact_s"),
])
def test_a_misspelling_of_a_key_left_to_its_default_names_that_key(tmp_path, name, old, new, use, nearest):
    """The key the file leaves out takes its default; its misspelled copy is not silently ignored."""
    path = tmp_path / name
    path.write_text(_text(name).replace(old, new, 1), encoding="utf-8")
    with pytest.raises(PressDataError) as exc:
        use(str(path))
    assert f"did you mean '{nearest}'" in str(exc.value)
