"""The press description: a human-edited TOML file read into an immutable, validated object.

The file describes the linkage generically (bodies with named points, joints joining body points,
the slide and its guide, the driven crank), the drive, friction and balance data, and the names of
the sensitivity parameters as paths into the file. Nothing in the physics modules names a link.

Units follow the suffix of each key (``_m``, ``_kg``, ``_kg_m2``, ``_deg`` ...). Angles are degrees in
the file and radians in the object.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np

from .electrical import Electrical, read_electrical
from press_io.errors import PressDataError
from .geometry import GRADIENT_TOL, trilaterate
from .press_settings import (BalanceSection, DriveSection, FrictionSection, LossesSection, MotorSection, NumericsSection,
                             PressSection, SensitivitySection, with_defaults)
from .readers import FieldReader, copy_tree, data_fingerprint, read_toml
from .schema import SCHEMA_KEY, migrate
from .settings_fields import read_section, read_value

FRAME = "frame"  # the reserved name of the fixed ground body

BUILTIN_PRESSES = {"reference": "reference_press.toml", "crank-slider": "crank_slider.toml"}
_NAME = re.compile(r"[A-Za-z0-9_-]+")
_PIN_ROOT = "universe"  # Pinocchio's name for its root joint and frame


def _check_name(rd: "FieldReader", path, name: str) -> None:
    """Body, joint and point names go into URDF names and Pinocchio frames (``<body>__<point>``)."""
    if not _NAME.fullmatch(name) or "__" in name or name == _PIN_ROOT:
        rd.fail(path, name, f"names must use only letters, digits, '_' or '-', without '__', and not be '{_PIN_ROOT}'")


@dataclass(frozen=True)
class ComSpec:
    """How the file places a body's COM, as given (so that an algorithm varying it never reads the file).

    ``kind``: "fixed" (``[x_m, y_m]``), "line" (``distance`` m from point ``start`` toward point ``toward``) or
    "trilateration" (``distances``: m to each named point, file order).
    """

    kind: str
    start: str | None = None
    toward: str | None = None
    distance: float | None = None
    distances: Mapping[str, float] | None = None


@dataclass(frozen=True)
class Body:
    """A rigid moving body. Points and COM are in body coordinates (m); inertia about the COM (kg m^2)."""

    name: str
    label: str
    mass: float
    inertia: float
    points: Mapping[str, np.ndarray]
    com: np.ndarray
    com_spec: ComSpec


@dataclass(frozen=True)
class Joint:
    """A joint between ``first`` and ``second`` (body name, point name). Relative motion is first - second."""

    name: str
    kind: str  # "revolute" or "prismatic"
    first: tuple[str, str]
    second: tuple[str, str]
    bearing_radius: float = 0.0  # m, revolute only
    axis: np.ndarray | None = None  # unit vector in the second body's frame, prismatic only


@dataclass(frozen=True)
class Drive:
    crank_body: str
    crank_joint: str
    angle_offset: float  # rad: crank body angle = angle_offset + theta_c
    gear_ratio: float
    efficiency: float
    gear_inertia: float  # kg m^2 at the motor shaft
    motors: int
    standstill: str  # "motoring" or "braking": efficiency exponent when the power is exactly zero
    # the losses Eq. 16 leaves out ([drive.losses] of the press file, :func:`press_model.motor.eq16`); 0 = off
    load_loss_at_rated: float = 0.0  # 1: extra gear loss torque at the motors' rated torque, per unit of it
    loss_reference_torque: float = 1.0  # N m: the motors' rated torque that load_loss_at_rated refers to (set by the reader)
    viscous: float = 0.0  # N m s/rad per motor at the motor shaft: a speed-proportional drive loss
    coulomb_drag: float = 0.0  # N m per motor at the motor shaft: a drag of constant magnitude opposing the rotation

    @property
    def has_losses(self) -> bool:
        """True when the press file turns on a loss that the paper's Eq. 16 leaves out."""
        return self.load_loss_at_rated != 0.0 or self.viscous != 0.0 or self.coulomb_drag != 0.0

    @property
    def load_loss_per_Nm(self) -> float:
        """1/(N m): the load-dependent loss torque is this x T_B |T_B| (:func:`press_model.motor.eq16`)."""
        return self.load_loss_at_rated / self.loss_reference_torque


@dataclass(frozen=True)
class MotorLimits:
    peak_torque: float  # N m per motor
    rated_torque: float  # N m per motor (thermal, RMS)
    max_speed: float  # rad/s at the motor shaft
    load_shares: tuple[float, ...] = ()  # each motor's share of the total torque (fractions adding to 1); (): an even load
    load_share_tolerance: float = 0.03  # largest difference of two shares calibrate accepts without a warning

    def heaviest_factor(self, motors: int) -> float:
        """The heaviest motor's torque per unit of the mean motor torque under the stated shares (motors x the
        largest share; 1 for an even load)."""
        return max(1.0, motors * max(self.load_shares)) if self.load_shares else 1.0


@dataclass(frozen=True)
class Friction:
    mu_r: float
    c_r: float  # N m s/rad
    mu_s: float
    c_s: float  # N s/m


