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

from press_io.errors import PressDataError
from press_model.press_data import PressData


@dataclass(frozen=True)
class NoiseLevel:
    """The noise of one grid point of a run's stroke-averaged curve: ``rms_Nm`` (N m per motor) and the AR(1) covariance
    inflation ``inflation`` (>= 1) of its correlation along the grid; ``source`` says where both come from."""

    rms_Nm: float
    inflation: float
    source: str
    strokes: int | None = None  # strokes averaged in the log the noise was measured on (None: not known)
    # N: the noise of one grid point of a run's stroke-averaged logged process force (its bin means), which the model takes
    # in place of the job's force (calibration/identification/force_noise.py); 0: not logged, or not known
    force_noise_N: float = 0.0

    @property
    def variance(self) -> float:
        """s^2 c, N^2 m^2."""
        return self.rms_Nm ** 2 * self.inflation

    def describe(self) -> str:
        return (f"{self.rms_Nm:.4g} N m x inflation {self.inflation:.3g}, logged force {self.force_noise_N:.4g} N a grid point "
                f"({self.source})")


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
    refuse_not_adequate(path, rec)
    rms = _number(path, rec, ("adequacy", "pure_error_rms_Nm"), lambda v: v > 0.0,
                  "a positive noise of the stroke-averaged curve in N m")
    lag1 = _number(path, rec, ("adequacy", "pure_error_lag1"), lambda v: -1.0 < v < 1.0, "a lag-one correlation in (-1, 1)")
    strokes = (rec.get("log") or {}).get("strokes") if isinstance(rec.get("log"), dict) else None
    force, where = logged_force_noise(path, rec)
    return NoiseLevel(rms, ar1_inflation(lag1), f"{path}: adequacy.pure_error_rms_Nm and pure_error_lag1; {where}",
                      int(strokes) if isinstance(strokes, int) and not isinstance(strokes, bool) else None, force)


def refuse_not_adequate(path: str, rec: dict) -> None:
    """Refuse (:class:`PressDataError`, one line) a calibration whose verdict is NOT ADEQUATE (``adequacy.adequate`` false).
    Its stroke-to-stroke noise is the log's own, but a design predicts the intervals of a model adequate for the runs'
    logs: the effect that calibration lacked (named by its suspects) is in the runs' logs too, so their joint
    calibration estimates that wrong model more precisely (its intervals narrow about a biased value), not the press
    better."""
    adequacy = rec.get("adequacy")
    if not isinstance(adequacy, dict) or adequacy.get("adequate") is not False:
        return
    suspects = [s for s in adequacy.get("suspects") or [] if isinstance(s, str)]
    named = f" (suspects: {', '.join(suspects)})" if suspects else ""
    raise PressDataError(path, "adequacy.adequate", False, f"must be true: that calibration found the model NOT ADEQUATE for its "
                         f"log{named}, and runs designed for its noise would calibrate that model's error more precisely, not "
                         "the press better; make the model adequate first (calibrate the parameters or model the effect its "
                         "warning names, e.g. the job's whole [calibration] list without --parameters) and design from that "
                         "calibration, or leave --calibrated out to design for the job's [design] noise_rms_Nm")


def logged_force_noise(path: str, rec: dict) -> tuple[float, str]:
    """(N, where from): the noise of one grid point of the stroke-averaged logged process force a calibration measured
    (calibrated.json ``process_force.logs[].noise_of_binned_point_N``, the RMS over its logs that logged the force), 0
    when no log of it had the force logged (a design's runs logged with the force then carry its noise unpredicted)."""
    logs = (rec.get("process_force") or {}).get("logs") if isinstance(rec.get("process_force"), dict) else None
    values = [lg.get("noise_of_binned_point_N") for lg in logs or [] if isinstance(lg, dict)]
    values = [float(v) for v in values if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0.0]
    if not values:
        return 0.0, "no logged process force (process_force.logs[].noise_of_binned_point_N): its noise taken as 0"
    return math.sqrt(sum(v * v for v in values) / len(values)), "process_force.logs[].noise_of_binned_point_N"
