"""Drive logs: reading onto the crank-angle grid, every repair and every refusal, and writing.

The logs are synthetic, made here: a known torque f(theta) sampled at 500 Hz while the crank turns at
a non-constant speed theta(t) = theta0 + w0 t + depth sin(w0 t) (closed form, so the truth at every
sample is exact). The grid values are checked against f at the grid angles within the bound of linear
interpolation, max|f''| h^2 / 8, an independent invariant; noise against the variance of an average.
"""
import math
import string
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calibration.traces.drive_log import (
    HEADER,
    DriveLogSettings,
    load_settings,
    parse_settings,
    read_drive_log,
    summary,
    write_drive_log,
)
from press_io.errors import PressDataError

G = 32.0  # gear ratio of the reference press
RATED = 13500.0  # N m per motor, reference press
W0 = 2.0 * math.pi / (60.0 / 11.4)  # rad/s, mean crank speed at 11.4 strokes/min
DEPTH = 0.4  # crank speed between 0.6 and 1.4 x W0
RATE = 500.0  # Hz
SEED_NOTE = "synthetic drive log made by tests/test_drive_log.py (truth: f(theta) in the test, seed {seed})"
F2_MAX = 3000.0 + 4.0 * 1000.0  # N m/rad^2, bound of |f''| for smooth_torque


def smooth_torque(theta):
    """N m per motor: a smooth periodic truth."""
    return 5000.0 + 3000.0 * np.sin(theta) + 1000.0 * np.cos(2.0 * theta)


def motion(t, start_deg=30.0, w0=W0):
    """Crank angle (rad, unwrapped) and speed (rad/s) at times t."""
    return (math.radians(start_deg) + w0 * t + DEPTH * np.sin(w0 * t), w0 * (1.0 + DEPTH * np.cos(w0 * t)))


def make_log(turns=3.0, start_deg=30.0, torque=smooth_torque, noise=0.0, seed=0, w0=W0, rate=RATE):
    """Columns of a synthetic log: the crank turns ``turns`` times (in time) from ``start_deg``."""
    t = np.arange(0.0, turns * 2.0 * math.pi / w0, 1.0 / rate)
    th, thd = motion(t, start_deg, w0)
    q = torque(th) + np.random.default_rng(seed).normal(0.0, noise, t.size) * (noise > 0)
    return dict(time_s=t, crank_angle_deg=np.degrees(th), motor_speed_rpm=thd * G * 60.0 / (2.0 * math.pi),
                motor_torque_Nm=q)


def write(path, cols, seed=0, comments=None):
    write_drive_log(path, cols["time_s"], cols["crank_angle_deg"], cols["motor_speed_rpm"], cols["motor_torque_Nm"],
                    comments if comments is not None else [SEED_NOTE.format(seed=seed)])
    return path


def lines_of(tmp_path, cols, name="base.csv"):
    """The text lines of the log file the writer makes (to mutate), and the index of the header line."""
    text = write(tmp_path / name, cols).read_text(encoding="utf-8").splitlines()
    return text, next(i for i, s in enumerate(text) if s.startswith("time_s"))


