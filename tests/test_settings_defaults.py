"""Settings defaults: every field of every settings dataclass says its unit and why its value, the README's defaults
table is made from them, and the readers give a missing key its default while still refusing a wrong value."""
from __future__ import annotations

import dataclasses
import importlib.util
from pathlib import Path

import pytest

from press_io.errors import PressDataError
from press_model.jobs import load_job
from planning.settings import read_planning

ROOT = Path(__file__).parents[1]
_spec = importlib.util.spec_from_file_location("settings_table", ROOT / "scripts" / "settings_table.py")
settings_table = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(settings_table)


def test_every_setting_has_a_unit_entry_and_a_reason():
    for sections in settings_table.FILES.values():
        for path, cls in sections.items():
            for f in dataclasses.fields(cls):
                if "section" in f.metadata:  # an inner table: its own path lists its settings
                    assert sections[(*path, f.name)] is f.metadata["section"], (path, f.name)
                    continue
                if "own" in f.metadata:  # the file's own data (the key parameters), no default to explain
                    continue
                assert "unit" in f.metadata and f.metadata["reason"].strip(), (path, f.name)


def test_the_readmes_defaults_table_is_the_settings_dataclasses():
    text = (ROOT / "press_model" / "README.md").read_text(encoding="utf-8")
    assert settings_table.with_table(text) == text, "run python scripts/settings_table.py --write"


def test_a_job_with_only_its_dwell_plans_with_the_door_panels_settings(tmp_path):
    """A [planning] table with the dwell alone reads every other setting from its default: the door panel's values."""
    path = tmp_path / "job.toml"
    path.write_text('schema = 2\n[job]\nname = "x"\n[process]\ncontact_height_m = 0.2\nheights_m = [0.2, 0.0]\n'
                    'forces_N = [1.0e6, 1.0e6]\n[planning]\ndwell_s = 1.0\n', encoding="utf-8")
    spec = read_planning(load_job(path))
    assert (spec.torque_margin, spec.crank_jerk, spec.playback_bandwidth, spec.dwell) == (0.9, 330.0, 3.0, 1.0)


def test_a_stop_at_top_job_without_its_dwell_is_refused_naming_the_key(tmp_path):
    path = tmp_path / "job.toml"
    path.write_text('[job]\nname = "x"\n[process]\ncontact_height_m = 0.2\nheights_m = [0.2, 0.0]\nforces_N = [1.0e6, 1.0e6]\n'
                    '[planning]\nmode = "stop-at-top"\n', encoding="utf-8")
    with pytest.raises(PressDataError, match=r"planning.dwell_s = '<missing>' is not valid: required; add 'dwell_s' under \[planning\]"):
        read_planning(load_job(path))


def test_a_wrong_value_of_a_defaulted_key_keeps_its_one_line_error(tmp_path):
    path = tmp_path / "job.toml"
    path.write_text('[job]\nname = "x"\n[process]\ncontact_height_m = 0.2\nheights_m = [0.2, 0.0]\nforces_N = [1.0e6, 1.0e6]\n'
                    '[planning]\ndwell_s = 1.0\n[planning.limits]\npeak_torque_margin = 1.5\n', encoding="utf-8")
    with pytest.raises(PressDataError) as err:
        read_planning(load_job(path))
    assert str(err.value) == f"{path}: planning.limits.peak_torque_margin = 1.5 is not valid: must be > 0.0 and <= 1.0"


def test_a_whole_number_setting_above_its_bound_is_refused_naming_the_bound(tmp_path):
    from calibration.identification.settings import CalibrationSettings
    path = tmp_path / "job.toml"
    shipped = (ROOT / "press_model" / "data" / "cushion_test.toml").read_text(encoding="utf-8")
    assert "[calibration.speed]" not in shipped
    path.write_text(shipped + "\n[calibration.speed]\nestimate_degree = 40\n", encoding="utf-8")
    with pytest.raises(PressDataError) as err:
        CalibrationSettings.from_job(load_job(path))
    assert str(err.value) == f"{path}: calibration.speed.estimate_degree = 40 is not valid: must be a whole number >= 2 and <= 5"
