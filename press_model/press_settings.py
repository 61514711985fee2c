"""The settings of a press file that are choices, not the press's own data: each a frozen dataclass whose defaults are
the reference press's values, with unit and reason (press_model/README.md "Defaults"). The geometry, masses,
inertias, joints, drive ratio and efficiency, motor limits, friction, balance cylinders and the sensitivity
parameters are the press's own and stay required.
"""
from __future__ import annotations

from dataclasses import dataclass

from .readers import FieldReader
from .settings_fields import fill_defaults, setting


def _read_range(rd: FieldReader, path: tuple, default: tuple) -> tuple[float, float]:
    """[low, high] factors of a nominal value; ``default`` when absent."""
    rel = rd.node(path, required=False)
    if rel is None:
        return default
    if not (isinstance(rel, list) and len(rel) == 2):
        rd.fail(path, rel, "must be [low, high] factors of the nominal value, e.g. [0.7, 1.3]")
    return (rd.number((*path, 0)), rd.number((*path, 1)))


@dataclass(frozen=True)
class PressSection:
    """The settings of [press] (its ``name`` is the press's own)."""

    gravity_m_s2: float = setting(9.81, "m/s^2", "standard gravity; acts along -y, the linkage moves in the x-y plane",
                                  gt=0.0, unit="m/s^2", limit="max_gravity_m_s2", what="the Earth's 9.81")


@dataclass(frozen=True)
class DriveSection:
    """The settings of [drive] (crank joint, angle offset, gear ratio, efficiency, gear inertia and motors are the press's)."""

    efficiency_at_standstill: str = setting("motoring", "", "at zero power take the larger (motoring) torque, the safe "
                                            "side", choices=("motoring", "braking"))


@dataclass(frozen=True)
class BalanceSection:
    """The model constants of [balance] (cylinders, piston area, tank volume and coefficient psi are the press's;
    ``masses`` defaults to "design" and ``design_mass_kg`` to the sum of the body masses)."""

    pressure_offset_MPa: float = setting(0.1033, "MPa", "Eq. 13's constant: the atmospheric offset of P0", ge=0.0,
                                         unit="MPa", limit="max_pressure_offset_MPa", what="an ambient pressure")
    polytropic_exponent: float = setting(1.4, "", "Eq. 13: adiabatic air", ge=1.0, le=2.0)


@dataclass(frozen=True)
class NumericsSection:
    """[numerics]: the model's solver settings."""

    position_tolerance_m: float = setting(1e-12, "m", "loop-closure Newton stop", gt=0.0, le=1e-6, unit="m",
                                          limit="min_position_tolerance_m", what="what float64 resolves on a press's links")
    newton_max_iterations: int = setting(30, "", "Newton iterations of the loop closure before it gives up",
                                         limit="max_iterations", what="what a converging loop needs")
    friction_tolerance: float = setting(1e-11, "", "relative change of the reactions at which the friction fixed point "
                                        "stops", gt=0.0, le=1e-3, limit="min_friction_tolerance",
                                        what="what float64 resolves in the reactions")
    friction_max_iterations: int = setting(200, "", "iterations of the friction fixed point before it gives up",
                                           limit="max_iterations", what="what a converging loop needs")
    baumgarte_phi1_per_s: float = setting(20.0, "1/s", "Eq. 8: damps velocity drift within ~0.1 s of a ~5 s stroke",
                                          ge=0.0, le=1000.0, unit="1/s")
    baumgarte_phi2_per_s: float = setting(20.0, "1/s", "Eq. 8, as phi1", ge=0.0, le=1000.0, unit="1/s")
    assembly_check_step_deg: float = setting(1.0, "deg", "crank step of the full-turn assembly check on load", le=10.0,
                                             unit="deg; the finest crank step of run_limits.toml")


@dataclass(frozen=True)
class SensitivitySection:
    """[sensitivity]: the sampling range of a parameter without its own ``range``."""

    default_relative_range: tuple = setting((0.7, 1.3), "x nominal", "70-130 % of the nominal value (paper Section "
                                            "3.2.2)", read=_read_range)


# the press file's tables with defaults, path -> settings dataclass
SECTIONS = {("press",): PressSection, ("drive",): DriveSection, ("balance",): BalanceSection,
            ("numerics",): NumericsSection, ("sensitivity",): SensitivitySection}


def with_defaults(raw: dict) -> dict:
    """``raw`` (a parsed press file, changed in place) with the defaults of :data:`SECTIONS` written in: what a press
    file of schema 1 had to say, so that its content (and fingerprint) is the same whether it says them or not. The
    default range is written only where a parameter has no range of its own (only then was it required)."""
    if not raw:  # an empty file is refused as such
        return raw
    present = {path: cls for path, cls in SECTIONS.items() if path[0] in raw}
    whole = {path: cls for path, cls in SECTIONS.items() if path in (("numerics",), ("sensitivity",))}
    params = raw.get("parameters")
    ranged = isinstance(params, dict) and all(isinstance(p, dict) and "range" in p for p in params.values())
    sens = raw.get("sensitivity")
    if ranged and not (isinstance(sens, dict) and "default_relative_range" in sens):
        present.pop(("sensitivity",), None)
        whole.pop(("sensitivity",))
    return fill_defaults(raw, {**present, **whole})
