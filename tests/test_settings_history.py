"""Every version of the shipped job and press files in the repository's history (tests/data/history, written by
scripts/history_files.py) still loads with today's readers, and where it says what today's shipped file says, it gives
the same settings; the shipped files, shrunk to what is theirs, read exactly as their last full versions did."""
from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from calibration.design.runs import DesignSection, DesignSettings
from calibration.identification.settings import SECTIONS as CALIBRATION_SECTIONS, CalibrationSettings
from calibration.synthetic.experiment import ExperimentSection, ExperimentSettings
from planning.cams import CamSettings
from planning.playback import playback_spec
from planning.settings import SECTIONS as PLANNING_SECTIONS, PlaybackSection, read_planning
from press_model import schema
from press_model.jobs import load_job
from press_model.press_data import load_press, read_press, without_electrical
from press_model.press_settings import SECTIONS as PRESS_SECTIONS
from press_model.readers import FieldReader
from press_model.settings_fields import fill_defaults, read_section, replaced

HISTORY = Path(__file__).parent / "data" / "history"
DATA = Path(__file__).parents[1] / "press_model" / "data"
JOB_SECTIONS = {**PLANNING_SECTIONS, ("planning", "cam"): CamSettings, **CALIBRATION_SECTIONS, ("experiment",): ExperimentSection,
                ("design",): DesignSection, ("design", "playback"): PlaybackSection}
# the last version of each shipped file before its settings took defaults: every setting written out
LAST_FULL = {"door_panel": "416d401", "cushion_test": "85e27a7", "crank_slider_cushion": "85e27a7", "cushion_validation": "9d35958",
             "cushion_slow": "85e27a7", "no_load_test": "84de5c7", "reference_press": "ea5bb72", "crank_slider": "95b7f61"}
VERSIONS = sorted(HISTORY.glob("*/*.toml"))
# shipped jobs whose dwell_s became [planning.transfer] after their last full version (planning/README.md, "The transfer
# window and pendulum mode"): the dwell is planned from the transfer instead
TRANSFER_SINCE = {"door_panel"}
# defaults changed on purpose since the last full versions (reader -> field -> (was, is)); the reason is the setting's own
# (a dotted field is one of an inner table)
CHANGED_DEFAULTS = {"calibration": {"speed_harmonics": (24, 0), "bootstrap.block_deg": (20.0, 1.0)}}


def is_press(path: Path) -> bool:
    return "bodies" in tomllib.loads(path.read_text(encoding="utf-8"))


def job_readers(job) -> dict:
    """Every reader's dataclass for the sections ``job`` has (source left out: it names the file)."""
    out = {}
    if "planning" in job.raw:
        out["planning"] = dataclasses.replace(read_planning(job), source="")
        out["cam"] = CamSettings.from_job(job)
    if "calibration" in job.raw:
        out["calibration"] = CalibrationSettings.from_job(job)
    if "experiment" in job.raw:
        out["experiment"] = ExperimentSettings.from_job(job)
    if "design" in job.raw:
        out["design"] = DesignSettings.from_job(job)
        out["design playback"] = dataclasses.replace(playback_spec(job, 0.9), source="")
    return out