@dataclass(frozen=True)
class Balance:
    cylinders: int
    piston_area: float  # m^2 each
    tank_volume: float  # m^3 each
    psi: float
    pressure_offset_mpa: float
    polytropic_exponent: float
    masses: str  # "design": z P0 A_b = psi * design_mass * g; "actual": psi * (sum of the current body masses) * g
    design_mass: float  # kg, sum of the moving masses the balance pressure is set from


@dataclass(frozen=True)
class Target:
    """What a sensitivity parameter sets in the press description, resolved from its file path by :func:`read_press`.

    ``section``: the file's top-level table ("drive", "friction", "balance", "bodies", ...). ``field``: one of the
    scalars of :data:`SCALAR_TARGETS` ("gear_inertia", "efficiency", "load_loss", "viscous", "coulomb_drag": Drive; "mu_r", "c_r", "mu_s", "c_s": Friction;
    "psi": Balance); or, of the body ``body``, "mass", "inertia", "com_distance" (a COM on a line) or
    "com_distances" (the trilateration distance to its vertex ``point``); or "" for any other number of the file,
    which only a new press description (:meth:`PressData.with_overrides`, the Pinocchio path) varies.
    """

    section: str
    field: str
    body: str = ""
    point: str = ""


SCALAR_TARGETS = {  # file path of a drive, friction or balance scalar -> its Target (field: the model's name)
    "drive.gear_inertia_kg_m2": Target("drive", "gear_inertia"),
    "drive.efficiency": Target("drive", "efficiency"),
    "drive.losses.load_loss_at_rated": Target("drive", "load_loss"),
    "drive.losses.viscous_Nms_per_rad": Target("drive", "viscous"),
    "drive.losses.coulomb_drag_Nm": Target("drive", "coulomb_drag"),
    "friction.revolute_coefficient": Target("friction", "mu_r"),
    "friction.revolute_viscous_Nms_per_rad": Target("friction", "c_r"),
    "friction.guide_coefficient": Target("friction", "mu_s"),
    "friction.guide_viscous_Ns_per_m": Target("friction", "c_s"),
    "balance.coefficient": Target("balance", "psi"),
}


def _target(path: str, bodies: Mapping) -> Target:
    """The :class:`Target` of the parameter at the file path ``path`` (dotted keys)."""
    parts = path.split(".")
    if path in SCALAR_TARGETS:
        return SCALAR_TARGETS[path]
    if parts[0] == "bodies" and len(parts) >= 3 and parts[1] in bodies:
        tail = parts[2:]
        fields = {("mass_kg",): "mass", ("inertia_kg_m2",): "inertia", ("com", "distance_m"): "com_distance"}
        if tuple(tail) in fields:
            return Target("bodies", fields[tuple(tail)], parts[1])
        if len(tail) == 3 and tail[:2] == ["com", "distances_m"]:
            return Target("bodies", "com_distances", parts[1], tail[2])
    return Target(parts[0], "")


@dataclass(frozen=True)
class Parameter:
    """A sensitivity parameter: a name, the path of its value in the file, its sampling range and what it sets."""

    name: str
    path: str
    nominal: float
    low: float
    high: float
    unit: str
    target: Target  # resolved from ``path`` when the press file is read


def _finest_step() -> float:
    """The finest crank step, deg, of run_limits.toml (a finer assembly check takes minutes and finds nothing new)."""
    from .limits import run_limits

    return run_limits().min_step_deg


def _design_mass(rd: FieldReader, path, bodies: Mapping[str, "Body"]) -> float:
    """The balance's design moving mass, kg (default: the sum of the body masses), at most every body at
    max_mass_kg of run_limits.toml."""
    from .limits import LIMITS_FILE, run_limits

    value = rd.number(path, gt=0.0, unit="kg", default=sum(b.mass for b in bodies.values()))
    bound = len(bodies) * run_limits().max_mass_kg
    if value > bound:
        rd.fail(path, value, f"must be at most {bound:g} kg, every body at max_mass_kg in {LIMITS_FILE}; check the unit and the exponent")
    return value


def _point(rd: FieldReader, path) -> np.ndarray:
    """A point [x_m, y_m] (or polar) no farther from its body's origin than max_length_m of run_limits.toml."""
    from .limits import LIMITS_FILE, run_limits

    p = rd.vec2(path)
    bound = run_limits().max_length_m
    with np.errstate(over="ignore"):
        far = float(np.hypot(*p))
    if not far <= bound:
        rd.fail(path, [float(p[0]), float(p[1])], f"lies {far:.3g} m from the body's origin: must be within {bound:g} m, "
                f"far beyond any press (max_length_m in {LIMITS_FILE}); check the unit and the exponent")
    return p


def _length(rd: FieldReader, path, value: float) -> float:
    """A length (m) within max_length_m of run_limits.toml, either sign."""
    from .limits import LIMITS_FILE, run_limits

    bound = run_limits().max_length_m
    if abs(value) > bound:
        rd.fail(path, value, f"must be within {bound:g} m, far beyond any press (max_length_m in {LIMITS_FILE}); check the unit and the exponent")
    return value