def put(tmp_path, lines, name="log.csv"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def interp_bound(h_rad):
    """Largest error of linear interpolation of smooth_torque between samples h_rad apart, plus file rounding."""
    return F2_MAX * h_rad ** 2 / 8.0 + 1e-3


H = W0 * (1.0 + DEPTH) / RATE  # rad, widest spacing of the samples in crank angle
BOUND = interp_bound(H)


def read(path, **kw):
    return read_drive_log(path, G, RATED, **kw)


def refused(path, **kw) -> PressDataError:
    with pytest.raises(PressDataError) as err:
        read(path, **kw)
    return err.value


# --- the grid ------------------------------------------------------------------------------------
def test_grid_curve_is_the_torque_at_the_grid_angles(tmp_path):
    log = read(write(tmp_path / "a.csv", make_log(turns=3.0, start_deg=30.0)))
    assert log.synthetic and "synthetic" in log.label and log.warnings == ()
    assert log.theta.shape == (360,) and log.theta[1] == pytest.approx(math.radians(1.0))
    assert np.max(np.abs(log.torque - smooth_torque(log.theta))) <= BOUND
    # turns: 30..359 deg, two whole turns, then 0..29 deg (the log ends 3 turns after it started): every crank angle
    # is covered three times, so three strokes, though only two turns counted from 0 deg are whole
    assert log.stroke_torque.shape == (4, 360) and log.strokes == 3
    assert np.isnan(log.stroke_torque).sum(axis=1).tolist() == [30, 0, 0, 330]
    assert np.all(np.isnan(log.stroke_torque[0, :30])) and np.all(np.isnan(log.stroke_torque[3, 30:]))
    # the strokes are the same function sampled at different angles: they differ by interpolation error only
    assert np.nanmax(log.torque_spread) <= 2 * BOUND
    assert log.sample_rate_hz == pytest.approx(RATE)
    assert log.rotation_deg == pytest.approx(3 * 360.0, abs=0.2)
    # crank speed against the truth, found by solving E + depth sin E = theta - theta0 (Newton)
    m = np.mod(log.theta - math.radians(30.0), 2 * math.pi)
    e = m.copy()
    for _ in range(50):
        e -= (e + DEPTH * np.sin(e) - m) / (1.0 + DEPTH * np.cos(e))
    assert np.max(np.abs(log.crank_speed - W0 * (1.0 + DEPTH * np.cos(e)))) < 1e-5
    with pytest.raises(ValueError):
        log.torque[0] = 0.0  # read-only
    text = summary(log)
    assert "SYNTHETIC" in text and "3 complete strokes" in text and "500 Hz" in text and "No repairs" in text


@pytest.mark.parametrize("start_deg, turns, strokes", [(200.0, 3.0, 3), (0.5, 3.0, 3), (200.0, 2.5, 2)])
def test_strokes_count_how_often_every_crank_angle_is_covered_whatever_the_start_phase(tmp_path, start_deg, turns, strokes):
    log = read(write(tmp_path / "a.csv", make_log(turns=turns, start_deg=start_deg)))
    assert log.strokes == strokes
    assert summary(log).count(f"{strokes} complete strokes") == 1


def test_a_torque_step_is_not_smeared_onto_the_neighbouring_grid_point(tmp_path):
    # die contact at 100.3 deg and release at 250.7 deg: the bin of the grid point 100 deg ([99.5, 100.5))
    # would mix both levels; interpolation between the samples around 100 deg does not.
    def stepped(theta):
        d = np.mod(np.degrees(theta), 360.0)
        return np.where((d >= 100.3) & (d < 250.7), 9000.0, 2000.0)

    log = read(write(tmp_path / "s.csv", make_log(turns=2.2, torque=stepped)))
    deg = np.arange(360)
    expect = np.where((deg > 100) & (deg <= 250), 9000.0, 2000.0)
    assert np.array_equal(log.torque, expect)
    assert log.torque[100] == 2000.0 and log.torque[101] == 9000.0 and log.torque[250] == 9000.0


def test_noise_averages_down_over_the_strokes(tmp_path):
    sigma = 150.0  # N m, white noise on every sample
    log = read(write(tmp_path / "n.csv", make_log(turns=9.0, start_deg=0.0, noise=sigma, seed=3, w0=3 * W0), seed=3))
    full = log.stroke_torque[~np.isnan(log.stroke_torque).any(axis=1)]
    assert full.shape[0] == log.strokes == 9
    truth = smooth_torque(log.theta)
    single = math.sqrt(np.mean((full - truth) ** 2))
    # a grid value is (1 - a) x_i + a x_(i+1) of two noisy samples, a uniform in [0, 1): variance 2/3 sigma^2
    assert single == pytest.approx(math.sqrt(2.0 / 3.0) * sigma, rel=0.06)
    mean_err = math.sqrt(np.mean((log.torque - truth) ** 2))
    assert mean_err == pytest.approx(single / math.sqrt(log.stroke_torque.shape[0]), rel=0.2)
    assert math.sqrt(np.mean(log.torque_spread ** 2)) == pytest.approx(single, rel=0.1)


def test_a_partial_turn_gives_the_points_it_covers_and_nan_spread_where_covered_once(tmp_path):
    log = read(write(tmp_path / "p.csv", make_log(turns=1.5, start_deg=30.0)))
    # 30..359 in turn 0, then 0..210 in turn 1: the log's last sample lies 0.37 of a sample step short of 30 + 540 =
    # 570 deg, within the half step it stands for, so 210 in turn 1 is covered too
    twice = np.zeros(360, bool)
    twice[30:211] = True
    assert np.array_equal(np.isfinite(log.torque_spread), twice)
    assert log.strokes == 1 and np.max(np.abs(log.torque - smooth_torque(log.theta))) <= BOUND


def test_write_then_read_round_trip_is_exact_and_byte_identical(tmp_path):
    cols = make_log(turns=1.3, noise=50.0, seed=7)
    notes = [SEED_NOTE.format(seed=7), "press: reference, job: cushion-test"]
    a, b = write(tmp_path / "a.csv", cols, comments=notes), write(tmp_path / "b.csv", cols, comments=notes)
    assert a.read_bytes() == b.read_bytes()
    text = a.read_text(encoding="utf-8").splitlines()
    assert text[:2] == [f"# {n}" for n in notes] and text[2].startswith("# written by calibration.traces.drive_log")
    data = np.loadtxt(a, delimiter=",", comments="#", skiprows=4)
    assert data.shape == (cols["time_s"].size, 4)
    assert np.array_equal(data[:, 0], np.round(cols["time_s"], 6))
    assert np.all((data[:, 1] >= 0.0) & (data[:, 1] < 360.0))  # written wrapped, as an encoder gives it
    assert np.allclose(data[:, 1], np.mod(cols["crank_angle_deg"], 360.0), atol=5.1e-7)
    assert np.array_equal(data[:, 3], np.round(cols["motor_torque_Nm"], 3))
    log = read(a)
    assert log.comments[:2] == tuple(notes) and log.label == notes[0] and log.synthetic
    # the writer's stamp is kept, not duplicated, when a log read back is written again
    write(tmp_path / "c.csv", cols, comments=list(log.comments))
    assert (tmp_path / "c.csv").read_bytes() == a.read_bytes()


def test_writer_refuses_bad_arrays_and_comments(tmp_path):
    cols = make_log(turns=1.2)
    bad = dict(cols, motor_torque_Nm=np.where(np.arange(cols["time_s"].size) == 3, np.nan, cols["motor_torque_Nm"]))
    with pytest.raises(PressDataError, match="motor_torque_Nm"):
        write(tmp_path / "x.csv", bad)
    with pytest.raises(PressDataError, match="same length"):
        write(tmp_path / "x.csv", dict(cols, time_s=cols["time_s"][:-1]))
    with pytest.raises(PressDataError, match="line breaks"):
        write(tmp_path / "x.csv", cols, comments=["two\nlines"])
    assert not (tmp_path / "x.csv").exists()


def test_a_log_without_synthetic_comment_is_not_synthetic(tmp_path):
    log = read(write(tmp_path / "m.csv", make_log(turns=1.2), comments=["press 7, 2024-05-01"]))
    assert not log.synthetic and log.label == "" and "not marked synthetic" in summary(log)


# --- repairs: each states itself and gives the right result -------------------------------------------
def test_rows_with_nan_inf_or_empty_cells_are_dropped_and_become_gaps(tmp_path):
    lines, h = lines_of(tmp_path, make_log())
    for k, col, val in ((h + 100, 3, "nan"), (h + 900, 2, "inf"), (h + 2000, 1, "")):
        cells = lines[k].split(",")
        cells[col] = val
        lines[k] = ", ".join(cells)
    log = read(put(tmp_path, lines))
    assert any(w.startswith("Dropped 3 rows with an empty, NaN or infinite cell") for w in log.warnings)
    assert any(w.startswith("Bridged 3 gaps") for w in log.warnings)
    assert np.max(np.abs(log.torque - smooth_torque(log.theta))) <= interp_bound(2 * H)


def test_a_short_gap_is_bridged_by_interpolation(tmp_path):
    lines, h = lines_of(tmp_path, make_log())
    del lines[h + 500:h + 503]  # three samples, at most 4 x 0.19 deg of rotation
    log = read(put(tmp_path, lines))
    assert len(log.warnings) == 1 and log.warnings[0].startswith("Bridged 1 gap in time")
    assert not np.isnan(log.stroke_torque[1:3]).any()
    assert np.max(np.abs(log.torque - smooth_torque(log.theta))) <= interp_bound(4 * H)


def test_a_long_gap_leaves_nan_in_its_turn_only(tmp_path):
    cols = make_log()
    lines, h = lines_of(tmp_path, cols)
    # drop the samples of turn 1 between 200 and 220 deg (unwrapped 560..580)
    u = cols["crank_angle_deg"]
    drop = np.flatnonzero((u > 560.0) & (u < 580.0))
    before, after = u[drop[0] - 1], u[drop[-1] + 1]
    lines = [s for i, s in enumerate(lines) if i - h - 1 not in set(drop.tolist())]
    log = read(put(tmp_path, lines))
    assert len(log.warnings) == 1 and "1 gap in time spans more than 1 deg" in log.warnings[0]
    deg = np.arange(360) + 360.0
    inside = (deg > before) & (deg < after)
    assert np.array_equal(np.isnan(log.stroke_torque[1]), inside) and inside.sum() == 21  # 560..580 deg
    assert np.max(np.abs(log.torque - smooth_torque(log.theta))) <= BOUND  # the other turns cover those angles
    assert log.strokes == 2  # 200..220 deg are covered twice, every other angle three times


def test_a_gap_that_no_turn_covers_is_refused_naming_the_angles(tmp_path):
    cols = make_log(turns=1.2, start_deg=0.0)
    lines, h = lines_of(tmp_path, cols)
    u = cols["crank_angle_deg"]
    drop = set(np.flatnonzero((u > 119.5) & (u < 140.5)).tolist())  # a gap only one turn could have filled
    err = refused(put(tmp_path, [s for i, s in enumerate(lines) if i - h - 1 not in drop]))
    assert err.field == "crank_angle_deg" and "120-140" in str(err.value) and "gaps in time" in err.expected


def test_identical_duplicate_rows_are_dropped(tmp_path):
    lines, h = lines_of(tmp_path, make_log())
    clean = read(put(tmp_path, lines, "clean.csv"))
    lines.insert(h + 301, lines[h + 300])
    lines.insert(h + 1001, lines[h + 1000])
    log = read(put(tmp_path, lines))
    assert log.warnings == (f"Dropped 2 duplicated rows (line {h + 302}, {h + 1002}) identical to the row before.",)
    assert np.array_equal(log.stroke_torque, clean.stroke_torque, equal_nan=True)


def test_same_time_with_different_values_is_refused(tmp_path):
    lines, h = lines_of(tmp_path, make_log())
    cells = lines[h + 300].split(",")
    lines.insert(h + 301, ",".join(cells[:3] + [str(float(cells[3]) + 1.0)]))
    err = refused(put(tmp_path, lines))
    assert err.field == f"lines {h + 301} and {h + 302}" and "same time" in err.expected


def test_rows_out_of_time_order_are_sorted_when_that_gives_a_forward_crank(tmp_path):
    lines, h = lines_of(tmp_path, make_log())
    clean = read(put(tmp_path, lines, "clean.csv"))
    lines[h + 50], lines[h + 51] = lines[h + 51], lines[h + 50]
    lines[h + 600:h + 700] = lines[h + 650:h + 700] + lines[h + 600:h + 650]
    log = read(put(tmp_path, lines))
    assert log.warnings == ("Sorted the rows by time_s (2 were out of order); sorted, the crank angle turns forward.",)
    assert np.array_equal(log.stroke_torque, clean.stroke_torque, equal_nan=True)


def test_rows_out_of_order_whose_times_do_not_fit_the_angles_are_refused(tmp_path):
    lines, h = lines_of(tmp_path, make_log())
    a, b = lines[h + 100].split(","), lines[h + 3000].split(",")
    a[0], b[0] = b[0], a[0]  # two time stamps exchanged: sorted by time, the angle runs backwards
    lines[h + 100], lines[h + 3000] = ",".join(a), ",".join(b)
    err = refused(put(tmp_path, lines))
    assert "crank_angle_deg" in err.field and "out of time order" in err.expected


def test_small_backward_jitter_is_held(tmp_path):
    cols = make_log()
    cols["crank_angle_deg"][1001] = cols["crank_angle_deg"][1000] - 0.03
    log = read(write(tmp_path / "j.csv", cols))
    assert len(log.warnings) == 1 and log.warnings[0].startswith("Held 1 sample whose crank angle fell back by at most 0.03")
    assert np.max(np.abs(log.torque - smooth_torque(log.theta))) <= 0.03 * math.pi / 180 * 5000 + BOUND


# --- refusals -------------------------------------------------------------------------------------
def test_less_than_one_turn_is_refused_saying_how_much_it_covers(tmp_path):
    cols = make_log(turns=0.8, start_deg=30.0)
    end = cols["crank_angle_deg"][-1]  # 288 deg of mean rotation less the speed modulation: 266.2 deg
    err = refused(write(tmp_path / "p.csv", cols))
    assert err.field == "crank_angle_deg" and "at least one full turn" in err.expected
    assert f"covers only {end - 30.0:.4g} deg (from 30 to {end:.4g} deg)" in err.expected


def test_reverse_running_is_refused(tmp_path):
    cols = make_log()
    cols["crank_angle_deg"] = -cols["crank_angle_deg"]
    cols["motor_speed_rpm"] = -cols["motor_speed_rpm"]
    err = refused(write(tmp_path / "r.csv", cols))
    assert "crank_angle_deg" in err.field and "must turn forward" in err.expected


def test_a_jump_of_the_crank_angle_is_refused(tmp_path):
    cols = make_log()
    cols["crank_angle_deg"][2000:] += 30.0
    lines, h = lines_of(tmp_path, cols)
    err = refused(put(tmp_path, lines))
    assert err.field == f"lines {h + 2001}-{h + 2002}, crank_angle_deg" and "encoder jump" in err.expected


def test_torque_in_kilo_newton_metres_is_recognised(tmp_path):
    cols = make_log()
    cols["motor_torque_Nm"] = cols["motor_torque_Nm"] / 1000.0
    path = write(tmp_path / "k.csv", cols)
    err = refused(path)
    assert err.field == "motor_torque_Nm" and "looks like kN m; multiply by 1000 or pass torque_unit='kN*m'" in err.expected
    log = read(path, torque_unit="kN*m")
    assert np.max(np.abs(log.torque - smooth_torque(log.theta))) <= BOUND + 0.5  # the file holds kN m to 1e-3
    assert refused(path, torque_unit="Nm").field == "torque_unit"


@pytest.mark.parametrize("factor, gear, ratio", [
    (1.0 / G, G, "32"),  # crank rpm in the speed column
    (2.0 * math.pi / 60.0, G, "9.549"),  # rad/s instead of rpm
    (1.0, 20.0, "0.625"),  # a wrong gear ratio (the log's is 32)
])
def test_a_speed_column_that_disagrees_with_the_crank_angle_is_refused(tmp_path, factor, gear, ratio):
    cols = make_log()
    cols["motor_speed_rpm"] = cols["motor_speed_rpm"] * factor
    with pytest.raises(PressDataError) as err:
        read_drive_log(write(tmp_path / "v.csv", cols), gear, RATED)
    assert err.value.field == "motor_speed_rpm"
    assert err.value.value.startswith(f"crank angle rate / (speed / gear_ratio) = {ratio}")
    assert "crank rpm instead of motor rpm" in err.value.expected and "rad/s instead of rpm" in err.value.expected
    if gear != G:
        assert "this log fits a gear ratio of 32" in err.value.expected


def test_a_speed_column_of_zeros_is_refused(tmp_path):
    cols = make_log()
    cols["motor_speed_rpm"] = 0.0 * cols["motor_speed_rpm"]
    assert "is 0 in every row" in refused(write(tmp_path / "z.csv", cols)).expected


def test_file_level_problems_are_refused(tmp_path):
    assert refused(tmp_path / "none.csv").field == "<file>"
    (tmp_path / "latin1.csv").write_bytes(b"# Pr\xe9sse\n" + HEADER.encode())
    assert "UTF-8" in refused(tmp_path / "latin1.csv").expected
    assert refused(put(tmp_path, [])).value == "empty"
    err = refused(put(tmp_path, ["# synthetic", "# nothing else"]))
    assert err.field == "<file>" and HEADER in err.expected


def test_header_problems_name_the_expected_header(tmp_path):
    lines, h = lines_of(tmp_path, make_log(turns=1.2))
    err = refused(put(tmp_path, lines[:h] + lines[h + 1:]))  # no header: the data comes first
    assert err.field == f"line {h + 1}" and HEADER in err.expected
    for header, detail in (("time_s, crank_angle_deg, motor_speed_rpm, motor_torque_kNm", "missing motor_torque_Nm"),
                           ("time_s;crank_angle_deg;motor_speed_rpm;motor_torque_Nm", "is semicolon-separated;"),
                           ("time_s, crank_angle_deg, motor_speed_rpm", "missing motor_torque_Nm"),
                           ("time_s, time_s, crank_angle_deg, motor_speed_rpm, motor_torque_Nm", "named twice")):
        err = refused(put(tmp_path, lines[:h] + [header] + lines[h + 1:]))
        assert err.field == f"header (line {h + 1})" and HEADER in err.expected and detail in err.expected


def test_columns_in_another_order_are_read_by_name(tmp_path):
    lines, h = lines_of(tmp_path, make_log())
    clean = read(put(tmp_path, lines, "clean.csv"))
    swapped = [", ".join(s.split(",")[i] for i in (3, 0, 2, 1)) if i > h - 1 else s
               for i, s in enumerate(lines)]
    log = read(put(tmp_path, swapped))
    assert np.array_equal(log.stroke_torque, clean.stroke_torque, equal_nan=True)


def test_bad_cells_and_rows_name_line_and_column(tmp_path):
    lines, h = lines_of(tmp_path, make_log(turns=1.2))
    bad = list(lines)
    bad[h + 10] = bad[h + 10].rsplit(",", 1)[0] + ",12O3.5"
    err = refused(put(tmp_path, bad))
    assert err.field == f"line {h + 11}, column motor_torque_Nm" and err.value == "12O3.5"
    bad = list(lines)
    bad[h + 10] = bad[h + 10].rsplit(",", 1)[0]  # a truncated row
    err = refused(put(tmp_path, bad))
    assert err.field == f"line {h + 11}" and "must hold 4 comma-separated cells" in err.expected
    bad = list(lines)
    bad.insert(h + 10, "# a comment in the data")
    assert "before the header" in refused(put(tmp_path, bad)).expected
    err = refused(put(tmp_path, lines[:h + 10]))
    assert err.field == "rows" and err.value == 9 and "at least 10" in err.expected


def test_bad_arguments_are_refused(tmp_path):
    path = write(tmp_path / "a.csv", make_log(turns=1.2))
    with pytest.raises(PressDataError, match="gear_ratio"):
        read_drive_log(path, 0.0, RATED)
    with pytest.raises(PressDataError, match="rated_torque_Nm"):
        read_drive_log(path, G, float("nan"))
    with pytest.raises(PressDataError, match="step"):
        read_drive_log(path, G, RATED, step_deg=0.7)


def test_settings_refuse_misspelled_keys_and_bad_values(tmp_path):
    cfg = load_settings()
    assert isinstance(cfg, DriveLogSettings) and cfg.gap_factor > 1.0
    import tomllib
    from importlib import resources

    raw = tomllib.loads(resources.files("press_model.data").joinpath("drive_log.toml").read_text(encoding="utf-8"))
    raw["repair"]["gap_factr"] = raw["repair"].pop("gap_factor")
    with pytest.raises(PressDataError) as err:
        parse_settings(raw, "t.toml")
    # the missing key has a close misspelling in the table: that is what is reported
    assert err.value.field == "repair.gap_factr" and "did you mean 'gap_factor'?" in err.value.expected
    del raw["repair"]["gap_factr"]
    with pytest.raises(PressDataError) as err:
        parse_settings(raw, "t.toml")
    assert err.value.field == "repair.gap_factor" and "required" in err.value.expected  # no near name: missing
    raw["repair"]["gap_factr"] = 1.5
    raw["repair"]["gap_factor"] = 1.5
    with pytest.raises(PressDataError) as err:
        parse_settings(raw, "t.toml")
    assert err.value.field == "repair.gap_factr" and "misspelled" in err.value.expected
    bad = tmp_path / "s.toml"
    bad.write_text("[read]\nmin_rows = 1\n", encoding="utf-8")
    with pytest.raises(PressDataError, match="min_rows"):
        load_settings(bad)


# --- anything at all: a log or a PressDataError, never another exception ------------------------------
_BASE = None


def _base_lines():
    global _BASE
    if _BASE is None:
        cols = make_log(turns=1.3, w0=2 * math.pi, rate=100.0)  # 130 rows
        t, a, n, q = (cols[k] for k in ("time_s", "crank_angle_deg", "motor_speed_rpm", "motor_torque_Nm"))
        _BASE = ["# synthetic fuzz base", HEADER] + [f"{x:.6f}, {y:.6f}, {z:.4f}, {w:.3f}" for x, y, z, w in zip(t, a, n, q)]
    return _BASE


_CELLS = st.sampled_from(["nan", "inf", "-inf", "", "abc", "1e308", "-1e308", "0", "-0", "1,5", "1e-300", " ", "#"])
_EDITS = st.one_of(
    st.tuples(st.just("delete"), st.integers(0, 140)),
    st.tuples(st.just("truncate"), st.integers(0, 140), st.integers(0, 40)),
    st.tuples(st.just("cell"), st.integers(0, 140), st.integers(0, 3), _CELLS),
    st.tuples(st.just("swap_rows"), st.integers(0, 140), st.integers(0, 140)),
    st.tuples(st.just("swap_columns"), st.permutations(range(4))),
    st.tuples(st.just("duplicate"), st.integers(0, 140)),
    st.tuples(st.just("insert"), st.integers(0, 140), st.text(string.printable + "é\x00", max_size=20)),
    st.tuples(st.just("scale"), st.integers(0, 3), st.sampled_from([0.0, -1.0, 1e-3, 1e3, 1e300])),
)


def _mutate(edits) -> bytes:
    lines = list(_base_lines())
    for e in edits:
        if not lines:
            break
        i = e[1] % len(lines) if isinstance(e[1], int) else 0
        if e[0] == "delete":
            del lines[i]
        elif e[0] == "truncate":
            lines[i] = lines[i][: e[2]]
        elif e[0] == "cell":
            cells = lines[i].split(",")
            cells[e[2] % len(cells)] = e[3]
            lines[i] = ",".join(cells)
        elif e[0] == "swap_rows":
            j = e[2] % len(lines)
            lines[i], lines[j] = lines[j], lines[i]
        elif e[0] == "swap_columns":
            lines = [",".join(c[k] for k in e[1]) if len(c := s.split(",")) == 4 else s for s in lines]
        elif e[0] == "duplicate":
            lines.insert(i, lines[i])
        elif e[0] == "insert":
            lines.insert(i, e[2])
        elif e[0] == "scale":
            out = []
            for s in lines:
                c = s.split(",")
                try:
                    c[e[1]] = repr(float(c[e[1]]) * e[2])
                except (ValueError, IndexError):
                    pass
                out.append(",".join(c))
            lines = out
    return ("\n".join(lines) + "\n").encode("utf-8")


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.one_of(st.lists(_EDITS, min_size=1, max_size=6).map(_mutate), st.binary(max_size=300),
                 st.text(max_size=300).map(lambda s: s.encode("utf-8"))))
