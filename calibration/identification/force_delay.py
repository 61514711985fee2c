"""The logged process force's delay: how much later the force column shows die contact than the torque column does.

A cushion's force is its pressure transducer's signal, filtered and often sent over another bus than the drive's
torque; a tonnage monitor's strain gauges likewise. A force column late by d puts the model's force on late: where
the die closes, the model's torque steps up d later than the log's, the peak window and the step guards sit d late,
and the parameters absorb the misfit (eta_gear 1.7 % off with a 10 ms late column on the held-out logs of issue 43).

**What tells it.** At die contact the force steps up, and the motor torque steps with it on the same sample clock
(the gear torque is the process force times its lever, 22 kN m a step on the cushion test against 150 N m of noise).
Each channel's step is timed at the middle of the sample interval that holds its largest jump near the force's rise
(:func:`step_time`): the same rule on both channels, so a step that rises over several samples (a filtered channel)
is timed alike on each. The force's lag behind the torque channel is the mean over the log's contacts of the two
times' difference (:func:`force_lag`). No model and no parameter enters it: the torque's step is where the torque
shows it.

**Its error.** A sampled step is known only to lie within one sample interval. On one sample clock the two channels'
difference is the delay rounded up or down to whole samples, by chance as the contact falls between samples: a
standard deviation of up to half a sample (at a delay of a half sample past a whole one); on two clocks, two uniform
errors, a sample over sqrt(6). Half a sample is the floor of one contact's standard deviation, the contacts' own
scatter where it is larger (then Student's t on their count less one); the standard error is over the number of
contacts (:func:`force_lag`). A force column on time reads 0 exactly on a log whose two channels share the sample
clock (the synthetic experiment's): both steps fall in the same interval.

**Against the angle.** The torque channel's own delay behind the angle is the recording's
(:mod:`calibration.identification.recording`), so the force's delay behind the angle is its lag behind the torque plus
the torque's delay as the calibration takes it (:func:`delay_estimate`); gridding reads the force against the torque
channel (:func:`calibration.traces.drive_log.grid_rows`: each force sample moved to the angle of its own time less the
torque's correction and the lag), so a recording correction of the torque moves the force with it. A lag within its
noise is reported and not corrected (the rule of the recording's correction: a sub-sample move by noise alone may shift a
force step across a grid point for nothing).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

# how far from the force's rise the torque's step is looked for (s): a channel delay of a drive or a cushion's pressure
# signal is milliseconds to tens of them (a 100 Hz filter: 1.6 ms; a fieldbus cycle: 1-10 ms); 50 ms is the 2 deg
# contact_warning_deg at the cushion test's 70 deg/s through die contact, and no other step of the torque lies that near
CONTACT_WINDOW_S = 0.05
# a torque jump no larger than this many of its sample-to-sample noise's standard deviations is no step (a contact
# near BDC, where the process force has no lever on the crank): that contact times nothing
STEP_NOISE_FACTOR = 10.0


@dataclass(frozen=True)
class ForceLag:
    """The force column's lag behind the torque column (s; positive: the force later), from ``contacts`` die contacts:
    its standard error (s) and each contact's difference (s)."""

    lag_s: float
    std_s: float
    contacts: int
    differences_s: tuple[float, ...]
    sample_s: float  # the log's median sample interval
    from_scatter: bool = False  # the contacts' scatter, not the sampling's floor, gave the standard error


