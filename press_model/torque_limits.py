"""The peak-torque limits a plan or a run keeps below the motor's T_max, in N m per motor: the one place the margin
and the feedback's reserve are multiplied out.

* ``verdict``: margin x T_max, what the motor torque may reach at any instant (the playback's verdict, the
  plan's and the comparison's "within margin", the calibration experiment's runs);
* ``feedforward``: (margin - feedback reserve) x T_max, what the planned feed-forward is held to, so that the
  verification's feedback has the reserve's share to add on top.

Both are limits of the model's torque per motor, the motors' mean. Where the motors do not share the load evenly
(calibrated.json's ``motor_shares``, the press file's ``[motor] load_shares``) the heaviest motor carries
``heaviest_motor`` times that mean, and it is the one held to the margin: both limits are divided by it.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TorqueLimits:
    """Peak-torque limits of one motor. ``peak_torque`` T_max in N m; ``margin`` and ``feedback_reserve`` fractions of it."""

    peak_torque: float
    margin: float
    feedback_reserve: float = 0.0  # a run without a controller's feedback on top keeps none
    heaviest_motor: float = 1.0  # the heaviest motor's torque per unit of the mean motor torque (>= 1; 1: an even load)

    @property
    def verdict(self) -> float:
        """margin x T_max / heaviest_motor (N m, mean motor torque): the limit of the motor torque with the feedback
        included, at which the heaviest motor reaches margin x T_max."""
        return self.margin * self.peak_torque / self.heaviest_motor

    @property
    def feedforward(self) -> float:
        """(margin - feedback reserve) x T_max / heaviest_motor (N m, mean motor torque): the limit the feed-forward is
        planned to."""
        return (self.margin - self.feedback_reserve) * self.peak_torque / self.heaviest_motor
