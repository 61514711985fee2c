"""The press file's tables of plain values, each a frozen dataclass whose fields are the file's keys, read once by
:func:`press_model.settings_fields.read_section`. The settings that are choices, not the press's own data, have
the reference press's values as defaults, with unit and reason (press_model/README.md "Defaults"); the drive ratio
and efficiency, motor limits, friction and balance cylinders are the press's own (:func:`key`: required, with their
checks), as are the geometry, masses, inertias, joints and sensitivity parameters (press_model/press_data.py reads
those tables of named bodies and joints).
"""
from __future__ import annotations

from dataclasses import dataclass

from .readers import FieldReader
from .settings_fields import fill_defaults, key, setting


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
    """[press]: the press's name and gravity."""

    name: str = key(str, "", "the press's name, in every result file")
    gravity_m_s2: float = setting(9.81, "m/s^2", "standard gravity; acts along -y, the linkage moves in the x-y plane",
                                  gt=0.0, unit="m/s^2", limit="max_gravity_m_s2", what="the Earth's 9.81")


@dataclass(frozen=True)
class DriveSection:
    """[drive]: the driven crank joint and the gear (Eq. 16); its losses are [drive.losses] (:class:`LossesSection`)."""

    crank_joint: str = key(str, "", "the revolute joint the gear drives, between the crank and the frame")
    angle_offset_deg: float = key(float, "deg", "crank body angle at crank angle 0", ge=-360.0, le=360.0, unit="deg")
    gear_ratio: float = key(float, "", "motor turns per crank turn", gt=0.0, limit="max_gear_ratio", what="any press drive")
    efficiency: float = key(float, "", "Eq. 16's eta_gear", gt=0.0, le=1.0)
    gear_inertia_kg_m2: float = key(float, "kg m^2", "the gear's inertia at the motor shaft", ge=0.0,
                                    unit="kg m^2 at the motor shaft", limit="max_inertia_kg_m2", what="any press drive")
    motors: int = key(int, "", "motors driving the gear", limit="max_motors", what="any press drive")
    efficiency_at_standstill: str = setting("motoring", "", "at zero power take the larger (motoring) torque, the safe "
                                            "side", choices=("motoring", "braking"))


@dataclass(frozen=True)
class LossesSection:
    """[drive.losses]: the drive losses Eq. 16 leaves out (:func:`press_model.motor.eq16`), off unless ``enabled``;
    ``coulomb_drag_Nm``'s bound is the motors' rated torque, read beside (press_model/press_data.py)."""

    enabled: bool = key(bool, "", "model the losses below", default=False)
    load_loss_at_rated: float = key(float, "", "extra gear loss torque at the rated motor torque, per unit of it", default=0.0,
                                    ge=0.0, le=1.0, unit="extra gear loss torque at the rated motor torque, per unit of it")
    viscous_Nms_per_rad: float = key(float, "N m s/rad", "a speed-proportional loss per motor at the motor shaft", default=0.0,
                                     ge=0.0, unit="N m s/rad at the motor shaft")
    coulomb_drag_Nm: float = key(float, "N m", "a drag per motor at the motor shaft opposing the rotation", default=0.0,
                                 ge=0.0, unit="N m per motor at the motor shaft (below the motors' rated torque: more would "
                                 "leave them nothing)")


def _read_shares(rd: FieldReader, path: tuple, default: tuple) -> tuple[float, ...]:
    """Each motor's share of the total torque, fractions adding to 1; ``default`` (an even load) when absent. Their
    count is checked against the drive's motors beside it (press_model/press_data.py)."""
    shares = rd.node(path, required=False)
    if shares is None:
        return default
    if not (isinstance(shares, list) and len(shares) >= 2):
        rd.fail(path, shares, "must be a list of each motor's share of the total torque, e.g. [0.53, 0.47]")
    values = tuple(rd.number((*path, i), gt=0.0, lt=1.0) for i in range(len(shares)))
    if abs(sum(values) - 1.0) > 1e-6:
        rd.fail(path, shares, f"must add to 1 (they add to {sum(values):.6g}): each is a motor's fraction of the total torque")
    return values


