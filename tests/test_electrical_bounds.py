"""Every number of a press file's [drive.electrical] has an upper bound far beyond any press drive (its reason beside it
in press_model/electrical.py): a typo is refused naming the field and the value instead of computed with
(torque_constant_Nm_per_A = 1e308 gave copper_J = 0.0; storage energy_J = 1e300 was planned with)."""
from __future__ import annotations

import copy
import dataclasses

import pytest

from press_io.errors import PressDataError
from press_model.electrical import SUBTABLES
from press_model.press_data import read_press

NUMBERS = [(name, f.name) for name, cls in SUBTABLES.items() for f in dataclasses.fields(cls) if type(f.default) is float]


def test_every_electrical_number_has_an_upper_bound():
    unbounded = [f"{t}.{k}" for t, k in NUMBERS
                 if not {"le", "lt"} & set(next(f for f in dataclasses.fields(SUBTABLES[t]) if f.name == k).metadata["check"])]
    assert unbounded == []


@pytest.mark.parametrize("table, key", NUMBERS)
def test_an_absurd_electrical_value_is_refused_naming_the_field(press, table, key):
    raw = copy.deepcopy(press.raw())
    raw["drive"]["electrical"].setdefault(table, {})[key] = 1e308
    with pytest.raises(PressDataError) as info:
        read_press(raw, "test")
    msg = str(info.value)
    assert f"drive.electrical.{table}.{key} = 1e+308 is not valid: must be" in msg and "<=" in msg, msg


def test_the_shipped_values_lie_well_inside_the_bounds(press):
    for table, key in NUMBERS:
        f = next(f for f in dataclasses.fields(SUBTABLES[table]) if f.name == key)
        bound = f.metadata["check"]["le"]
        assert getattr(getattr(press.electrical, table), key) <= 0.1 * bound or bound == 1.0, (table, key)