def same(a, b) -> bool:
    """Equal, NaN equal to NaN (the playback spec's unused fields)."""
    if dataclasses.is_dataclass(a):
        return type(a) is type(b) and all(same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def dotted(obj, name: str):
    """The field ``name`` of a settings dataclass, a dotted one of an inner table."""
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def node(raw, path):
    for key in path:
        if not isinstance(raw, dict) or key not in raw:
            return None
        raw = raw[key]
    return raw


def compare_sections(old_raw: dict, new_raw: dict, sections: dict, source: str) -> int:
    """Assert, for every section the old file has, that each setting it gives as today's file does (each side with its
    defaults written in) reads the same; returns how many settings were compared."""
    sections = {path: cls for path, cls in sections.items() if path[0] in old_raw}  # the old file's tables, defaults written in
    old_full = fill_defaults(schema.migrate(old_raw, "job" if "job" in old_raw else "press", source, note=lambda _: None), sections)
    new_full = fill_defaults(schema.migrate(new_raw, "job" if "job" in new_raw else "press", "today", note=lambda _: None), sections)
    n = 0
    for path, cls in sections.items():
        old = read_section(FieldReader(source, old_full), path, cls)
        new = read_section(FieldReader("today", new_full), path, cls)
        for f in dataclasses.fields(cls):
            if node(old_full, (*path, f.name)) == node(new_full, (*path, f.name)):
                assert same(getattr(old, f.name), getattr(new, f.name)), (source, path, f.name)
                n += 1
    return n


@pytest.mark.parametrize("path", VERSIONS, ids=[f"{p.parent.name}@{p.stem}" for p in VERSIONS])
def test_every_historical_version_loads_and_reads_as_today_where_it_says_the_same(path):
    today = DATA / f"{path.parent.name}.toml"
    old_raw = tomllib.loads(path.read_text(encoding="utf-8"))
    new_raw = tomllib.loads(today.read_text(encoding="utf-8"))
    if is_press(path):
        old, new = load_press(path), load_press(today)
        n = compare_sections(old_raw, new_raw, PRESS_SECTIONS, str(path))
        for section in ("friction", "motor", "numerics"):  # raw(): the content with its defaults written in
            if old.raw().get(section) == new.raw().get(section):
                assert getattr(old, section) == getattr(new, section), section
        assert set(old.parameters) <= set(new.parameters) | {"k_load", "c_drive"}
    else:
        old, new = load_job(path), load_job(today)
        old_readers, new_readers = job_readers(old), job_readers(new)
        n = compare_sections(old_raw, new_raw, JOB_SECTIONS, str(path))
        for name, value in old_readers.items():  # a reader whose every table says the same gives the same dataclass
            tables = {"planning": ("planning", "playback"), "cam": ("planning",), "calibration": ("calibration",),
                      "experiment": ("experiment",), "design": ("design",), "design playback": ("design",)}[name]
            o = copy.deepcopy({t: old.raw[t] for t in tables if t in old.raw})
            w = copy.deepcopy({t: new.raw[t] for t in tables if t in new.raw})
            sections = {p: c for p, c in JOB_SECTIONS.items() if p[0] in tables}
            if fill_defaults(o, sections) == fill_defaults(w, sections) and name in new_readers:
                assert same(value, new_readers[name]), name
    settings = PRESS_SECTIONS if is_press(path) else JOB_SECTIONS
    assert n > 0 or not any(p[0] in old_raw for p in settings)  # a file with settings had some compared


@pytest.mark.parametrize("stem", sorted(LAST_FULL))
def test_each_shipped_file_reads_as_its_last_full_version_did(stem):
    """The shrunk shipped file and its last version with every setting written out give equal dataclasses (press: the
    same fingerprint, so results made before stay valid, and the same description)."""
    full, today = HISTORY / stem / f"{LAST_FULL[stem]}.toml", DATA / f"{stem}.toml"
    if is_press(today):
        old, new = load_press(full), load_press(today)
        assert new.fingerprint == old.fingerprint
        for attr in ("name", "gravity", "drive", "motor", "friction", "balance", "numerics", "assembly_crank_angle",
                     "cut_joints_hint"):
            assert getattr(new, attr) == getattr(old, attr), attr
        assert dict(new.assembly_angles) == dict(old.assembly_angles)
        assert new.parameters == old.parameters
        for b in old.bodies:
            assert np.array_equal(new.bodies[b].com, old.bodies[b].com) and new.bodies[b].mass == old.bodies[b].mass
        # what with_overrides reads again, and the disk caches' key ([drive.electrical] came later: no mechanical result's)
        assert without_electrical(new.raw()) == old.raw()
    else:
        old, new = job_readers(load_job(full)), job_readers(load_job(today))
        assert old.keys() == new.keys()
        if stem in TRANSFER_SINCE:  # its fixed dwell became a transfer window on purpose: everything else reads the same
            assert new["planning"].transfer is not None and old["planning"].transfer is None
            new["planning"] = dataclasses.replace(new["planning"], dwell=old["planning"].dwell, transfer=None)
        if "design" in new:  # re-measured on purpose: the noise of the stroke-averaged curve, not the residual (calibration/design/noise.py);
            # the old file's residual keys are dropped by schema 3, so the old side has none
            assert (old["design"].noise_rms, old["design"].noise_inflation) == (None, None)
            # the logged process force's noise (force_noise_N) is a measured figure added since, absent (0) in the old file
            assert old["design"].force_noise == 0.0
            new["design"] = dataclasses.replace(new["design"], noise_rms=None, noise_inflation=None, force_noise=0.0)
        if "calibration" in new:  # schema 4 changed job_force_tolerance's default (0 -> 0.03): an older file is read with
            # the 0 it meant (press_model/schema.py Kept), today's with its own or the new default
            assert old["calibration"].process_force.job_force_tolerance == 0.0
            old["calibration"] = dataclasses.replace(old["calibration"], process_force=new["calibration"].process_force
                                                     if old["calibration"].process_force == dataclasses.replace(
                                                         new["calibration"].process_force, job_force_tolerance=0.0)
                                                     else old["calibration"].process_force)
        for name in old:
            was = {f: now for f, (before, now) in CHANGED_DEFAULTS.get(name, {}).items() if dotted(old[name], f) == before}
            assert same(new[name], replaced(old[name], was)), name


def test_a_job_of_schema_1_with_a_removed_key_is_read_with_one_note_and_the_file_is_not_touched(tmp_path, capsys):
    """door_panel.toml as it was when the playback had fixed gains: kp and kd are dropped with one note on stderr that
    names them and how to silence it; the file is left as it was."""
    old = HISTORY / "door_panel" / "d1c1b5c.toml"
    path = tmp_path / "door_panel.toml"
    path.write_bytes(old.read_bytes())
    spec = read_planning(load_job(path))
    load_job(path)  # the note once per file
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"note: {path}: read as schema 1 (no 'schema' key): dropped playback.kp_Nm_per_rad")
    assert "playback.kd_Nm_s_per_rad" in err[0] and err[0].endswith(f"add 'schema = {schema.CURRENT}' to silence")
    assert spec.playback_bandwidth == PlaybackSection.bandwidth_Hz  # the gains come from the bandwidth's default
    assert path.read_bytes() == old.read_bytes()


