"""A calibration's verdict on itself (adequacy, warnings) as plan, compare and reproduce carry it."""
from press_model.calibration_verdict import calibration_verdict, verdict_warning


def test_hand_written_overrides_carry_no_verdict():
    assert calibration_verdict({"m8": 32940}, "x.json") is None
    assert verdict_warning(None) is None


def test_an_adequate_calibration_without_warnings_is_not_warned_about():
    v = calibration_verdict({"parameters": {}, "adequacy": {"adequate": True}, "warnings": []}, "cal.json")
    assert v == {"source": "cal.json", "adequate": True, "warnings": 0, "first_warning": None}
    assert verdict_warning(v) is None


def test_an_inadequate_calibration_gets_one_line_naming_the_file_and_the_margin():
    v = calibration_verdict({"adequacy": {"adequate": False}, "warnings": []}, "my/cal.json")
    w = verdict_warning(v)
    assert "\n" not in w and w.startswith("my/cal.json:") and "NOT ADEQUATE" in w and "margin is not guaranteed" in w
    assert "robust plan" in w and "do not cover the model's error" in w


def test_warnings_alone_are_counted_with_their_first_line():
    v = calibration_verdict({"warnings": ["m8 on a range bound\nsecond line", "other"]}, "c.json")
    assert v == {"source": "c.json", "adequate": None, "warnings": 2, "first_warning": "m8 on a range bound"}
    w = verdict_warning(v)
    assert "warned 2 time(s), first: m8 on a range bound" in w and "second line" not in w
    assert "may not cover the model's error" in w  # adequate as far as it was tested: the warnings may still matter
