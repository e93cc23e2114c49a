"""Each model's control table against its ROBOTIS e-manual page, and the driver's own
register table (written apart, in handrig/devices/servo) against every model's."""

from __future__ import annotations

import pytest

from firmware_protocol import dxl_tables as t
from firmware_protocol.dxl_tables import MODELS, Access, Reg
from handrig.devices.servo import registers as driver

# Values read off each model's e-manual page (control tables of the EEPROM and RAM
# areas): initial value and range of the items that differ between models. Secondary
# ID: initial 255, written 253..255 it is off (e-manual, Secondary ID), so 0..255.
# (model, page, model number, Current Limit default/max (None: no such item),
#  Velocity Limit default/max, Max Voltage default, Min Voltage default, voltage range,
#  Temperature Limit, Moving Threshold, Baud Rate max index, Position P/D gain defaults,
#  Shutdown default, operating modes)
EMANUAL = [
    ("XL330-M288", "https://emanual.robotis.com/docs/en/dxl/x/xl330-m288/", 1200, 1750, 445,
     2047, 70, 35, (31, 70), 70, 10, 6, 400, 0, 53, (0, 1, 3, 4, 5, 16)),
    ("XL330-M077", "https://emanual.robotis.com/docs/en/dxl/x/xl330-m077/", 1190, 1750, 1620,
     2047, 70, 35, (31, 70), 70, 10, 6, 400, 0, 53, (0, 1, 3, 4, 5, 16)),
    ("XC330-M288", "https://emanual.robotis.com/docs/en/dxl/x/xc330-m288/", 1240, 2352, 350,
     2047, 70, 35, (31, 70), 70, 10, 6, 1100, 500, 52, (0, 1, 3, 4, 5, 16)),
    ("XC330-T288", "https://emanual.robotis.com/docs/en/dxl/x/xc330-t288/", 1220, 910, 320,
     2047, 140, 55, (55, 140), 70, 10, 6, 900, 0, 52, (0, 1, 3, 4, 5, 16)),
    ("XM430-W350", "https://emanual.robotis.com/docs/en/dxl/x/xm430-w350/", 1020, 1193, 350,
     1023, 160, 95, (95, 160), 80, 10, 7, 800, 0, 52, (0, 1, 3, 4, 5, 16)),
    ("XC430-W150", "https://emanual.robotis.com/docs/en/dxl/x/xc430-w150/", 1070, None, 460,
     1023, 160, 60, (60, 160), 80, 20, 7, 460, 0, 52, (1, 3, 4, 16)),
    ("XC430-T240BB", "https://emanual.robotis.com/docs/en/dxl/x/xc430-t240bb/", 1080, None,
     306, 1023, 160, 60, (60, 160), 80, 10, 7, 700, 0, 52, (1, 3, 4, 16)),
]


@pytest.mark.parametrize("row", EMANUAL, ids=lambda r: r[0])
def test_model_table_matches_its_emanual_page(row: tuple) -> None:  # type: ignore[type-arg]
    (name, page, number, current, velocity, velocity_max, max_v, min_v, v_range, temp,
     moving, baud_max, p_gain, d_gain, shutdown, modes) = row
    m = MODELS[name]
    assert m.emanual == page
    d = m.defaults
    assert m.model_number == number == d[Reg.MODEL_NUMBER]
    if current is None:
        assert not m.has_current
        assert Reg.CURRENT_LIMIT not in m.table and Reg.GOAL_CURRENT not in m.table
    else:
        assert d[Reg.CURRENT_LIMIT] == current
        lim = m.table[Reg.CURRENT_LIMIT]
        assert (lim.min_value, lim.max_value) == (0, current)
        goal = m.table[Reg.GOAL_CURRENT]
        assert (goal.min_value, goal.max_value) == (-current, current)
    assert d[Reg.VELOCITY_LIMIT] == velocity
    assert m.table[Reg.VELOCITY_LIMIT].max_value == velocity_max
    assert (d[Reg.MAX_VOLTAGE_LIMIT], d[Reg.MIN_VOLTAGE_LIMIT]) == (max_v, min_v)
    for reg in (Reg.MAX_VOLTAGE_LIMIT, Reg.MIN_VOLTAGE_LIMIT):
        assert (m.table[reg].min_value, m.table[reg].max_value) == v_range
    assert d[Reg.TEMPERATURE_LIMIT] == temp
    assert d[Reg.MOVING_THRESHOLD] == moving
    assert m.table[Reg.BAUD_RATE].max_value == baud_max
    assert (d[Reg.POSITION_P_GAIN], d[Reg.POSITION_D_GAIN]) == (p_gain, d_gain)
    assert d[Reg.SHUTDOWN] == shutdown
    assert m.operating_modes == modes
    # the layout is shared: every item a model has sits at the X-series address
    for reg, item in m.table.items():
        assert item.address == int(reg) and item.size == t.X_SERIES_TABLE[reg].size


def test_every_default_fits_its_own_range() -> None:
    for m in MODELS.values():
        for reg, value in m.defaults.items():
            item = m.table[reg]
            if item.min_value is not None and item.max_value is not None:
                assert item.min_value <= value <= item.max_value, (m.name, reg.name, value)


@pytest.mark.parametrize("model", list(MODELS))
@pytest.mark.parametrize("reg", list(driver.Reg), ids=lambda r: r.name)
def test_the_drivers_table_agrees_with_every_model(model: str, reg: driver.Reg) -> None:
    m = MODELS[model]
    item = m.table.get(Reg[reg.name])
    if item is None:  # an item the model lacks (XC430: no current sensing)
        assert not m.has_current and reg.name in ("CURRENT_LIMIT", "GOAL_CURRENT")
        return
    assert (reg.address, reg.size, reg.signed) == (item.address, item.size, item.signed)
    assert reg.writable == (item.access is Access.RW)


def test_the_drivers_current_units_agree_where_it_knows_the_model() -> None:
    for number, unit in driver.CURRENT_MA_PER_UNIT.items():
        assert t.MODEL_BY_NUMBER[number].current_unit_ma == unit