def test_a_schema_3_job_without_the_force_tolerance_reads_the_exact_force_it_meant_with_one_note(tmp_path, capsys):
    """Schema 4 changed job_force_tolerance's default from 0 (the job's force exact) to 0.03: a schema-3 cushion test
    that leaves it out is read with 0 and one note naming the key and the new default; the same file saying schema 4
    takes the new default, silently; the file is left as it was."""
    text = "\n".join(ln for ln in (DATA / "cushion_test.toml").read_text(encoding="utf-8").splitlines()
                      if not ln.startswith("job_force_tolerance"))
    old = tmp_path / "old.toml"
    old.write_text(text.replace(f"schema = {schema.CURRENT}", "schema = 3"), encoding="utf-8")
    before = old.read_bytes()
    assert CalibrationSettings.from_job(load_job(old)).process_force.job_force_tolerance == 0.0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"note: {old}: read as schema 3 (schema = 3): read "
                                               "calibration.process_force.job_force_tolerance as 0.0"), err
    assert "0.03" in err[0] and err[0].endswith(f"add 'schema = {schema.CURRENT}' to silence")
    now = tmp_path / "now.toml"
    now.write_text(text, encoding="utf-8")
    tolerance = CalibrationSettings.from_job(load_job(now)).process_force.job_force_tolerance
    assert tolerance == CALIBRATION_SECTIONS[("calibration", "process_force")].job_force_tolerance == 0.03
    assert not capsys.readouterr().err and old.read_bytes() == before


def test_a_file_of_the_current_schema_keeps_the_refusal_of_a_removed_key(tmp_path):
    """Schema 2 says the file is today's form: a removed key there is the user's mistake and is refused, naming it."""
    from press_io.errors import PressDataError

    text = (DATA / "door_panel.toml").read_text(encoding="utf-8") + "\n[playback]\nkp_Nm_per_rad = 1.0e6\n"
    (tmp_path / "job.toml").write_text(text, encoding="utf-8")
    with pytest.raises(PressDataError, match=r"playback.kp_Nm_per_rad = 1000000.0 is not valid: is no longer read"):
        read_planning(load_job(tmp_path / "job.toml"))