def _check_com_inside(rd: FieldReader, path, points: Mapping[str, np.ndarray], com: np.ndarray) -> None:
    """Refuse a centre of mass outside its body: farther from the body's nearest joint point than the body's
    span (the largest distance between two of its points), or, on a body with one point, than
    max_com_offset_m of run_limits.toml. Mass outside the material cannot be, and the reactions would be wrong."""
    from .limits import LIMITS_FILE, run_limits

    pts = np.asarray(list(points.values()))
    span = max((float(np.hypot(*(a - b))) for a in pts for b in pts), default=0.0)
    reach = span if len(pts) > 1 else run_limits().max_com_offset_m
    nearest = float(np.min(np.hypot(*(pts - com).T)))
    if nearest > reach:
        why = (f"its points are at most {span:.4g} m apart" if len(pts) > 1
               else f"max_com_offset_m = {reach:g} m for a body with one joint point, in {LIMITS_FILE}")
        rd.fail(path, [round(float(com[0]), 6), round(float(com[1]), 6)],
                f"puts the centre of mass {nearest:.4g} m from the body's nearest joint point, outside the body ({why}); "
                "check the COM's coordinates, distances and points")


_COM_FITS: dict[bytes, tuple[np.ndarray, float]] = {}  # a press is read again at every override, its COM fit alike


def _fitted_com(points: np.ndarray, distances: np.ndarray) -> tuple[np.ndarray, float]:
    """:func:`trilaterate`'s point (m, a new array) and gradient norm (m) for the one row ``distances`` (1, k) to
    ``points`` (k, 2), kept by the inputs' bytes: the same inputs give the same bits, so a fit is made once a process."""
    key = points.tobytes() + distances.tobytes()
    if key not in _COM_FITS:
        if len(_COM_FITS) >= 1024:  # a fuzz or a long session of edited presses: keep the memory bounded
            _COM_FITS.clear()
        with np.errstate(all="ignore"):  # absurd distances overflow; the caller checks the result
            com, gnorm = trilaterate(points, distances)
        _COM_FITS[key] = (com[0], float(gnorm[0]))
    com, gnorm = _COM_FITS[key]
    return com.copy(), gnorm


def _read_com(rd: FieldReader, path, points: Mapping[str, np.ndarray]) -> tuple[np.ndarray, ComSpec]:
    """The COM (body coordinates, m) and how the file gives it."""
    spec = rd.node(path)
    known = ", ".join(sorted(points))
    if isinstance(spec, list):
        return _point(rd, path), ComSpec("fixed")
    if not isinstance(spec, Mapping):
        rd.fail(path, spec, "must be [x_m, y_m], {from, toward, distance_m} or {distances_m = {point = d}}")
    if "distances_m" in spec:
        dist = rd.table((*path, "distances_m"))
        if len(dist) < 3:
            rd.fail((*path, "distances_m"), dict(dist), "needs distances to at least three points to fix a COM")
        pts, ds = [], []
        for pname in dist:
            if pname not in points:
                rd.fail((*path, "distances_m", pname), pname, f"must name a point of this body ({known})")
            pts.append(points[pname])
            ds.append(_length(rd, (*path, "distances_m", pname), rd.number((*path, "distances_m", pname), gt=0.0, unit="m")))
        com, gnorm = _fitted_com(np.asarray(pts), np.asarray([ds]))
        if not (np.all(np.isfinite(com)) and gnorm <= GRADIENT_TOL):  # a least-squares point has zero gradient
            rd.fail((*path, "distances_m"), dict(dist), "no centre of mass fits these distances (the least-squares "
                    "trilateration did not converge); check that they are consistent with the body's points")
        return com, ComSpec("trilateration", distances=MappingProxyType(dict(zip(dist, ds))))
    start = rd.string((*path, "from"))
    toward = rd.string((*path, "toward"))
    for key, pname in (("from", start), ("toward", toward)):
        if pname not in points:
            rd.fail((*path, key), pname, f"must name a point of this body ({known})")
    with np.errstate(all="ignore"):  # points of absurd size overflow here: the result is checked below
        direction = points[toward] - points[start]
        length = math.hypot(*direction)
        if length < 1e-12:
            rd.fail((*path, "toward"), toward, "must differ in position from the 'from' point")
        dist = _length(rd, (*path, "distance_m"), rd.number((*path, "distance_m"), unit="m"))
        com = points[start] + dist * direction / length
    if not np.all(np.isfinite(com)):
        rd.fail((*path, "distance_m"), dist, f"puts the centre of mass out of reach of float arithmetic (points "
                f"{start} and {toward} of this body are {length:.3g} m apart): check the body's points_m")
    return com, ComSpec("line", start=start, toward=toward, distance=dist)


