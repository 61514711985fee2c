"""The peak-torque limits a plan or a run keeps below the motor's T_max, in N m per motor: the one place the margin
and the feedback's reserve are multiplied out.

* ``verdict``: margin x T_max, what the motor torque may reach at any instant (the playback's verdict, the
  plan's and the comparison's "within margin", the calibration experiment's runs);
* ``feedforward``: (margin - feedback reserve) x T_max, what the planned feed-forward is held to, so that the
  verification's feedback has the reserve's share to add on top.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TorqueLimits:
    """Peak-torque limits of one motor. ``peak_torque`` T_max in N m; ``margin`` and ``feedback_reserve`` fractions of it."""

    peak_torque: float
    margin: float
    feedback_reserve: float = 0.0  # a run without a controller's feedback on top keeps none

    @property
    def verdict(self) -> float:
        """margin x T_max (N m per motor): the limit of the motor torque with the feedback included."""
        return self.margin * self.peak_torque

    @property
    def feedforward(self) -> float:
        """(margin - feedback reserve) x T_max (N m per motor): the limit the feed-forward is planned to."""
        return (self.margin - self.feedback_reserve) * self.peak_torque