@pytest.mark.parametrize("value", [0, schema.CURRENT + 1, "2", 2.0, True])
def test_a_schema_that_is_no_known_one_is_refused(tmp_path, value):
    from press_io.errors import PressDataError

    text = (DATA / "no_load_test.toml").read_text(encoding="utf-8").replace(f"schema = {schema.CURRENT}",
                                                                            f"schema = {value!r}".replace("True", "true"))
    (tmp_path / "job.toml").write_text(text, encoding="utf-8")
    with pytest.raises(PressDataError, match=f"schema = .* is not valid: must be a whole number from 1 to {schema.CURRENT}"):
        load_job(tmp_path / "job.toml")


def test_a_press_read_from_a_table_with_its_schema_key_reads_as_from_the_file():
    raw = tomllib.loads((DATA / "reference_press.toml").read_text(encoding="utf-8"))
    assert raw["schema"] == schema.CURRENT
    assert read_press(raw, "test").fingerprint == load_press().fingerprint


def test_a_job_of_schema_2_with_the_residual_as_its_noise_is_read_without_it_with_one_note(tmp_path, capsys):
    """cushion_test.toml as it was when [design] residual_rms_Nm / covariance_inflation were the first calibration's
    residual (151 N m x 1.94, mostly model misfit): schema 3 drops them with one note that names them, says what they
    meant and the fix; the design then needs the noise anew; the file is left as it was."""
    old = HISTORY / "cushion_test" / "710b3ff.toml"
    assert tomllib.loads(old.read_text(encoding="utf-8"))["design"]["residual_rms_Nm"] == 152.0
    path = tmp_path / "cushion_test.toml"
    path.write_bytes(old.read_bytes())
    job = load_job(path)
    load_job(path)  # the note once per file
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"note: {path}: read as schema 2 (schema = 2): dropped design.residual_rms_Nm ("), err
    for said in ("design.covariance_inflation", "residual", "noise_rms_Nm", "adequacy.pure_error_rms_Nm", "--calibrated"):
        assert said in err[0], said
    assert not {"residual_rms_Nm", "covariance_inflation"} & set(job.raw["design"])
    settings = DesignSettings.from_job(job)
    from press_io.errors import PressDataError

    with pytest.raises(PressDataError, match=r"design.noise_rms_Nm = None is not valid: is missing.*--calibrated"):
        settings.noise(job.source)
    assert path.read_bytes() == old.read_bytes()


def test_a_job_of_the_current_schema_with_the_residual_keys_is_refused_with_the_fix(tmp_path):
    """Schema 3 says the file is today's form: the old noise keys there would be read with today's meaning, so they are
    refused, naming the key, what it meant and the keys that replace it."""
    from press_io.errors import PressDataError

    text = (DATA / "cushion_test.toml").read_text(encoding="utf-8").replace("\n[design]\n", "\n[design]\nresidual_rms_Nm = 151.0\n", 1)
    (tmp_path / "job.toml").write_text(text, encoding="utf-8")
    with pytest.raises(PressDataError, match=r"design.residual_rms_Nm = 151.0 is not valid: is no longer read: .*noise_rms_Nm"):
        DesignSettings.from_job(load_job(tmp_path / "job.toml"))


def test_design_experiment_on_a_schema_2_job_with_the_residual_refuses_in_one_line_naming_the_key(tmp_path, capsys):
    from servo_press.cli import main

    path = tmp_path / "cushion_test.toml"
    path.write_bytes((HISTORY / "cushion_test" / "710b3ff.toml").read_bytes())
    assert main(["design-experiment", "--job", str(path), "--no-verify", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and err[0].startswith("note: ") and "dropped design.residual_rms_Nm" in err[0], err
    assert err[1].startswith(f"servo-press: error: {path}: design.noise_rms_Nm = None is not valid: is missing") and "--calibrated" in err[1]
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("path", sorted(DATA / f"{d.name}.toml" for d in HISTORY.iterdir()), ids=lambda p: p.stem)
def test_the_shipped_files_are_of_the_current_schema_and_read_silently(path, capsys):
    raw = tomllib.loads(path.read_text(encoding="utf-8"))
    if "bodies" in raw:
        load_press(path)
    else:
        job = load_job(path)
        if "design" in job.raw:
            DesignSettings.from_job(job).noise(job.source)
    assert raw["schema"] == schema.CURRENT
    assert capsys.readouterr().err == ""