@dataclass(frozen=True, eq=False)
class PressData:
    """An immutable, validated press description: plain data, built from a press file by :func:`read_press`
    (:func:`load_press` reads the file). Lengths in m, angles in rad, masses in kg.

    :meth:`with_overrides` returns a new object with some sensitivity parameters changed; this one never changes.
    """

    source: str  # the file, for messages
    fingerprint: str  # identifies the press as loaded (results made on one press are refused on another); overrides keep it
    name: str
    gravity: float  # m/s^2
    frame_points: Mapping[str, np.ndarray]
    bodies: Mapping[str, Body]
    joints: Mapping[str, Joint]
    revolute_joints: tuple[Joint, ...]
    guide: Joint  # the one prismatic joint
    slide_body: str
    slide_point: str
    cut_joints_hint: tuple[str, ...] | None
    drive: Drive
    motor: MotorLimits
    friction: Friction
    balance: Balance
    numerics: NumericsSection  # [numerics] as the file gives it (its units: m, 1/s, deg)
    assembly_crank_angle: float  # rad
    assembly_angles: Mapping[str, float]  # rad, body angle hints for the first assembly
    parameters: Mapping[str, Parameter]
    _raw: Mapping = field(repr=False)  # the file's contents: overrides are applied to it and read again
    electrical: Electrical | None = None  # [drive.electrical] (press_model.power_flow); None: off, no electrical quantity

    # --- parameters --------------------------------------------------------------------------
    def parameter_values(self) -> dict[str, float]:
        """Current value of every sensitivity parameter (SI units), by name."""
        return {p.name: self._get(p.path) for p in self.parameters.values()}

    def _get(self, path: str):
        cur = self._raw
        for k in path.split("."):
            cur = cur[k]
        return float(cur)

    def with_overrides(self, overrides: Mapping[str, float], source: str = "--params") -> "PressData":
        """A new PressData with the named sensitivity parameters replaced (SI units)."""
        raw = copy_tree(self._raw)
        if self.balance.masses == "design":
            raw["balance"]["design_mass_kg"] = self.balance.design_mass
        for name, value in overrides.items():
            if name not in self.parameters:
                raise PressDataError(source, name, value, self.unknown_parameter_hint(name))
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise PressDataError(source, name, value, "must be a finite number")
            cur = raw
            keys = self.parameters[name].path.split(".")
            for k in keys[:-1]:
                cur = cur[k]
            cur[keys[-1]] = float(value)
        return read_press(raw, f"{self.source} with {source}", fingerprint=self.fingerprint)

    def unknown_parameter_hint(self, name: str) -> str:
        """What an error message says of ``name`` when it is not in :attr:`parameters`: a parameter of a switched-off
        option (``requires`` in the press file) is named as such, with the switch that turns it on."""
        spec = self._raw.get("parameters", {}).get(name)
        if isinstance(spec, Mapping) and spec.get("requires") == LOSS_SWITCH:
            return f"is a parameter only when the press file sets {LOSS_SWITCH} = true (it is off in {self.source})"
        return f"is not a parameter of this press; known: {', '.join(self.parameters)}"

    def raw(self) -> dict:
        """A deep copy of the file's contents (for provenance records)."""
        return copy_tree(self._raw)

    def identity(self) -> dict:
        """The press as every result file names it: ``press`` (name), ``press_source`` (file), ``press_fingerprint``."""
        return {"press": self.name, "press_source": self.source, "press_fingerprint": self.fingerprint}


def check_parameter_ranges(press: PressData, names=None) -> None:
    """Refuse a sensitivity range whose end is no valid value of its field (``mu_r`` up to 1e300, ``eta_gear`` up
    to 1.5): a sampler or an optimiser would run the model there. Reads the press again with each end of each named
    parameter (default: all) in place; raises :class:`PressDataError` naming ``parameters.<name>.range`` and why."""
    for name in names if names is not None else press.parameters:
        p = press.parameters[name]
        key = (press.fingerprint, name, p.low, p.high)
        if key in _RANGES_CHECKED:  # a monitor or a test suite calibrates the same press many times
            continue
        for end in (p.low, p.high):
            try:
                press.with_overrides({name: end}, source=f"the range of {name}")
            except PressDataError as exc:
                raise PressDataError(press.source, f"parameters.{name}.range", [p.low, p.high],
                                     f"must hold only valid values of {p.path}: at {end!r}, {exc.field} {exc.expected}; narrow the range") from None
        _RANGES_CHECKED.add(key)


_RANGES_CHECKED: set[tuple] = set()  # (press fingerprint, parameter, low, high) found valid at both ends


def load_press(path: str | Path | None = None) -> PressData:
    """Read and validate a press file. ``None`` or a built-in name ('reference', 'crank-slider') loads a shipped one.
    A file of an older schema (none given: 1) is read as the current one, with a note (:mod:`press_model.schema`)."""
    builtin = BUILTIN_PRESSES[str(path) if path is not None else "reference"] if path is None or str(path) in BUILTIN_PRESSES else None
    raw, source = read_toml(path, builtin, "--press", "must be an existing TOML file or one of " + ", ".join(BUILTIN_PRESSES))
    if "press" not in raw and "job" in raw:
        raise PressDataError(source, "--press", source, "is a job file (it has [job], no [press]): pass it as --job, and give "
                             "--press a press file or one of " + ", ".join(BUILTIN_PRESSES))
    return read_press(migrate(raw, "press", source), source)


