"""The drive's electrical side as the press file describes it ([drive.electrical], off where absent): the motors'
copper and iron losses, the motor inverters, the common DC link, the supply (a regenerative infeed, or a diode
rectifier with a braking resistor) and an optional storage (a capacitor bank on the DC link).

Plain frozen settings, one dataclass a sub-table: every field has a default, and its metadata the unit, the bounds
the reader checks and the reason for the default. The defaults are the reference press's class of drive (two
~2.6 MW torque motors, 25,000 N m peak, 13,500 N m rated, 1,000 rpm, a 690 V supply); the reference press file
states them again as its chosen values. What the settings do is in :mod:`press_model.power_flow`.
"""
from __future__ import annotations

from dataclasses import dataclass

from .readers import FieldReader
from .settings_fields import read_section, setting

SECTION = ("drive", "electrical")
SUPPLY_KINDS = ("regenerative", "diode")

# Upper bounds of the values a press file sets, each far beyond any press drive, so that a typo (an exponent, another
# unit) is refused instead of computed: torque_constant_Nm_per_A = 1e308 left no copper loss at all (copper_J = 0.0),
# a storage of energy_J = 1e300 was planned with.
MAX_POWER_W = 1.0e9  # W: a power station's output; the reference's two motors peak at 2.6 MW each
MAX_ENERGY_J = 1.0e9  # J: a supercapacitor bank holds ~20 kJ/kg, so 1 GJ is 50 t of cells; the reference's bank: 2 MJ
MAX_VOLTAGE_V = 20000.0  # V: medium-voltage drives run at 3.3-13.8 kV; no press's DC link is above 20 kV (the reference's 1,050 V)
MAX_CAPACITANCE_F = 100.0  # F on the DC link: 3,300 times the reference's 30 mF, 55 MJ at 1,050 V
MAX_TORQUE_CONSTANT = 1000.0  # N m/A: a phase's back-EMF is k_t omega / 3, so at 100 rpm it would be 3.5 kV, five times a 690 V supply's
MAX_WINDING_OHM = 100.0  # ohm: 3 I^2 R at 10 A (a 5 kW motor's current) would burn 30 kW, six times its power; the reference's 0.009
MAX_BRAKE_OHM = 1000.0  # ohm: at 1,150 V a 1,000-ohm resistor takes 1.3 kW, no brake for a press (the reference's 0.25 ohm takes 5.3 MW)


def _f(default, unit: str, reason: str, **bounds):
    """A settings field (:func:`press_model.settings_fields.setting`); a number's unit also names it in the reader's messages."""
    return setting(default, unit, reason, **({"unit": unit} if isinstance(default, float) else {}), **bounds)


@dataclass(frozen=True)
class MotorWinding:
    """[drive.electrical.motor]: the loss of each motor between its terminals and its shaft."""

    torque_constant_Nm_per_A: float = _f(10.0, "N m per A (RMS phase current)", "a 690 V torque motor of 1.4 MW rated (13,500 N m at "
                                        "1,000 rpm) draws ~1,350 A at its rated torque", gt=0.0,
                                        le=MAX_TORQUE_CONSTANT)
    winding_resistance_ohm: float = _f(0.009, "ohm per phase, warm", "3 I^2 R at the rated torque is 49 kW, 3.5 % of the rated power: "
                                      "the copper loss of MW-class torque motors", ge=0.0, le=MAX_WINDING_OHM)
    iron_loss_at_max_speed_W: float = _f(15000.0, "W per motor at max_speed_rpm", "about 1 % of the rated power at top speed: "
                                        "core (hysteresis and eddy-current) and windage losses", ge=0.0, le=MAX_POWER_W)
    iron_loss_hysteresis_share: float = _f(0.5, "1", "share of the iron loss growing with speed (hysteresis); the rest grows with its "
                                          "square (eddy currents): an even split for laminated steel at these frequencies", ge=0.0, le=1.0)


@dataclass(frozen=True)
class Inverter:
    """[drive.electrical.inverter]: each motor's inverter between the DC link and the motor."""

    efficiency: float = _f(0.98, "1, either direction", "IGBT inverters of this size lose 1.5-2.5 % at load", gt=0.0, le=1.0)


@dataclass(frozen=True)
class DcLink:
    """[drive.electrical.dc_link]: the common DC link of both motors' inverters."""

    capacitance_F: float = _f(0.03, "F, all inverters and the infeed together", "~5 mF per MW of drive power, usual for 690 V "
                              "converters", gt=0.0, le=MAX_CAPACITANCE_F)
    nominal_voltage_V: float = _f(1050.0, "V", "what a regenerative infeed on a 690 V grid holds the link at", gt=0.0,
                                le=MAX_VOLTAGE_V)
    min_voltage_V: float = _f(900.0, "V", "undervoltage trip: below the 690 V grid's rectified 930 V the infeed cannot "
                              "hold the link", ge=0.0, le=MAX_VOLTAGE_V)
    max_voltage_V: float = _f(1200.0, "V", "overvoltage trip of 690 V-class inverters (1,200 V IGBTs are rated 1,700 V)", gt=0.0,
                              le=MAX_VOLTAGE_V)