@dataclass(frozen=True)
class MotorSection:
    """[motor]: the limits of each motor, and how the motors share the load."""

    peak_torque_Nm: float = key(float, "N m", "peak torque per motor", gt=0.0, unit="N m", limit="max_motor_torque_Nm",
                                what="any servo motor")
    rated_torque_Nm: float = key(float, "N m", "rated (thermal, RMS) torque per motor", gt=0.0, unit="N m",
                                 limit="max_motor_torque_Nm", what="any servo motor")
    max_speed_rpm: float = key(float, "rpm", "top speed at the motor shaft", gt=0.0, unit="rpm", limit="max_motor_speed_rpm",
                               what="any servo motor")
    load_shares: tuple = key(tuple, "", "each motor's share of the total torque, in the order of the drive log's torque "
                             "columns, measured (a calibration's motor_shares) or stated by the press builder; absent: an "
                             "even load, as identical motors on one gear with their drives' torque loops tuned alike share "
                             "it; the plan holds the heaviest motor to the torque margin", default=(), read=_read_shares)
    load_share_tolerance: float = key(float, "", "largest difference between two motors' shares that calibrate accepts "
                                      "without a warning: 0.03, since a drive's torque channel is its current times the "
                                      "motor's torque constant, stated within +/-3 % (servo motor data sheets, k_T "
                                      "tolerance), so two channels of an even load may read shares 0.515/0.485",
                                      default=0.03, ge=0.0, lt=1.0)


@dataclass(frozen=True)
class FrictionSection:
    """[friction]: Coulomb and viscous coefficients of the revolute joints and the guide (Eqs. 10-12)."""

    revolute_coefficient: float = key(float, "", "mu_r", ge=0.0, lt=1.0)
    revolute_viscous_Nms_per_rad: float = key(float, "N m s/rad", "c_r", ge=0.0, unit="N m s/rad",
                                              limit="max_revolute_viscous_Nms_per_rad", what="any press bearing")
    guide_coefficient: float = key(float, "", "mu_s", ge=0.0, lt=1.0)
    guide_viscous_Ns_per_m: float = key(float, "N s/m", "c_s", ge=0.0, unit="N s/m", limit="max_guide_viscous_Ns_per_m",
                                        what="any slide guide")


@dataclass(frozen=True)
class BalanceSection:
    """[balance]: the pneumatic balance (Eqs. 13, 17); ``design_mass_kg`` (default: the sum of the body masses) is
    read beside it (press_model/press_data.py)."""

    cylinders: int = key(int, "", "balance cylinders; 0: a press without balance", ge=0, limit="max_balance_cylinders",
                         what="any press's balance")
    piston_area_m2: float = key(float, "m^2", "piston area of each cylinder", gt=0.0, unit="m^2", limit="max_piston_area_m2",
                                what="any balance cylinder")
    tank_volume_m3: float = key(float, "m^3", "tank volume of each cylinder", gt=0.0, unit="m^3", limit="max_tank_volume_m3",
                                what="any balance tank")
    coefficient: float = key(float, "", "psi: the share of the moving weight the balance carries", ge=0.0, le=3.0)
    pressure_offset_MPa: float = setting(0.1033, "MPa", "Eq. 13's constant: the atmospheric offset of P0", ge=0.0,
                                         unit="MPa", limit="max_pressure_offset_MPa", what="an ambient pressure")
    polytropic_exponent: float = setting(1.4, "", "Eq. 13: adiabatic air", ge=1.0, le=2.0)
    masses: str = key(str, "", '"design": the pressure is set from the design masses; "actual": from the current body '
                      "masses", default="design", choices=("design", "actual"))


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