def is_reference_press(fingerprint: str) -> bool:
    """Whether the press of ``fingerprint`` (:attr:`PressData.fingerprint`, which overrides keep, or a result's
    ``press_fingerprint``) is the shipped reference press, the paper's. Only then are the paper's figures set beside a
    result, labelled as the paper's; a press edited from it is the user's own, and the paper says nothing about it."""
    return fingerprint == _reference_fingerprint()


@functools.lru_cache(maxsize=1)
def _reference_fingerprint() -> str:
    return load_press("reference").fingerprint


def read_press(raw: Mapping, source: str, fingerprint: str | None = None) -> PressData:
    """The validated :class:`PressData` of a press file's parsed TOML ``raw`` (the current schema; a ``schema`` key of
    an older one is migrated, :mod:`press_model.schema`); ``source`` names it in messages. Absent settings take the
    defaults of :mod:`press_model.press_settings`, written into the press's content before its fingerprint is taken.

    Every error is a :class:`PressDataError` naming the field, the value and the fix.
    """
    raw = copy_tree(dict(raw))
    if SCHEMA_KEY in raw:
        raw = migrate(raw, "press", source)
    raw = with_defaults(raw)
    # identifies the press as loaded (results made on one press are refused on another); overrides keep it
    fingerprint = fingerprint or data_fingerprint(_identity(raw))
    rd = FieldReader(source, raw)
    name, gravity = _read_header(rd)
    frame_points = _read_frame(rd)
    bodies = _read_bodies(rd)
    joints = _read_joints(rd, bodies, frame_points)
    revolute_joints = tuple(j for j in joints.values() if j.kind == "revolute")
    guide = _guide(rd, joints)
    cut_joints_hint = _read_tree(rd, joints)
    drive = _read_drive(rd, joints)
    motor = _read_motor(rd)
    if motor.load_shares and len(motor.load_shares) != drive.motors:
        rd.fail(("motor", "load_shares"), list(motor.load_shares), f"must hold one share per motor ([drive] motors = {drive.motors})")
    drive = _read_losses(rd, drive, motor)
    electrical = read_electrical(rd, motor.max_speed)
    friction = _read_friction(rd)
    balance = _read_balance(rd, bodies)
    numerics = _read_numerics(rd)
    assembly_crank_angle, assembly_angles = _read_assembly(rd, bodies)
    parameters = _read_parameters(rd, bodies)
    rd.reject_unread()
    _check_topology(rd, bodies, joints)
    return PressData(
        source=source,
        fingerprint=fingerprint,
        name=name,
        gravity=gravity,
        frame_points=frame_points,
        bodies=bodies,
        joints=joints,
        revolute_joints=revolute_joints,
        guide=guide,
        slide_body=guide.first[0],
        slide_point=guide.first[1],
        cut_joints_hint=cut_joints_hint,
        drive=drive,
        motor=motor,
        friction=friction,
        balance=balance,
        numerics=numerics,
        assembly_crank_angle=assembly_crank_angle,
        assembly_angles=assembly_angles,
        parameters=parameters,
        _raw=raw,
        electrical=electrical,
    )


def _read_header(rd: FieldReader) -> tuple[str, float]:
    """[press]: the press's name and gravity, m/s^2."""
    rd.table(("press",))
    press = read_section(rd, ("press",), PressSection)
    return press.name, press.gravity_m_s2


def _read_frame(rd: FieldReader) -> Mapping[str, np.ndarray]:
    """[frame]: the fixed pivots by name, m."""
    frame_pts = rd.table(("frame", "points_m"))
    if not frame_pts:
        rd.fail(("frame", "points_m"), {}, "needs at least one frame point")
    for k in frame_pts:
        _check_name(rd, ("frame", "points_m", k), k)
    return MappingProxyType({k: _point(rd, ("frame", "points_m", k)) for k in frame_pts})


def _read_bodies(rd: FieldReader) -> Mapping[str, Body]:
    """[bodies.*]: the moving bodies by name, file order."""
    bodies = {}
    raw_bodies = rd.table(("bodies",))
    if not raw_bodies:
        rd.fail(("bodies",), {}, "needs at least one moving body")
    for bname in raw_bodies:
        if bname == FRAME:
            rd.fail(("bodies", bname), bname, f"'{FRAME}' is reserved for the fixed ground; rename the body")
        path = ("bodies", bname)
        _check_name(rd, path, bname)
        pts = rd.table((*path, "points_m"))
        if not pts:
            rd.fail((*path, "points_m"), {}, "needs the body's joint points in body coordinates")
        for k in pts:
            _check_name(rd, (*path, "points_m", k), k)
        points = {k: _point(rd, (*path, "points_m", k)) for k in pts}
        com, com_spec = _read_com(rd, (*path, "com"), points)
        _check_com_inside(rd, (*path, "com"), points, com)
        bodies[bname] = Body(
            name=bname,
            label=rd.string((*path, "label"), default=bname),
            mass=rd.number((*path, "mass_kg"), gt=0.0, unit="kg", limit="max_mass_kg", what="any press body"),
            inertia=rd.number((*path, "inertia_kg_m2"), ge=0.0, unit="kg m^2 about the COM", limit="max_inertia_kg_m2",
                           what="any press body"),
            points=MappingProxyType(points),
            com=com,
            com_spec=com_spec,
        )
    return MappingProxyType(bodies)


