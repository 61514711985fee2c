"""A calibration's verdict on itself (calibrated.json's ``adequacy`` and ``warnings``), carried to what is planned from it.

`calibrate` tests whether the model explains the log (``adequacy.adequate``, the lack-of-fit test) and warns about
what it found (``warnings``). Its intervals and joint region describe the estimator's scatter for a model that fits;
where the model misses part of the log, they do not cover the model's error, so neither a plan at the calibrated
values nor the robust plan over the region is guaranteed to keep the torque margin on the press. `plan`, `compare`
and `reproduce` print :func:`verdict_warning` and record :func:`calibration_verdict` in their summaries.
"""
from __future__ import annotations

from press_io.errors import PressDataError, one_line

_AS_WRITTEN = "as `servo-press calibrate` writes it: a hand edit changed it; pass calibrated.json as calibrate wrote it"


def calibration_verdict(obj, source: str) -> dict | None:
    """The verdict of a parsed calibration result ``obj`` (calibrated.json) named ``source``: {"source", "adequate"
    (True, False, or None when the result has no adequacy test), "warnings" (count), "first_warning" (its first line, or
    None)}. None for overrides written by hand (neither ``adequacy`` nor ``warnings``): there is no verdict to carry.
    Read strictly (a :class:`PressDataError` otherwise): ``adequacy`` an object whose ``adequate`` is true or false (the
    string "false" is no verdict of adequacy), ``warnings`` a list of strings (a lone string is not dropped)."""
    if not isinstance(obj, dict) or ("adequacy" not in obj and "warnings" not in obj):
        return None
    adequate = None
    if "adequacy" in obj:
        adequacy = obj["adequacy"]
        if not isinstance(adequacy, dict):
            raise PressDataError(source, "adequacy", adequacy, f"must be an object with \"adequate\": true or false, {_AS_WRITTEN}")
        adequate = adequacy.get("adequate")
        if not isinstance(adequate, bool):
            raise PressDataError(source, "adequacy.adequate", "<missing>" if adequate is None else adequate,
                                 f"must be true or false (JSON, not a string), {_AS_WRITTEN}")
    warnings = obj.get("warnings", [])
    if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
        raise PressDataError(source, "warnings", warnings if len(repr(warnings)) <= 80 else repr(warnings)[:77] + "...",
                             f"must be a list of strings, {_AS_WRITTEN}")
    first = warnings[0].splitlines()[0] if warnings and warnings[0].strip() else None
    return {"source": source, "adequate": adequate, "warnings": len(warnings), "first_warning": first}


def verdict_warning(verdict: dict | None) -> str | None:
    """One line for the user when the calibration is not adequate or warned (None when there is nothing to say)."""
    if verdict is None or (verdict["adequate"] is not False and not verdict["warnings"]):
        return None
    what = []
    if verdict["adequate"] is False:
        what.append("its model is NOT ADEQUATE for the log (calibrated.json adequacy)")
    if verdict["warnings"]:
        what.append(f"it warned {verdict['warnings']} time(s), first: {verdict['first_warning']}")
    cover = "do not cover" if verdict["adequate"] is False else "may not cover"
    return one_line(f"{verdict['source']}: {'; '.join(what)}. Its intervals {cover} the model's error, so the torque margin is "
                    "not guaranteed on the press, not even by the robust plan over its region; check the warnings (recalibrate, "
                    "`servo-press design-experiment`) before running this plan")