@dataclass(frozen=True)
class Supply:
    """[drive.electrical.supply]: what connects the DC link to the grid."""

    kind: str = _f("regenerative", "regenerative or diode", "presses of this size have a regenerative (active) infeed that "
                   "returns braking energy to the grid", choices=SUPPLY_KINDS)
    motoring_limit_W: float = _f(5.5e6, "W drawn from the grid at most", "sized for both motors at peak torque and top speed "
                                 "(2 x 2.62 MW) with their losses: without a limit of the plan the press never waits on it", gt=0.0,
                                 le=MAX_POWER_W)
    regenerating_limit_W: float = _f(5.5e6, "W returned to the grid at most (a diode rectifier returns none)", "the regenerative "
                                     "infeed is symmetrical", ge=0.0, le=MAX_POWER_W)
    efficiency: float = _f(0.98, "1, either direction", "an active front end with its line filter loses ~2 %", gt=0.0, le=1.0)


@dataclass(frozen=True)
class BrakeResistor:
    """[drive.electrical.brake_resistor]: a chopper and resistor that burn what the link cannot hold."""

    enabled: bool = _f(True, "true or false", "every press drive has one to stop safely when the supply cannot take the braking energy")
    resistance_ohm: float = _f(0.25, "ohm", "takes 5.3 MW at 1,150 V: both motors braking at peak power", gt=0.0,
                            le=MAX_BRAKE_OHM)
    chopper_voltage_V: float = _f(1150.0, "V", "the chopper switches the resistor in above this, below the 1,200 V trip",
                               gt=0.0, le=MAX_VOLTAGE_V)


@dataclass(frozen=True)
class Storage:
    """[drive.electrical.storage]: a capacitor bank on the DC link through its DC/DC converter (off by default)."""

    enabled: bool = _f(False, "true or false", "the reference press has none; turn it on to see what one buys")
    energy_J: float = _f(2.0e6, "J usable between the bank's voltage limits", "a bank of the size press builders fit to a "
                         "2,500 t servo press (a few MJ): about twice one door-panel stroke's braking energy", gt=0.0,
                         le=MAX_ENERGY_J)
    power_limit_W: float = _f(3.0e6, "W either way at the DC link", "the DC/DC converter's rating, about one motor's peak power", gt=0.0,
                                 le=MAX_POWER_W)
    efficiency: float = _f(0.95, "1, each way (converter and the cells' resistance)", "supercapacitor banks with their converter "
                           "return ~90 % round trip", gt=0.0, le=1.0)


@dataclass(frozen=True)
class Electrical:
    """[drive.electrical]: the drive's electrical side (:mod:`press_model.power_flow` turns torque and speed into power flows).

    ``max_speed`` (rad/s at the motor shaft) is the [motor] top speed the iron loss refers to, set by the reader."""

    motor: MotorWinding = MotorWinding()
    inverter: Inverter = Inverter()
    dc_link: DcLink = DcLink()
    supply: Supply = Supply()
    brake_resistor: BrakeResistor = BrakeResistor()
    storage: Storage = Storage()
    max_speed: float = _f(0.0, "rad/s at the motor shaft", "the [motor] top speed, set by the reader from max_speed_rpm", ge=0.0)


SUBTABLES = {"motor": MotorWinding, "inverter": Inverter, "dc_link": DcLink, "supply": Supply, "brake_resistor": BrakeResistor,
             "storage": Storage}


def read_electrical(rd: FieldReader, max_speed: float) -> Electrical | None:
    """The press file's [drive.electrical] (None where it is absent or ``enabled = false``: no electrical quantity is
    computed); ``max_speed`` the motors' top speed, rad/s. Refuses a DC-link window that does not hold its nominal
    voltage or a chopper voltage outside it."""
    if rd.node(SECTION, required=False) is None:
        return None
    rd.table(SECTION)
    if not rd.flag((*SECTION, "enabled"), default=True):
        rd.delegate(SECTION)
        return None
    parts = {name: read_section(rd, (*SECTION, name), cls) for name, cls in SUBTABLES.items()}
    el = Electrical(**parts, max_speed=max_speed)
    link, chop = el.dc_link, el.brake_resistor
    if not link.min_voltage_V < link.nominal_voltage_V < link.max_voltage_V:
        rd.fail((*SECTION, "dc_link", "nominal_voltage_V"), link.nominal_voltage_V,
                f"must lie strictly between min_voltage_V = {link.min_voltage_V:g} and max_voltage_V = {link.max_voltage_V:g}")
    if chop.enabled and not link.nominal_voltage_V < chop.chopper_voltage_V <= link.max_voltage_V:
        rd.fail((*SECTION, "brake_resistor", "chopper_voltage_V"), chop.chopper_voltage_V,
                f"must lie above dc_link.nominal_voltage_V = {link.nominal_voltage_V:g} and at most max_voltage_V = {link.max_voltage_V:g}")
    return el
