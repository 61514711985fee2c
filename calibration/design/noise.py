"""The noise level a design predicts its intervals for: from the job's ``[design]`` keys or from a first calibration's
calibrated.json (``design-experiment --calibrated``).

The prediction (:mod:`calibration.design.information`) needs the variance s^2 c of one grid point of a run's
stroke-averaged torque curve: the measurement noise s^2 that is left after averaging the log's strokes and the AR(1)
factor c of its correlation along the grid. A calibration measures both twice over (calibration/identification/
record.py): the residual's (``metrics.rmse_after_Nm``, ``covariance_inflation``) and the stroke-to-stroke scatter's
(``adequacy.pure_error_rms_Nm``, ``adequacy.pure_error_lag1``). The design needs the second: the residual also holds
what the model does not follow (the points next to a force step, the die-contact ringing), which is the same in every
log of a run and so biases the estimates without scattering them; taken as noise it made the predicted intervals about
2-4 times the estimates' scatter over seeds (calibration/design/information.py).

The noise of a stroke average falls as 1 / sqrt(strokes): the prediction holds for runs logged with as many strokes
as the first calibration's log (``strokes``, in prediction.json); with S strokes instead of S1 every half-width
scales by sqrt(S1 / S).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from press_model.errors import PressDataError
from press_model.press_data import PressData


@dataclass(frozen=True)
class NoiseLevel:
    """The noise of one grid point of a run's stroke-averaged curve: ``rms_Nm`` (N m per motor) and the AR(1) covariance
    inflation ``inflation`` (>= 1) of its correlation along the grid; ``source`` says where both come from."""

    rms_Nm: float
    inflation: float
    source: str
    strokes: int | None = None  # strokes averaged in the log the noise was measured on (None: not known)

    @property
    def variance(self) -> float:
        """s^2 c, N^2 m^2."""
        return self.rms_Nm ** 2 * self.inflation

    def describe(self) -> str:
        return f"{self.rms_Nm:.4g} N m x inflation {self.inflation:.3g} ({self.source})"


def ar1_inflation(lag1: float) -> float:
    """(1 + rho) / (1 - rho) for a positive lag-one correlation rho < 1, else 1: the factor
    :func:`calibration.identification.uncertainty.analyse` applies to the covariance."""
    return (1.0 + lag1) / (1.0 - lag1) if 0.0 < lag1 < 1.0 else 1.0


def _number(path: str, rec: dict, keys: tuple[str, ...], check, valid: str) -> float:
    node = rec
    for key in keys:
        if not isinstance(node, dict) or key not in node:
            raise PressDataError(path, ".".join(keys), None, f"is missing: {valid} (a calibrated.json of `servo-press "
                                 "calibrate`, made with the adequacy test on, records it)")
        node = node[key]
    if isinstance(node, bool) or not isinstance(node, (int, float)) or not math.isfinite(node) or not check(node):
        raise PressDataError(path, ".".join(keys), node, f"must be {valid}")
    return float(node)


def noise_from_calibrated(path: str | Path, press: PressData) -> NoiseLevel:
    """The :class:`NoiseLevel` a first calibration of ``press`` measured, read from its calibrated.json ``path``: the
    noise of its stroke-averaged curve and the AR(1) factor of that noise's lag-one correlation along the grid
    (module docstring: why not the residual's).

    Raises :class:`PressDataError` (one line, naming the file and the field) when the file cannot be read, is no JSON
    object, lacks the fields, or was made on another press (its ``press_fingerprint`` is not ``press``'s)."""
    path = str(path)
    try:
        rec = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise PressDataError(path, "--calibrated", path, "is no file: give the calibrated.json of a first calibration "
                             "(`servo-press calibrate --out DIR` writes DIR/calibrated.json)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PressDataError(path, "--calibrated", path, f"cannot be read as JSON ({type(exc).__name__}): give the "
                             "calibrated.json of a first calibration") from None
    if not isinstance(rec, dict):
        raise PressDataError(path, "--calibrated", type(rec).__name__, "must be a JSON object: the calibrated.json of a "
                             "first calibration")
    fp = rec.get("press_fingerprint")
    if fp != press.fingerprint:
        raise PressDataError(path, "press_fingerprint", fp, f"must be {press.fingerprint} ({press.name}, {press.source}): "
                             f"this calibration was made on {rec.get('press', 'another press')!r}; give a calibration of the "
                             "press being designed for, or --press with the file it was made on")
    rms = _number(path, rec, ("adequacy", "pure_error_rms_Nm"), lambda v: v > 0.0,
                  "a positive noise of the stroke-averaged curve in N m")
    lag1 = _number(path, rec, ("adequacy", "pure_error_lag1"), lambda v: -1.0 < v < 1.0, "a lag-one correlation in (-1, 1)")
    strokes = (rec.get("log") or {}).get("strokes") if isinstance(rec.get("log"), dict) else None
    return NoiseLevel(rms, ar1_inflation(lag1), f"{path}: adequacy.pure_error_rms_Nm and pure_error_lag1",
                      int(strokes) if isinstance(strokes, int) and not isinstance(strokes, bool) else None)
