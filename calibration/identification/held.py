"""The parameters a calibration holds: which of the job's parameters a subset leaves at the press file's values, their
score-test columns, and the warning when the log disagrees with one.

A sensitivity's key set (``--parameters key_parameters.json``) screens parameters by how much their *range* moves the
responses; it says nothing about whether the press file's value of a parameter left out is right for this press. The
log does: each held parameter is one more candidate of the adequacy's score tests
(:mod:`calibration.identification.adequacy`), its column the model curve's derivative along it, so its t says whether
the log disagrees with the held value beyond the noise (at the verdict's Bonferroni-shared level, as every other
candidate) and its coefficient is the change of the parameter the log implies (to first order). A held parameter the
log disagrees with is freed and the fit repeated (``[calibration.adequacy] free_held``), or only named.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.identification.adequacy import Candidate, ScoreTest
from calibration.identification.problem import Objective
from calibration.identification.curves import motor_curves
from press_model.press_data import PressData


@dataclass(frozen=True)
class Held:
    """What a calibration holds and has freed: ``names`` the job's parameters still held; ``freed`` the held parameters'
    tests the log disagreed with, freed so far; ``chosen`` the parameters first chosen and ``before`` {"rmse": N m, "F":
    lack-of-fit F} of their fit (None until one is freed)."""

    names: tuple[str, ...] = ()
    freed: tuple[ScoreTest, ...] = ()
    chosen: tuple[str, ...] = ()
    before: dict | None = None

    def record(self, statement: str) -> dict | None:
        """calibrated.json's ``held_parameters``: the names still held, those freed with their tests, and ``statement``
        (what freeing did, :func:`freed_warning`; "" if none was freed); None when the fit held none."""
        if not self.names and not self.freed:
            return None
        return {"held": list(self.names), "first_chosen": list(self.chosen),
                "freed": {t.name: {"held_value": t.held, "t": t.t, "implied_change": t.size, "implied_change_sd": t.size_std,
                                   "unit": t.unit} for t in self.freed},
                "statement": statement,
                "method": "each held parameter a score test beside the adequacy's candidates (its column the model curve's "
                          "derivative along it), at the verdict's Bonferroni-shared level; one the log disagrees with and no "
                          "other candidate explains is freed and the fit repeated (calibration/identification/held.py)"}

    def free(self, wrong: list[ScoreTest], chosen, before: dict) -> "Held":
        """These held parameters freed: the first fit's ``chosen`` names and ``before`` kept from the first freeing."""
        names = {t.name for t in wrong}
        return Held(tuple(n for n in self.names if n not in names), (*self.freed, *wrong), self.chosen or tuple(chosen),
                    self.before or before)


def held_names(job_parameters, calibrated) -> tuple[str, ...]:
    """The job's parameters (its [calibration] list, in its order) that a calibration of ``calibrated`` holds."""
    return tuple(n for n in job_parameters if n not in set(calibrated))


def held_candidates(o: Objective, x: np.ndarray, press: PressData, names) -> list[Candidate]:
    """One score-test candidate per held parameter of ``names``: the derivative (N m per unit, SI) of the model curve on
    ``o``'s grid at the calibrated ``x`` along it, by a central difference of a thousandth of its sensitivity range (the
    curve is smooth in every parameter; the step's error is of its square, far below the noise)."""
    bm = o.bm
    col = {n: i for i, n in enumerate(bm.names)}
    base = o.problem.full_sets(bm, np.asarray(x, float)[None])[0]
    out = []
    for n in names:
        p = press.parameters[n]
        h = 1e-3 * (p.high - p.low)
        X = np.tile(base, (2, 1))
        X[0, col[n]] += h
        X[1, col[n]] -= h
        T = motor_curves(bm, X)
        value = float(base[col[n]])
        unit = "" if p.unit == "1" else p.unit  # a ratio's unit is said by no word
        out.append(Candidate(n, f"{n} held at {value:.4g}{' ' + unit if unit else ''}", ((T[0] - T[1]) / (2.0 * h))[:, None],
                             unit, 1.0, held=value))
    return out


def disagreeing(tests) -> list[ScoreTest]:
    """The held parameters the log disagrees with: significant, and not explained by another significant candidate; when
    every significant one is explained by another (two held parameters the log cannot tell apart), the one of the
    largest t, so that a fit repeated with it freed judges the rest."""
    sig = [t for t in tests if t.held is not None and t.significant]
    alone = [t for t in sig if not t.explained_by]
    return alone or sorted(sig, key=lambda t: -t.t)[:1]


def describe(t: ScoreTest) -> str:
    """A held parameter's test in words: held value, t, the value the log implies, with its standard error."""
    u = f" {t.unit}" if t.unit else ""
    return (f"{t.name} held at {t.held:.4g}{u} (score t = {t.t:.1f}; the log implies {t.held + t.size:.4g} "
            f"+- {t.size_std:.2g}{u})")


def freed_warning(freed, calibrated, before: dict, after: dict) -> str:
    """The WARNING of a fit repeated with held parameters freed: which, why, and what freeing them did (``before``,
    ``after``: {"rmse": N m, "F": lack-of-fit F, "adequate": bool} of the subset's fit and of the repeated fit)."""
    verdict = "adequate" if after["adequate"] else "still NOT ADEQUATE"
    return (f"HELD PARAMETER FREED: the log disagrees with {'; '.join(describe(t) for t in freed)}, which the parameters "
            f"chosen ({', '.join(calibrated)}) would otherwise absorb; calibrated with {'it' if len(freed) == 1 else 'them'} "
            f"too: RMSE {before['rmse']:.1f} -> {after['rmse']:.1f} N m, lack-of-fit F {before['F']:.2f} -> {after['F']:.2f}, "
            f"{verdict}. {'Its press-file value is' if len(freed) == 1 else 'Their press-file values are'} not this press's: calibrate {'it' if len(freed) == 1 else 'them'} on this press (--parameters "
            f"{','.join([*calibrated, *(t.name for t in freed)])}), or set [calibration.adequacy] free_held = false to "
            "keep the list as given and only be warned")


def held_warning(held: list[ScoreTest]) -> str:
    """The WARNING of a fit that keeps held parameters the log disagrees with (``free_held = false``): which, and what
    freeing them would do (the lack-of-fit F with each freed, linearised)."""
    what = "; ".join(f"{describe(t)}: freeing it would bring the lack-of-fit F to about {t.lof_if_freed:.2f}"
                     for t in held if math.isfinite(t.lof_if_freed))
    return (f"HELD PARAMETER WRONG FOR THIS LOG: {what}. The calibrated parameters absorb that error; add "
            f"{', '.join(t.name for t in held)} to --parameters (or set [calibration.adequacy] free_held = true)")