def rises(t: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Indices i of the samples where the force ``force`` (N, time-sorted at ``t`` s) first reaches half its peak
    magnitude on the way up from below it (its value at i at least half the peak, at i - 1 below): die contacts. The
    peak is the 99th percentile of |force| (one glitch does not set it)."""
    f = np.abs(np.asarray(force, float))
    half = 0.5 * float(np.quantile(f, 0.99))
    if half <= 0.0:
        return np.zeros(0, int)
    return np.flatnonzero((f[1:] >= half) & (f[:-1] < half)) + 1


def step_time(t: np.ndarray, values: np.ndarray, near: float, window_s: float) -> tuple[float, float]:
    """(s, the jump): the middle of the sample interval of ``values`` (time-sorted at ``t`` s) with the largest
    absolute change within ``window_s`` of ``near`` (s), and that change; (nan, 0) when the window holds fewer than
    two samples."""
    i = np.flatnonzero(np.abs(t - near) <= window_s)
    if i.size < 2:
        return math.nan, 0.0
    d = np.diff(values[i])
    k = int(np.argmax(np.abs(d)))
    return 0.5 * float(t[i[k]] + t[i[k + 1]]), float(d[k])


def force_lag(t: np.ndarray, torque: np.ndarray, force: np.ndarray) -> ForceLag | None:
    """The force column's lag behind the torque column (module docstring) of the samples ``t`` (s), ``torque`` (N m)
    and ``force`` (N), finite and time-sorted; None where no die contact shows a torque step above its noise."""
    t, torque, force = (np.asarray(a, float) for a in (t, torque, force))
    dt = float(np.median(np.diff(t)))
    # the torque's sample-to-sample noise, robustly (the median absolute change, as a standard deviation of one sample)
    noise = 1.4826 * float(np.median(np.abs(np.diff(torque)))) / math.sqrt(2.0)
    diffs = []
    for i in rises(t, force):
        t_force, _ = step_time(t, force, float(t[i]), 1.5 * dt)  # the force's own rise: its jump beside sample i
        t_torque, jump = step_time(t, torque, t_force, CONTACT_WINDOW_S)
        if math.isfinite(t_torque) and abs(jump) > STEP_NOISE_FACTOR * noise:
            diffs.append(t_force - t_torque)
    if not diffs:
        return None
    d = np.array(diffs)
    floor = 0.5 * dt  # the delay rounded to whole samples by the contact's phase (module docstring)
    scatter = float(np.std(d, ddof=1)) if d.size > 1 else 0.0
    return ForceLag(float(np.mean(d)), max(scatter, floor) / math.sqrt(d.size), int(d.size), tuple(map(float, d)), dt,
                    scatter > floor)


def lag_of_rows(rows) -> ForceLag | None:
    """:func:`force_lag` of a log's rows as read (:class:`calibration.traces.drive_log.LogRows`): its finite rows of
    time, torque and force in time order; None without a force column or a contact that shows."""
    if rows.force_N is None:
        return None
    t, torque = rows.data[:, 0], rows.data[:, 3]
    ok = np.isfinite(t) & np.isfinite(torque) & np.isfinite(rows.force_N)
    if ok.sum() < 3:
        return None
    order = np.argsort(t[ok], kind="stable")
    return force_lag(t[ok][order], torque[ok][order], rows.force_N[ok][order])


def beyond_noise(lag: ForceLag | None, level: float) -> bool:
    """True when the lag's two-sided ``level`` interval leaves out zero: the force column is corrected for it."""
    return lag is not None and abs(lag.lag_s) > _quantile(lag, level) * lag.std_s


def _quantile(lag: ForceLag, level: float) -> float:
    # the scatter of a few contacts is itself uncertain: Student's t on contacts - 1 degrees of freedom where it rules;
    # the sampling's floor is known, not estimated
    return float(stats.t.ppf(0.5 + level / 2.0, lag.contacts - 1) if lag.from_scatter else stats.norm.ppf(0.5 + level / 2.0))


@dataclass(frozen=True)
class ForceDelay:
    """The logged force's delay behind the angle channel (s): its lag behind the torque channel plus the torque's
    delay as the calibration takes it, with its standard error and interval at ``level``; ``corrected``: the force
    column was read that much earlier."""

    delay_s: float
    std_s: float
    low_s: float
    high_s: float
    level: float
    lag: ForceLag
    torque_delay_s: float
    corrected: bool
    torque_corrected: bool = False  # the recording corrected the torque channel (else the torque is taken as on time)

    def record(self) -> dict:
        """calibrated.json's ``process_force.logged_force_delay``."""
        return {"delay_s": self.delay_s, "standard_error_s": self.std_s, "interval_s": [self.low_s, self.high_s],
                "level": self.level, "corrected": self.corrected, "lag_behind_torque_s": self.lag.lag_s,
                "torque_channel_delay_s": self.torque_delay_s, "torque_corrected": self.torque_corrected,
                "contacts": self.lag.contacts,
                "contact_differences_s": list(self.lag.differences_s),
                "method": "the force column's die-contact step timed against the torque column's (the middle of the sample "
                          "interval holding each channel's largest jump), averaged over the contacts, plus the torque "
                          "channel's delay as corrected; standard error the contacts' scatter, at least half a sample per "
                          "contact (calibration/identification/force_delay.py)"}

    def statement(self) -> str:
        """One line for people: a delay whose interval holds zero is none beyond the noise."""
        iv = f"{100 * self.level:g} % interval {1e3 * self.low_s:.2f} .. {1e3 * self.high_s:.2f} ms"
        what = (f"no force-channel delay beyond its noise ({iv})" if self.low_s <= 0.0 <= self.high_s
                else f"a force-channel delay of {1e3 * self.delay_s:.2f} ms ({iv})")
        torque = (f"the torque column corrected by {1e3 * self.torque_delay_s:.2f} ms" if self.torque_corrected
                  else "the torque column, taken as on time")
        return (f"  logged force: {what}, timed against {torque} at {self.lag.contacts} die "
                f"contact{'s' if self.lag.contacts != 1 else ''}; "
                + ("the force column read that much earlier" if self.corrected else "the force column taken as logged"))


def delay_estimate(lag: ForceLag, corrected: bool, torque_delay: tuple[float, float, bool], level: float) -> ForceDelay:
    """The force's delay behind the angle (:class:`ForceDelay`) from its lag behind the torque channel and the
    torque's delay ``torque_delay`` (s, its standard error s, whether the recording corrected the torque by it: where
    it did not, the delay is 0 as the calibration takes it, with the recording's standard error still), the two
    independent; ``corrected``: whether the lag was corrected."""
    d = lag.lag_s + (torque_delay[0] if torque_delay[2] else 0.0)
    sd = math.hypot(lag.std_s, torque_delay[1])
    q = _quantile(lag, level)
    return ForceDelay(d, sd, d - q * sd, d + q * sd, level, lag, torque_delay[0] if torque_delay[2] else 0.0, corrected,
                      torque_delay[2])


def with_lag(rows, lag: ForceLag | None, level: float):
    """``rows`` (:class:`calibration.traces.drive_log.LogRows`) with their force read ``lag`` later against the torque
    channel where it is beyond its noise at ``level`` (:func:`beyond_noise`); as they are otherwise."""
    return dataclasses.replace(rows, force_lag_s=lag.lag_s) if beyond_noise(lag, level) else rows
