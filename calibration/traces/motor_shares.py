"""Each motor's share of the total torque, from a log that holds one torque channel per motor.

Motors on one gear share its load as their drives' torque loops and the gear's meshes make them share it, not
necessarily evenly; the torque limit holds for each motor, not for their mean. Motor i's share s_i is the
least-squares factor of T_i ~ s_i T_total over the log's samples (T_total the sum of the channels, so the shares
add to 1), weighted by T_total^2: where the total torque is small the share is ill-defined and counts little.

Its 95 % interval comes from the scatter of the same estimate over the log's crank turns (blocks): within a turn
the noise is coloured (die-contact ringing, the drives' filters), from turn to turn it is not, so each turn gives one
independent estimate and the interval is Student's t over them. Whether the share depends on the torque's sign
(driving against braking: a gear mesh that carries more one way) or on the crank angle (sectors of
:data:`SECTOR_DEG`) is tested the same way: the per-turn difference between the sign's (the sector's) share and the
turn's own share, t-tested over the turns at 95 % with a Bonferroni split over the tests, so that a log whose
shares are constant shows a difference in at most 5 % of logs. A difference the data shows enters the heaviest
motor's bound (:attr:`MotorShares.torque_factor`) where the torque is large enough to meet the limit
(:data:`LOADED_SHARE_OF_PEAK`).

Units: shares are fractions of the total torque (1 = all of it); angles in deg in the record, the crank angle of the
log's own angle channel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

LEVEL = 0.95  # the intervals' and the tests' level
SECTOR_DEG = 30.0  # crank-angle sectors the angle dependence is tested on: 12 a turn, a few samples of each turn's peak
LOADED_SHARE_OF_PEAK = 0.5  # a sign or sector whose |T_total| stays below this share of the log's peak cannot bring
# its heavier motor to the limit unless that motor carries over twice the mean: its share does not bound the plan
MIN_BLOCK_SHARE = 0.5  # a turn enters as a block when it holds at least this share of a full turn's samples


@dataclass(frozen=True)
class MotorShares:
    """The motors' shares of a log (module docstring). ``shares`` (M,) fractions adding to 1; ``low``/``high`` (M,)
    their 95 % bounds (NaN with fewer than two turns); ``blocks`` the turns they come from; ``by_sign``
    {"driving"|"braking": (M,) shares}; ``sign_differs`` whether the data shows the shares depend on the torque's sign;
    ``sectors`` ((J, 2) deg bounds, (J, M) shares, (J,) bool: the sector differs from the turn's share, (J,) bool: loaded);
    ``heaviest`` (motor index from 0, upper 95 % bound of its share, where: "every angle", "driving", "braking" or a
    sector's "a-b deg")."""

    channels: tuple[str, ...]
    shares: np.ndarray
    low: np.ndarray
    high: np.ndarray
    blocks: int
    by_sign: dict
    sign_differs: bool
    sectors: tuple
    heaviest: tuple[int, float, str]

    @property
    def motors(self) -> int:
        return len(self.channels)

    @property
    def torque_factor(self) -> float:
        """The heaviest motor's torque per unit of the mean motor torque at the 95 % bound of its share (M x share,
        >= 1; 1: an even load): what the planner divides the per-motor torque limit by."""
        return max(1.0, self.motors * self.heaviest[1])

    @property
    def spread(self) -> float:
        """The largest share less the smallest (fraction of the total torque)."""
        return float(np.max(self.shares) - np.min(self.shares))

    def record(self) -> dict:
        """calibrated.json's ``motor_shares``."""
        bounds, per, differs, loaded = self.sectors
        m, up, where = self.heaviest
        return {
            "channels": list(self.channels),
            "shares": [float(s) for s in self.shares],
            "intervals_95": [[float(a), float(b)] for a, b in zip(self.low, self.high)],
            "turns": self.blocks,
            "by_torque_sign": {**{k: [float(s) for s in v] for k, v in self.by_sign.items()}, "differs": self.sign_differs},
            "by_crank_angle": {"sector_deg": SECTOR_DEG,
                               "differs_at_deg": [[float(a), float(b)] for (a, b), d in zip(bounds, differs) if d],
                               "shares_where_it_differs": [[float(s) for s in row] for row, d in zip(per, differs) if d]},
            "heaviest": {"motor": m + 1, "channel": self.channels[m], "share_upper_95": float(up), "where": where,
                         "torque_factor": self.torque_factor},
            "method": ("motor i's share: least squares of T_i ~ s_i T_total over the samples (T_total the channels' sum); 95 % "
                       "intervals: Student's t over the log's crank turns, one estimate a turn; a dependence on the torque's "
                       f"sign or on the crank angle ({SECTOR_DEG:g} deg sectors) counted where the per-turn difference is "
                       "significant at 95 % (Bonferroni over the tests); the plan holds the mean motor torque to the limit over "
                       "torque_factor = motors x the heaviest share's upper 95 % bound (calibration/traces/motor_shares.py)"),
        }

    def line(self) -> str:
        """One sentence naming each motor's share and the heaviest."""
        each = ", ".join(f"motor {i + 1} ('{c}') {100 * s:.1f} % (95 %: {100 * a:.1f}-{100 * b:.1f} %)" if math.isfinite(a) else
                         f"motor {i + 1} ('{c}') {100 * s:.1f} %"
                         for i, (c, s, a, b) in enumerate(zip(self.channels, self.shares, self.low, self.high)))
        m, up, where = self.heaviest
        extra = ("; the shares depend on the torque's sign (driving " + "/".join(f"{100 * s:.1f}" for s in self.by_sign["driving"])
                 + " %, braking " + "/".join(f"{100 * s:.1f}" for s in self.by_sign["braking"]) + " %)") if self.sign_differs else ""
        return (f"Motor shares of the total torque over {self.blocks} turns: {each}{extra}; heaviest motor {m + 1} at up to "
                f"{100 * up:.1f} % ({where}), {self.torque_factor:.3f} x the mean motor torque")


def _share(T: np.ndarray, total: np.ndarray) -> np.ndarray:
    """(M,) least-squares shares of the channels ``T`` (M, n) in ``total`` (n,); NaN where the total is all zero."""
    den = float(np.dot(total, total))
    return T @ total / den if den > 0.0 else np.full(T.shape[0], np.nan)


def _differs(d: np.ndarray, tests: int) -> bool:
    """Whether the per-turn differences ``d`` (K,) have a mean other than 0 at 95 % split over ``tests`` (t-test)."""
    d = d[np.isfinite(d)]
    if d.size < 3:
        return False  # two turns give one degree of freedom: no test of a difference worth the name
    sd = float(np.std(d, ddof=1))
    q = float(stats.t.ppf(1.0 - (1.0 - LEVEL) / (2.0 * tests), d.size - 1))
    return abs(float(np.mean(d))) > q * sd / math.sqrt(d.size) if sd > 0.0 else float(np.mean(d)) != 0.0


def estimate_shares(angle_deg: np.ndarray, torques: np.ndarray, channels: tuple[str, ...]) -> MotorShares | None:
    """The motors' shares (:class:`MotorShares`) of the time-ordered samples: ``angle_deg`` (n,) the crank angle as
    logged (wrapping or not), ``torques`` (n, M) each motor's channel (any one unit), ``channels`` their names; None
    when fewer than two channels, or no sample has torque."""
    T = np.asarray(torques, dtype=float)
    a = np.asarray(angle_deg, dtype=float)
    ok = np.isfinite(a) & np.all(np.isfinite(T), axis=1)
    if T.ndim != 2 or T.shape[1] < 2 or ok.sum() < 2:
        return None
    a, T = a[ok], T[ok].T
    total = T.sum(axis=0)
    shares = _share(T, total)
    if not np.all(np.isfinite(shares)):
        return None
    M = T.shape[0]
    u = np.degrees(np.unwrap(np.radians(a)))  # the crank turns forward: a wrap is a new turn
    turn = np.floor((u - u[0]) / 360.0).astype(int)
    per_turn = np.bincount(turn)
    blocks = [np.flatnonzero(turn == k) for k in range(per_turn.size) if per_turn[k] >= MIN_BLOCK_SHARE * per_turn.max()]
    drive, brake = total > 0.0, total < 0.0
    sector = np.floor(np.mod(a, 360.0) / SECTOR_DEG).astype(int)
    J = int(round(360.0 / SECTOR_DEG))
    masks = {"every angle": np.ones_like(drive), "driving": drive, "braking": brake,
             **{f"{j * SECTOR_DEG:g}-{(j + 1) * SECTOR_DEG:g} deg": sector == j for j in range(J)}}
    est = {k: _share(T[:, m], total[m]) for k, m in masks.items()}  # over every sample
    by_turn = {k: np.array([_share(T[:, b][:, m[b]], total[b][m[b]]) for b in blocks]).reshape(len(blocks), M)
               for k, m in masks.items()}
    K = len(blocks)
    q = float(stats.t.ppf(0.5 + LEVEL / 2.0, K - 1)) if K >= 2 else math.nan

    def bounds(key):
        x = by_turn[key]
        x = x[np.all(np.isfinite(x), axis=1)]
        if x.shape[0] < 2:
            return np.full(M, np.nan), np.full(M, np.nan)
        half = q * np.std(x, axis=0, ddof=1) / math.sqrt(x.shape[0])
        return est[key] - half, est[key] + half

    low, high = bounds("every angle")
    base = by_turn["every angle"]
    tests = M * (1 + J)  # the sign's test and each sector's, for each motor
    sign_differs = any(_differs(by_turn["driving"][:, i] - by_turn["braking"][:, i], tests) for i in range(M))
    peak = float(np.max(np.abs(total)))
    loaded = {k: float(np.max(np.abs(total[m]), initial=0.0)) >= LOADED_SHARE_OF_PEAK * peak for k, m in masks.items()}
    keys = list(masks)[3:]
    differs = np.array([any(_differs(by_turn[k][:, i] - base[:, i], tests) for i in range(M)) for k in keys])
    shown = {"driving": sign_differs, "braking": sign_differs, **dict(zip(keys, differs))}
    # the heaviest motor: the largest upper bound over every angle and over each sign or sector the data shows apart
    # where the torque is large enough to meet the limit
    candidates = [("every angle", np.where(np.isfinite(high), high, shares))]
    for k in (k for k, on in shown.items() if on and loaded[k]):
        hi = bounds(k)[1]
        candidates.append((k, np.where(np.isfinite(hi), hi, est[k])))
    where, up = max(candidates, key=lambda c: float(np.max(c[1])))
    m = int(np.argmax(up))
    sectors = (np.array([[j * SECTOR_DEG, (j + 1) * SECTOR_DEG] for j in range(J)]), np.array([est[k] for k in keys]),
               differs, np.array([loaded[k] for k in keys]))
    return MotorShares(tuple(channels), shares, low, high, K, {"driving": est["driving"], "braking": est["braking"]},
                       sign_differs, sectors, (m, float(up[m]), where))


def shares_of_rows(rows) -> MotorShares | None:
    """:func:`estimate_shares` of a drive log's rows as read (:class:`calibration.traces.drive_log.LogRows`, time-ordered
    by their time column); None for a log of one torque column."""
    if rows.motor_torques is None:
        return None
    t = rows.data[:, 0]
    order = np.argsort(np.where(np.isfinite(t), t, np.inf), kind="stable")
    return estimate_shares(rows.data[order, 1], rows.motor_torques[order], rows.motor_channels)
