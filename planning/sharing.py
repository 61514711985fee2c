"""How the press's motors share the load, as a plan takes it: the heaviest motor, its torque per unit of the mean motor
torque the model computes, and where that came from.

A calibration of a log with one torque channel per motor records the motors' shares (calibrated.json
``motor_shares``, :mod:`calibration.traces.motor_shares`), with the heaviest motor's factor at the upper 95 % bound of
its share; a plan with ``--params`` takes it. Without one, the press file's ``[motor] load_shares`` (absent: an even
load, factor 1). The planner holds the mean motor torque to the torque limits over the factor
(:class:`press_model.torque_limits.TorqueLimits`), so that the heaviest motor keeps the margin.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from press_io.errors import PressDataError
from press_model.press_data import PressData


@dataclass(frozen=True)
class MotorSharing:
    """``factor``: the heaviest motor's torque per unit of the mean motor torque (>= 1; 1: an even load); ``motor`` its
    number (from 1; 0: none heavier); ``source`` where the shares come from, for the summary."""

    factor: float = 1.0
    motor: int = 0
    source: str = "an even load (no shares measured or stated)"

    def record(self, peak_torque_Nm: float, t_max: float) -> dict:
        """summary.json's ``limiting_motor``: the heaviest motor and its peak torque (N m and / T_max) at the plan's peak
        mean motor torque ``peak_torque_Nm``."""
        return {"motor": self.motor or None, "torque_factor": self.factor, "shares_from": self.source,
                "peak_torque_Nm": self.factor * peak_torque_Nm, "peak_torque_ratio": self.factor * peak_torque_Nm / t_max}



def limiting_line(rec: dict) -> str:
    """One line naming the limiting motor of a summary's ``limiting_motor`` (:meth:`MotorSharing.record`) and its peak;
    "" for an even load."""
    if rec.get("motor") is None:
        return ""
    return (f"limiting motor: motor {rec['motor']}, {rec['torque_factor']:.3f} x the mean motor torque ({rec['shares_from']}): "
            f"peak {rec['peak_torque_Nm']:,.0f} N m ({rec['peak_torque_ratio']:.3f} T_max)")


def motor_sharing(press: PressData, calibration: dict | None = None, source: str = "--params") -> MotorSharing:
    """The :class:`MotorSharing` of a plan: the calibration's ``motor_shares`` (a parsed calibrated.json, ``source``
    its file) where it has them, else the press file's ``[motor] load_shares``."""
    rec = calibration.get("motor_shares") if isinstance(calibration, dict) else None
    if rec is not None:
        h = rec.get("heaviest") if isinstance(rec, dict) else None
        f = h.get("torque_factor") if isinstance(h, dict) else None
        m = h.get("motor") if isinstance(h, dict) else None
        if not (isinstance(f, (int, float)) and not isinstance(f, bool) and math.isfinite(f) and f >= 1.0
                and isinstance(m, int) and not isinstance(m, bool) and 1 <= m <= press.drive.motors):
            raise PressDataError(source, "motor_shares.heaviest", h, "must hold torque_factor (a number >= 1) and motor (1 to "
                                 f"{press.drive.motors}) as `servo-press calibrate` wrote them: pass calibrated.json as written")
        return MotorSharing(float(f), m, f"{source} motor_shares: motor {m} at up to {100 * f / press.drive.motors:.1f} % "
                                         "of the total (upper 95 % bound)")
    shares = press.motor.load_shares
    if shares:
        m = max(range(len(shares)), key=lambda i: shares[i]) + 1
        f = press.motor.heaviest_factor(press.drive.motors)
        return MotorSharing(f, m if f > 1.0 else 0, f"{press.source} [motor] load_shares: motor {m} at {100 * shares[m - 1]:.1f} %")
    return MotorSharing()