def _read_joints(rd: FieldReader, bodies: Mapping[str, Body], frame_points: Mapping[str, np.ndarray]) -> Mapping[str, Joint]:
    """[joints.*]: the joints by name, file order, each joining two body (or frame) points."""
    joints = {}
    raw_joints = rd.table(("joints",))
    for jname in raw_joints:
        path = ("joints", jname)
        _check_name(rd, path, jname)
        if jname in bodies or jname == FRAME:  # a Pinocchio joint frame would share the body frame's name
            rd.fail(path, jname, f"a joint name must differ from every body name ({FRAME}, {', '.join(bodies)})")
        kind = rd.string((*path, "type"), choices=("revolute", "prismatic"))
        conn = rd.node((*path, "connects"))
        if not (isinstance(conn, list) and len(conn) == 2 and all(isinstance(c, str) for c in conn)):
            rd.fail((*path, "connects"), conn, 'must be two "body.point" names, e.g. ["crank.O", "frame.O"]')
        ends = []
        for c in conn:
            body, _, point = c.partition(".")
            pts = frame_points if body == FRAME else (bodies[body].points if body in bodies else None)
            if pts is None:
                rd.fail((*path, "connects"), c, f"body must be '{FRAME}' or one of {', '.join(bodies)}")
            if point not in pts:
                rd.fail((*path, "connects"), c, f"point must be one of {', '.join(pts)} on body '{body}'")
            ends.append((body, point))
        if ends[0][0] == ends[1][0]:
            rd.fail((*path, "connects"), conn, "must join two different bodies")
        if kind == "revolute":
            joints[jname] = Joint(
                jname, kind, ends[0], ends[1], _length(rd, (*path, "bearing_radius_m"), rd.number((*path, "bearing_radius_m"), gt=0.0, unit="m"))
            )
        else:
            axis = rd.vec2((*path, "axis"))
            length = math.hypot(*axis)  # hypot cannot overflow on huge components; only the direction is kept
            if length < 1e-12:
                rd.fail((*path, "axis"), [float(a) for a in axis], "must be a non-zero direction")
            joints[jname] = Joint(jname, kind, ends[0], ends[1], axis=axis / length)
    return MappingProxyType(joints)


def _guide(rd: FieldReader, joints: Mapping[str, Joint]) -> Joint:
    """The one prismatic joint, the slide guide, its second end on the frame."""
    prismatic = [j for j in joints.values() if j.kind == "prismatic"]
    if len(prismatic) != 1:
        rd.fail(("joints",), [j.name for j in prismatic], "needs exactly one prismatic joint: the slide guide")
    guide = prismatic[0]
    if guide.second[0] != FRAME:
        rd.fail(("joints", guide.name, "connects"), guide.second, f"the guide's second end must be on '{FRAME}'")
    return guide


def _read_tree(rd: FieldReader, joints: Mapping[str, Joint]) -> tuple[str, ...] | None:
    """[tree]: the joints to cut, or None (chosen by the model)."""
    rd.table(("tree",), required=False)
    cut = rd.node(("tree", "cut_joints"), required=False)
    if cut is not None and (not isinstance(cut, list) or any(not isinstance(c, str) or c not in joints for c in cut)):
        rd.fail(("tree", "cut_joints"), cut, f"must list joint names among {', '.join(joints)}")
    return tuple(cut) if cut is not None else None


def _read_drive(rd: FieldReader, joints: Mapping[str, Joint]) -> Drive:
    """[drive] without its losses: the driven crank joint and the gear (Eq. 16)."""
    dp = ("drive",)
    d = read_section(rd, dp, DriveSection)
    if d.crank_joint not in joints or joints[d.crank_joint].kind != "revolute":
        rd.fail((*dp, "crank_joint"), d.crank_joint, "must name a revolute joint")
    cj = joints[d.crank_joint]
    if FRAME not in (cj.first[0], cj.second[0]):
        rd.fail((*dp, "crank_joint"), d.crank_joint, f"the driven crank joint must connect a body to '{FRAME}'")
    return Drive(crank_body=cj.first[0] if cj.second[0] == FRAME else cj.second[0], crank_joint=d.crank_joint,
                 angle_offset=math.radians(d.angle_offset_deg), gear_ratio=d.gear_ratio, efficiency=d.efficiency,
                 gear_inertia=d.gear_inertia_kg_m2, motors=d.motors, standstill=d.efficiency_at_standstill)


def _read_motor(rd: FieldReader) -> MotorLimits:
    """[motor]: the limits per motor (SI units)."""
    mp = ("motor",)
    m = read_section(rd, mp, MotorSection)
    motor = MotorLimits(peak_torque=m.peak_torque_Nm, rated_torque=m.rated_torque_Nm,
                        max_speed=m.max_speed_rpm * 2.0 * math.pi / 60.0, load_shares=m.load_shares,
                        load_share_tolerance=m.load_share_tolerance)
    if motor.rated_torque > motor.peak_torque:
        rd.fail((*mp, "rated_torque_Nm"), motor.rated_torque, f"must not exceed peak_torque_Nm = {motor.peak_torque}")
    return motor


