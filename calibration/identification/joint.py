"""Several drive logs in one calibration: one parameter set fitted to all of them.

Another speed or another cushion force excites the losses and the recording's shifts differently, which is
how they become identifiable (a channel delay shifts a curve by omega x delay, an encoder offset by the same
angle at every speed: on two speeds they separate). The logs' crank grids are laid end to end (the second
log's grid after the first's 2 pi, and so on) and Eq. 28 is taken over the joint record: Y_RMSE and the peak
of Eq. 23 over every log's peak points (outside its die-contact window), the peak against the largest of their measured
peaks, each normalised by the theoretical parameters' values on the joint record as for one log. Everything
that reads an :class:`~calibration.identification.problem.Objective` (the solvers, the polish, the bootstrap, the Jacobian
intervals) then works unchanged on a :class:`JointObjective`.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from press_io.errors import PressDataError

from calibration.identification.problem import CalibrationProblem, Objective, y_pr_against
from calibration.responses import y_rmse


@dataclass(frozen=True, eq=False)
class StackedGrid:
    """The crank grids of several batch models end to end: what Eq. 28, the bootstrap and the reports read of a
    batch model (n_points, theta, theta_dot, names, nominal). ``theta`` (rad) runs on past 2 pi into the next log."""

    parts: tuple

    @property
    def n_points(self) -> int:
        return sum(p.n_points for p in self.parts)

    @cached_property
    def theta(self) -> np.ndarray:
        return np.concatenate([p.theta + 2.0 * np.pi * i for i, p in enumerate(self.parts)])

    @cached_property
    def theta_dot(self) -> np.ndarray:
        return np.concatenate([p.theta_dot for p in self.parts])

    @property
    def names(self):
        return self.parts[0].names

    @property
    def nominal(self):
        return self.parts[0].nominal

    def split(self, arr: np.ndarray) -> list[np.ndarray]:
        """``arr`` (..., n_points) cut into the logs' pieces."""
        edges = np.cumsum([p.n_points for p in self.parts])[:-1]
        return np.split(np.asarray(arr), edges, axis=-1)


@dataclass(frozen=True)
class JointObjective(Objective):
    """Eq. 28 over several logs end to end (module docstring); ``pieces`` are the logs' own objectives."""

    pieces: tuple[Objective, ...] = ()

    def torques(self, P) -> np.ndarray:
        return np.concatenate([o.torques(P) for o in self.pieces], axis=-1)


def joint_objective(problem: CalibrationProblem, parts: list[Objective]) -> Objective:
    """One objective over the logs' objectives ``parts`` (all of the same problem); one part: that part itself."""
    if len(parts) == 1:
        return parts[0]
    grid = StackedGrid(tuple(o.bm for o in parts))
    measured = np.concatenate([o.measured for o in parts])
    mask = np.concatenate([o.peak_points for o in parts])
    peak = max(o.measured_peak for o in parts)
    t0 = np.concatenate([o.torques(problem.theoretical[None])[0] for o in parts])
    rmse0, pr0 = float(y_rmse(t0[mask], measured[mask])), float(y_pr_against(t0[mask], peak))
    if rmse0 == 0.0 or pr0 == 0.0:
        raise PressDataError("calibration", "measured curves", "equal to the theoretical prediction",
                             "leave Eq. 28's normalisation undefined (Y_RMSE,0 or Y_PR,0 is zero): nothing to calibrate")
    return JointObjective(problem, grid, measured, mask, rmse0, pr0, peak, tuple(parts))
