"""Job files a user wrote for another release or in the first form: a schema newer than this release says so; a
``schema`` key under a table is pointed to the top level, not called a misspelling; a schema-3 job whose
[calibration] holds ``process_force = 0.03`` (a number where the table is) gets the refusal alone, not first a note
that the table's key was read; a job without a [calibration] table (the first job files) takes every default and
asks only for what has none, the parameters, which --parameters gives."""
from __future__ import annotations

import pytest

from calibration.identification.settings import CalibrationSettings
from press_io.errors import PressDataError
from press_model import schema
from press_model.jobs import load_job

from bad_input_helpers import DATA, cli, refused, write_log

CUSHION = (DATA / "cushion_test.toml").read_text(encoding="utf-8")


def without_calibration(text: str) -> str:
    """The job's text without its [calibration] tables (a job file from before [calibration] existed)."""
    out, skip = [], False
    for line in text.splitlines():
        if line.startswith("["):
            skip = line.startswith("[calibration")
        if not skip:
            out.append(line)
    return "\n".join(out) + "\n"


def test_a_schema_newer_than_this_release_says_so(tmp_path):
    path = tmp_path / "job.toml"
    path.write_text(CUSHION.replace(f"schema = {schema.CURRENT}", f"schema = {schema.CURRENT + 1}"), encoding="utf-8")
    with pytest.raises(PressDataError) as info:
        load_job(path)
    assert "newer than this servo-press reads" in str(info.value) and "update servo-press" in str(info.value)


def test_schema_under_a_table_is_pointed_to_the_top_level(capsys, work):
    text = CUSHION.replace(f"schema = {schema.CURRENT}\n", "").replace("[job]\n", f"[job]\nschema = {schema.CURRENT}\n", 1)
    path = work.root / "job.toml"
    path.write_text(text, encoding="utf-8")
    work.snap()
    line = refused(cli(capsys, "experiment", "--job", path, "--out", work.root / "log.csv"), "job.schema = 4",
                   "'schema' is a top-level key")
    assert "misspelled" not in line, line
    work.unchanged()


def test_a_number_where_a_kept_settings_table_is_gets_no_note_that_it_was_read():
    notes = []
    raw = {"schema": 3, "calibration": {"parameters": ["eta_gear"], "process_force": 0.03}}
    out = schema.migrate(raw, "job", "old.toml", note=notes.append)
    assert notes == [] and out["calibration"]["process_force"] == 0.03  # the reader refuses it, naming the key
    raw = {"schema": 3, "calibration": {"parameters": ["eta_gear"]}}
    schema.migrate(raw, "job", "old.toml", note=notes.append)
    assert len(notes) == 1 and "job_force_tolerance as 0.0" in notes[0]  # the table absent: made and read, with its note


def test_a_job_without_a_calibration_table_takes_the_defaults(tmp_path):
    path = tmp_path / "job.toml"
    path.write_text(without_calibration(CUSHION), encoding="utf-8")
    cs = CalibrationSettings.from_job(load_job(path))
    assert cs.parameters == () and cs.weight == 0.3 and cs.default_method == "aco"


def test_calibrate_with_a_job_without_calibration_asks_for_the_parameters_alone(capsys, work, log_lines):
    job = work.root / "job.toml"
    job.write_text(without_calibration(CUSHION), encoding="utf-8")
    log = write_log(work, log_lines[0])
    line = refused(cli(capsys, "calibrate", "--log", log, "--job", job, "--out", work.out),
                   "calibration.parameters = '<missing>'", "--parameters")
    assert "a job needs a [calibration] table" not in line
    work.unchanged()


def test_calibrate_with_a_job_without_calibration_runs_on_the_parameters_given(capsys, work, log_lines):
    job = work.root / "job.toml"
    job.write_text(without_calibration(CUSHION), encoding="utf-8")
    log = write_log(work, log_lines[0])
    code, _, err = cli(capsys, "calibrate", "--log", log, "--job", job, "--parameters", "eta_gear,psi", "--method",
                       "least-squares", "--out", work.out)
    assert code == 0 and "Traceback" not in err, err
    assert (work.out / "calibrated.json").is_file()