def _read_friction(rd: FieldReader) -> Friction:
    """[friction]: Coulomb and viscous coefficients of the revolute joints and the guide (Eqs. 10-12)."""
    f = read_section(rd, ("friction",), FrictionSection)
    return Friction(mu_r=f.revolute_coefficient, c_r=f.revolute_viscous_Nms_per_rad, mu_s=f.guide_coefficient,
                    c_s=f.guide_viscous_Ns_per_m)


def _read_balance(rd: FieldReader, bodies: Mapping[str, Body]) -> Balance:
    """[balance]: the pneumatic balance system (Eqs. 13, 17)."""
    bp = ("balance",)
    b = read_section(rd, bp, BalanceSection)
    balance = Balance(
        cylinders=b.cylinders, piston_area=b.piston_area_m2, tank_volume=b.tank_volume_m3, psi=b.coefficient,
        pressure_offset_mpa=b.pressure_offset_MPa, polytropic_exponent=b.polytropic_exponent, masses=b.masses,
        # the design masses are those of the file as first loaded: with_overrides pins them, so a sampled or
        # calibrated m8 changes gravity and inertia but not the pressure the controller was set to
        design_mass=_design_mass(rd, (*bp, "design_mass_kg"), bodies),
    )
    if balance.cylinders > 0 and balance.psi == 0.0:  # P0 = 0 would divide by zero in Eq. 13
        rd.fail((*bp, "coefficient"), 0.0, "must be > 0 when cylinders > 0; set cylinders = 0 for a press without balance")
    return balance


def _read_numerics(rd: FieldReader) -> NumericsSection:
    """[numerics]: the solvers' settings; absent keys take :class:`NumericsSection`'s defaults. The assembly check's
    step is at least the finest crank step of run_limits.toml (a bound of this run, so read beside the others)."""
    np_ = ("numerics",)
    step_field = _field(NumericsSection, "assembly_check_step_deg")
    n = read_section(rd, np_, NumericsSection, skip=("assembly_check_step_deg",))
    step = rd.number((*np_, "assembly_check_step_deg"), ge=_finest_step(), default=step_field.default, **step_field.metadata["check"])
    return dataclasses.replace(n, assembly_check_step_deg=step)


def _read_assembly(rd: FieldReader, bodies: Mapping[str, Body]) -> tuple[float, Mapping[str, float]]:
    """[assembly]: the crank angle (rad) and the body angle hints (rad) that pick the assembly branch."""
    ap = ("assembly",)
    assembly_crank_angle = rd.angle((*ap, "crank_angle_deg"))
    hint = rd.table((*ap, "body_angles_deg"))
    angles = {}
    for b in hint:
        if b not in bodies:
            rd.fail((*ap, "body_angles_deg", b), b, f"must name a body ({', '.join(bodies)})")
        angles[b] = rd.angle((*ap, "body_angles_deg", b))
    return assembly_crank_angle, MappingProxyType(angles)


def _read_parameters(rd: FieldReader, bodies: Mapping[str, Body]) -> Mapping[str, Parameter]:
    """[parameters]: the sensitivity parameters by name, each with its range ([sensitivity]'s relative one by default)."""
    params = {}
    range_field = _field(SensitivitySection, "default_relative_range")
    for pname, spec in rd.table(("parameters",), required=False).items():
        ppath = ("parameters", pname)
        fpath = rd.string((*ppath, "path"))
        if not _switched_on(rd, ppath):
            rd.delegate(ppath)  # a parameter of a switched-off option: read and checked once the switch is on
            continue
        value = rd.node(tuple(fpath.split(".")), required=False)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            rd.fail((*ppath, "path"), fpath, "must point at a number in this file")
        rng = spec.get("range") if isinstance(spec, Mapping) else None
        if rng is None:
            rel = read_value(rd, ("sensitivity", "default_relative_range"), range_field)
            low, high = value * rel[0], value * rel[1]
            if not low < high:
                rd.fail((*ppath, "range"), [low, high], f"must have low < high; the default relative range of "
                        f"the nominal {value!r} is empty, so give this parameter an explicit range = [low, high]")
        else:
            if not (isinstance(rng, list) and len(rng) == 2):
                rd.fail((*ppath, "range"), rng, "must be [low, high]")
            low, high = rd.number((*ppath, "range", 0)), rd.number((*ppath, "range", 1))
        if not low < high:
            rd.fail((*ppath, "range"), [low, high], "must have low < high")
        if not low <= value <= high:  # calibration starts from the nominal value and samples around it
            rd.fail((*ppath, "range"), [low, high], f"must contain the nominal value {fpath} = {value!r} of parameter "
                    f"'{pname}'; widen the range or correct the value")
        params[pname] = Parameter(pname, fpath, float(value), low, high, rd.string((*ppath, "unit"), default=""),
                                  _target(fpath, bodies))
    _check_loss_ranges(rd, params)
    rd.node(("sensitivity", "default_relative_range"), required=False)  # optional when every range is explicit
    return MappingProxyType(params)


def _field(cls, name: str):
    """The dataclass field ``name`` of the settings class ``cls``."""
    return cls.__dataclass_fields__[name]


