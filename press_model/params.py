"""Reading parameter overrides given on the command line (a JSON object, a JSON file, or a calibrated.json)."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from press_io.errors import PressDataError
from .press_data import PressData
from .readers import is_file, read_text_file


@dataclass(frozen=True)
class JsonInput:
    """A JSON argument read once: its parsed ``value`` and its ``source`` (the file, or the option) for messages."""

    value: object
    source: str


def read_json(arg: str, press: PressData | None = None, flag: str = "--params") -> JsonInput:
    """:class:`JsonInput` of a JSON text or file argument, read once: the overrides (:func:`overrides_of`) and the box
    (:func:`joint_box_of`) are taken from it without reading the file again. Given ``press``, a result file made on
    another press is refused."""
    return JsonInput(*_read_json(arg, press, flag))


def _read_json(arg: str, press: PressData | None = None, flag: str = "--params") -> tuple[object, str]:
    """The JSON value of a text or file argument (the option ``flag``) and its source name for messages; given
    ``press``, a result file made on another press (its ``press_fingerprint``) is refused."""
    text, source = arg, flag
    if not arg.lstrip().startswith("{"):
        path = Path(arg)
        if not is_file(path):
            shown = arg if len(arg) <= 80 else arg[:32] + "..." + arg[-45:]  # a long path: its start and its file name
            raise PressDataError(flag, flag, shown, 'must be a JSON object such as \'{"m8": 32940}\' or the path of a JSON file')
        text, source = read_text_file(path, flag), str(path)
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as exc:
        raise PressDataError(source, "<json>", text[:60], f"is not valid JSON ({exc.msg} at character {exc.pos})") from None
    if press is not None and isinstance(obj, dict) and "press_fingerprint" in obj and obj["press_fingerprint"] != press.fingerprint:
        raise PressDataError(source, "press_fingerprint", obj["press_fingerprint"],
                             f"this file was made on another press ({obj.get('press', 'unnamed')}); the press in use, "
                             f"{press.source}, has fingerprint {press.fingerprint}: use the same --press as the run that "
                             f"wrote the file (parameters fitted on one press do not carry over to another)")
    return obj, source


def read_overrides(arg: str | None, press: PressData | None = None, flag: str = "--params") -> dict[str, float]:
    """Overrides (SI units) from a JSON text or file; a file with a "parameters" object uses that object.

    A result file records the press it was made on (``press_fingerprint``); given ``press``, a file made on
    another press is refused. A JSON without the key (overrides written by hand) is taken as it is.
    """
    if arg is None:
        return {}
    return overrides_of(read_json(arg, press, flag))


def overrides_of(doc: JsonInput) -> dict[str, float]:
    """The overrides of a JSON read once (:func:`read_json`), as :func:`read_overrides` gives them."""
    obj, source = doc.value, doc.source
    if isinstance(obj, dict) and "parameters" not in obj and _is_calibration_result(obj):
        raise PressDataError(source, "parameters", "<missing>", "must be the object of calibrated values {name: value} that "
                             "`servo-press calibrate` writes: this calibration result has lost it; pass calibrated.json as "
                             "calibrate wrote it")
    if isinstance(obj, dict) and isinstance(obj.get("parameters"), dict):
        obj = obj["parameters"]
    if not isinstance(obj, dict):
        raise PressDataError(source, "<top level>", type(obj).__name__, 'must be a JSON object such as {"m8": 32940}')
    return obj


def apply_overrides(press: PressData, overrides: dict, source: str = "--params") -> PressData:
    """The press with the overrides applied; parameters outside their sensitivity range are refused."""
    for name, value in overrides.items():
        p = press.parameters.get(name)
        if p is not None and isinstance(value, (int, float)) and not isinstance(value, bool):
            slack = 1e-12 * max(abs(p.low), abs(p.high))  # round-off of values written in another unit system
            if not p.low - slack <= value <= p.high + slack:
                raise PressDataError(source, name, value, f"must lie in its range [{p.low:.6g}, {p.high:.6g}]"
                                     + ("" if p.unit in ("1", "") else f" {p.unit}"))  # "1": a ratio, no unit to show
    return press.with_overrides(overrides, source) if overrides else press


def read_intervals(arg: str, press: PressData | None = None, flag: str = "--params",
                   required: bool = True) -> tuple[dict[str, float], dict[str, tuple[float, float]] | None]:
    """The calibrated values and their 95 % box from a calibration result (calibrated.json, or its JSON text).

    Returns (``parameters``: name -> value, ``intervals``: name -> (low, high)), SI units; with ``required``
    False, a result without intervals gives None for them (malformed intervals are refused all the same). This
    is the one reader of the intervals: a robust plan, a comparison or a monitor baseline takes them from here
    whatever method made them.
    """
    return intervals_of(read_json(arg, press, flag), required)


def intervals_of(doc: JsonInput, required: bool = True) -> tuple[dict[str, float], dict[str, tuple[float, float]] | None]:
    """:func:`read_intervals` of a JSON read once (:func:`read_json`)."""
    return _intervals_of(doc.value, doc.source, required)


def read_joint_box(arg: str, press: PressData | None = None, flag: str = "--params",
                   required: bool = True) -> tuple[dict[str, float], dict[str, tuple[float, float]] | None, str]:
    """As :func:`read_intervals`, with the box that holds every parameter's truth at once (``joint_region.box``, what
    a plan that must hold for the whole parameter set needs) instead of the per-parameter intervals; a result written
    before the joint region existed gives its per-parameter intervals. Returns (parameters, box, which box:
    "joint region" or "per-parameter intervals")."""
    return joint_box_of(read_json(arg, press, flag), required)


def joint_box_of(doc: JsonInput, required: bool = True) -> tuple[dict[str, float], dict[str, tuple[float, float]] | None, str]:
    """:func:`read_joint_box` of a JSON read once (:func:`read_json`)."""
    obj, source = doc.value, doc.source
    region = obj.get("joint_region") if isinstance(obj, dict) else None
    if isinstance(region, dict) and "box" in region:
        if not isinstance(region["box"], dict):
            raise PressDataError(source, "joint_region.box", region["box"], "must be an object {name: [low, high]}: "
                                 "pass the calibrated.json that `servo-press calibrate` wrote")
        return (*_intervals_of({**obj, "intervals": region["box"]}, source, required, "joint_region.box"), "joint region")
    if isinstance(obj, dict) and "intervals" not in obj and "joint_region" not in obj and _is_calibration_result(obj):
        # calibrate writes both: without them a plan would quietly lose the robust default
        raise PressDataError(source, "joint_region", "<missing>", "and intervals are missing from this calibration result "
                             "(`servo-press calibrate` writes both; a plan is robust over the joint region by default): pass "
                             "calibrated.json as calibrate wrote it, or only its \"parameters\" object to plan at those values alone")
    return (*_intervals_of(obj, source, required), "per-parameter intervals")


def _is_calibration_result(obj: dict) -> bool:
    """Whether a parsed JSON object is a result `servo-press calibrate` wrote (calibrated.json: it names the press it
    was made on, ``press_fingerprint``, and carries its verdict on itself, ``adequacy`` or ``warnings``) rather than
    overrides or a box written by hand: such a result has its calibrated values, its intervals and a joint region
    holding every calibrated parameter, so one without them was edited."""
    return "press_fingerprint" in obj and ("adequacy" in obj or "warnings" in obj)


def _intervals_of(obj, source: str, required: bool,
                  key: str = "intervals") -> tuple[dict[str, float], dict[str, tuple[float, float]] | None]:
    """(parameters, intervals) of a parsed calibration result (:func:`read_intervals`); ``key``: where the box was
    read (``intervals`` or ``joint_region.box``), for messages. In a result calibrate wrote every calibrated parameter
    must have its interval (a box written by hand may hold some of them)."""
    if not isinstance(obj, dict) or not isinstance(obj.get("intervals"), dict):
        if not required and isinstance(obj, dict) and "intervals" not in obj:
            return dict(obj.get("parameters", obj)), None
        raise PressDataError(source, "intervals", "<missing>", 'must be an object {name: [low, high]}: pass the calibrated.json that '
                             "`servo-press calibrate` wrote (a robust plan needs the calibration's intervals)")
    params = obj.get("parameters")
    if not isinstance(params, dict):
        raise PressDataError(source, "parameters", "<missing>", "must be the object of calibrated values beside the intervals")
    box = {}
    for name, iv in obj["intervals"].items():
        ok = (isinstance(iv, list) and len(iv) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in iv)
              and iv[0] <= iv[1])
        if not ok:
            raise PressDataError(source, f"{key}.{name}", iv, "must be [low, high] with finite numbers, low <= high")
        box[name] = (float(iv[0]), float(iv[1]))
    left_out = [n for n in params if n not in box]
    if left_out and _is_calibration_result(obj):
        raise PressDataError(source, key, f"without {', '.join(left_out)}",
                             f"must hold every calibrated parameter (\"parameters\"): {', '.join(left_out)} "
                             f"{'has' if len(left_out) == 1 else 'have'} no [low, high], so a robust plan would take "
                             f"{'it' if len(left_out) == 1 else 'them'} as exact; put the interval back or pass the "
                             "calibrated.json as `servo-press calibrate` wrote it")
    return dict(params), box


def load_model(press_arg: str | None, params_arg: str | None = None):
    """The (PressModel, overrides) of a --press argument with the --params overrides applied (SI units)."""
    from .model import PressModel
    from .press_data import load_press

    press = load_press(press_arg)
    overrides = read_overrides(params_arg, press)
    return PressModel(apply_overrides(press, overrides)), overrides