def test_any_input_reads_or_raises_press_data_error(tmp_path, blob):
    path = tmp_path / "fuzz.csv"
    path.write_bytes(blob)
    try:
        log = read(path)
    except PressDataError:
        return
    assert np.all(np.isfinite(log.torque)) and log.torque.shape == (360,)


def test_c_parser_reads_a_log_as_the_cell_by_cell_reading_does(synthetic_log, monkeypatch):
    # the fast path (pandas' C parser, calibration/traces/drive_log.py _c_rows) against the reading it stands in for, on
    # the SYNTHETIC seed-0 log as written, with empty cells, 'nan' cells and an extra column of text that is skipped
    import calibration.traces.drive_log as dl

    text = synthetic_log.read_text(encoding="utf-8")
    lines = text.splitlines()
    at = next(i for i, s in enumerate(lines) if s.startswith("time_s"))
    edited = lines[:at] + [lines[at] + ",note"] + [s + (",ok" if i % 7 else ",x-y") for i, s in enumerate(lines[at + 1:])]
    edited[at + 5] = ",".join(c if j != 3 else "" for j, c in enumerate(edited[at + 5].split(",")))
    edited[at + 9] = ",".join(c if j != 2 else "nan" for j, c in enumerate(edited[at + 9].split(",")))
    # a twin-drive log: each motor's own torque column (motor 1 at 106 %, motor 2 at 94 % of the logged torque)
    names = lines[at].split(",")
    q = names.index("motor_torque_Nm")
    twin = lines[:at] + [",".join(names[:q] + ["motor_torque_Nm_1", "motor_torque_Nm_2"] + names[q + 1:])]
    for s in lines[at + 1:]:
        c = s.split(",")
        twin.append(",".join(c[:q] + [f"{1.06 * float(c[q]):.3f}", f"{0.94 * float(c[q]):.3f}"] + c[q + 1:]))
    for case in (text, "\n".join(edited), "\n".join(twin)):
        monkeypatch.setattr(dl, "C_PARSER_ROWS", 0)  # the fast path on a log of any length
        fast = dl._parse(case, "log.csv")
        monkeypatch.setattr(dl, "_c_rows", lambda *a: None)
        slow = dl._parse(case, "log.csv")
        monkeypatch.undo()
        assert np.array_equal(fast.data, slow.data, equal_nan=True)
        assert np.array_equal(fast.lines, slow.lines)
        assert (fast.force_N is None) == (slow.force_N is None)
        assert fast.force_N is None or np.array_equal(fast.force_N, slow.force_N, equal_nan=True)
        assert (fast.data_key, fast.ignored) == (slow.data_key, slow.ignored)
        assert (fast.motor_torques is None and slow.motor_torques is None) or np.array_equal(fast.motor_torques, slow.motor_torques)
        assert fast.motor_channels == slow.motor_channels
    assert dl._c_rows(edited, at, lines[at].split(",") + ["note"], [0, 1, 2, 3], None, []) is not None  # the fast path read it


def test_c_parser_reads_only_a_long_log_unless_pandas_is_imported(monkeypatch):
    # a calibration log is read cell by cell: pandas' import costs more than its parser saves there
    import calibration.traces.drive_log as dl

    monkeypatch.delitem(sys.modules, "pandas", raising=False)
    assert not dl._c_parser_pays(dl.C_PARSER_ROWS - 1)
    assert dl._c_parser_pays(dl.C_PARSER_ROWS)
    monkeypatch.setitem(sys.modules, "pandas", object())
    assert dl._c_parser_pays(10)