LOSS_SWITCH = "drive.losses.enabled"  # the press file's switch of the losses Eq. 16 leaves out


def _read_losses(rd: FieldReader, drive: Drive, motor: MotorLimits) -> Drive:
    """``drive`` with the optional [drive.losses] of the press file (:func:`press_model.motor.eq16`): zero, as in the
    paper's Eq. 16, unless ``enabled = true``; a non-zero loss with the switch off is refused rather than ignored."""
    lp = ("drive", "losses")
    losses = read_section(rd, lp, LossesSection, skip=("coulomb_drag_Nm",))
    load, visc = losses.load_loss_at_rated, losses.viscous_Nms_per_rad
    if visc * motor.max_speed > motor.peak_torque:  # such a drag would stall the motors below their top speed
        rd.fail((*lp, "viscous_Nms_per_rad"), visc, f"must be at most {motor.peak_torque / motor.max_speed:.4g} N m s/rad: more would "
                "take more than the motors' peak torque at their top speed (motor.peak_torque_Nm / max_speed_rpm); check the unit")
    drag_field = _field(LossesSection, "coulomb_drag_Nm")  # its bound is the motors' rated torque, this press's
    drag = rd.number((*lp, "coulomb_drag_Nm"), lt=motor.rated_torque, default=drag_field.default, **drag_field.metadata["check"])
    if not losses.enabled:
        for key, value in (("load_loss_at_rated", load), ("viscous_Nms_per_rad", visc), ("coulomb_drag_Nm", drag)):
            if value != 0.0:
                rd.fail((*lp, key), value, f"is a loss of an option that is off: set {LOSS_SWITCH} = true to model it, or 0")
    return dataclasses.replace(drive, load_loss_at_rated=load, loss_reference_torque=motor.rated_torque, viscous=visc,
                               coulomb_drag=drag)


def _identity(raw: Mapping) -> Mapping:
    """The file's contents as its fingerprint sees them: a switched-off [drive.losses] (the paper's model) and the
    parameters that require it are left out, so a press file keeps the identity it had before the option existed and
    results made on it stay valid. (A switched-off table with non-zero losses is refused by the reader anyway.)
    [drive.electrical] is left out always: the electrical side changes no mechanical result, so calibrations and
    plans made before it was added or changed stay valid for the press."""
    raw = without_electrical(raw)
    losses = raw.get("drive", {}).get("losses") if isinstance(raw.get("drive"), Mapping) else None
    if not isinstance(losses, Mapping) or losses.get("enabled", False) is not False:
        return raw
    out = copy_tree(dict(raw))
    del out["drive"]["losses"]
    params = out.get("parameters")
    if isinstance(params, Mapping):
        out["parameters"] = {k: v for k, v in params.items() if not (isinstance(v, Mapping) and v.get("requires") == LOSS_SWITCH)}
    return out


def without_electrical(raw: Mapping) -> Mapping:
    """A press file's content ``raw`` without [drive.electrical] (a copy when it has one): what every mechanical result
    depends on (the fingerprint, the disk caches' key); the electrical side changes none."""
    drive = raw.get("drive")
    if not isinstance(drive, Mapping) or "electrical" not in drive:
        return raw
    out = dict(raw)
    out["drive"] = {k: v for k, v in drive.items() if k != "electrical"}
    return out


def _switched_on(rd: FieldReader, ppath: tuple) -> bool:
    """False for a parameter whose ``requires`` names a press-file switch that is off (it is then no parameter)."""
    switch = rd.node((*ppath, "requires"), required=False)
    if switch is None:
        return True
    if switch != LOSS_SWITCH:
        rd.fail((*ppath, "requires"), switch, f"must be '{LOSS_SWITCH}' (the only switch a parameter can depend on)")
    return rd.flag(tuple(LOSS_SWITCH.split(".")), default=False)


def _check_loss_ranges(rd: FieldReader, params: Mapping[str, "Parameter"]) -> None:
    """A loss parameter's range must stay >= 0: a negative loss would make the drive a power source."""
    for p in params.values():
        if p.target.field in ("load_loss", "viscous", "coulomb_drag") and p.low < 0.0:
            rd.fail(("parameters", p.name, "range"), [p.low, p.high], "must not go below 0 (a loss cannot be negative); "
                    "start the range at 0")


def _check_topology(rd: FieldReader, bodies: Mapping, joints: Mapping) -> None:
    """Every body joined to something, and one degree of freedom in all."""
    used = {j.first[0] for j in joints.values()} | {j.second[0] for j in joints.values()}
    for b in bodies:
        if b not in used:
            rd.fail(("bodies", b), b, "is joined to nothing; add a joint that connects it")
    n_cut = len(joints) - len(bodies)
    if n_cut < 0:
        rd.fail(("joints",), list(joints), "too few joints to connect every body to the frame")
    dof = len(bodies) - 2 * n_cut  # planar: one tree coordinate per body, two equations per cut joint
    if dof != 1:
        rd.fail(
            ("joints",),
            list(joints),
            f"the linkage has {dof} degrees of freedom; a press linkage driven by one crank needs exactly 1",
        )
