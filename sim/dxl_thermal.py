"""The emulated servo's heat: a first-order thermal model per X-series model.

The figures come from each model's datasheet (ROBOTIS e-manual Specifications: stall
current at the nominal voltage, standby current, case size, weight) and three stated
assumptions; docs/hardware.md ("Heat") tabulates what they give and why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_protocol.dynamixel import MODELS

# Thermal model, first order, one lump per servo (the control table's Present
# Temperature is the servo's internal temperature):
#   dT/dt = (T_ambient + R_th x P - T) / tau,   P = I^2 R + V x I_standby
# with I the motor current, R = V_nominal / I_stall (winding plus driver, from the
# datasheet's stall figures) and I_standby the datasheet's Standby Current. R_th and
# tau are not in any datasheet; they are derived from the case's size and weight
# (ROBOTIS e-manual, each model's Specifications) under three stated assumptions:
# - free air around the case: convection plus radiation ~12 W/(m^2 K) (natural
#   convection of a small body ~6, radiation at emissivity ~0.9 near 40 C ~6);
# - 5 K/W between the motor/driver and the case surface (the sensor is inside);
# - ~900 J/(kg K) for the whole servo (plastic ~1500, aluminium ~900, copper and
#   steel ~400-500).
# So an X330 (20 x 34 x 26 mm, 18-23 g) has R_th ~25 K/W and tau ~7-9 min; an X430
# (28.5 x 46.5 x 34 mm, 65-82 g) ~16 K/W and tau ~15-19 min. Checked against ROBOTIS's
# rule that a servo runs continuously at about 20 % of its stall torque (robotis.us
# blog, "Torque Ratings", 2020): there every model settles 10-25 K above ambient,
# well under its Temperature Limit; at 40-45 % of stall an X330's steady state
# reaches its limit; stalled, an XL330 reaches 70 C in under two minutes.
# Not modelled: the winding's own faster rise, copper's resistance rising ~0.4 %/K,
# a case mounted on metal (cooler) or in a closed puppet (hotter).
AMBIENT_TEMPERATURE_C = 30  # a stage under lights, not a lab at 25 C (assumed)
HEAT_TRANSFER_W_M2K = 12.0
INTERNAL_K_PER_W = 5.0
SPECIFIC_HEAT_J_KGK = 900.0


@dataclass(frozen=True)
class ThermalSpec:
    """A model's thermal figures: datasheet facts (size, weight, standby current) and
    what the assumptions above derive from them."""

    size_mm: tuple[float, float, float]  # W x H x D, e-manual Specifications
    weight_g: float  # e-manual Specifications
    standby_current_a: float  # e-manual Specifications, "Standby Current"

    @property
    def surface_m2(self) -> float:
        w, h, d = (x / 1000.0 for x in self.size_mm)
        return 2.0 * (w * h + w * d + h * d)

    @property
    def resistance_k_per_w(self) -> float:
        """Internal temperature rise per watt dissipated, K/W."""
        return 1.0 / (HEAT_TRANSFER_W_M2K * self.surface_m2) + INTERNAL_K_PER_W

    def temperature_after(self, temperature_c: float, volts: float, current_ma: float,
                          stall_current_a: float, dt_s: float) -> float:
        """The temperature ``dt_s`` later at a motor current ``current_ma`` (I^2 R, R from
        the stall figures) plus the standby draw, cooling toward ambient."""
        resistance = volts / stall_current_a if volts else 1.0
        amps = current_ma / 1000.0
        power_w = amps * amps * resistance + volts * self.standby_current_a
        target = AMBIENT_TEMPERATURE_C + power_w * self.resistance_k_per_w
        alpha = 1.0 - math.exp(-dt_s / self.time_constant_s)  # exact for a constant P
        return temperature_c + (target - temperature_c) * alpha

    @property
    def time_constant_s(self) -> float:
        """R_th x heat capacity: how fast the temperature follows a change of load."""
        return self.resistance_k_per_w * self.weight_g / 1000.0 * SPECIFIC_HEAT_J_KGK


_X330_MM = (20.0, 34.0, 26.0)
_X430_MM = (28.5, 46.5, 34.0)
# Per model (e-manual Specifications of each; XL330 and XC330 list 17 mA standby,
# XC430-W150 and XC430-T240BB 46 mA, XM430-W350 40 mA).
THERMAL: dict[str, ThermalSpec] = {
    "XL330-M288": ThermalSpec(_X330_MM, 18.0, 0.017),
    "XL330-M077": ThermalSpec(_X330_MM, 18.0, 0.017),
    "XC330-M288": ThermalSpec(_X330_MM, 23.0, 0.017),
    "XC330-T288": ThermalSpec(_X330_MM, 23.0, 0.017),
    "XM430-W350": ThermalSpec(_X430_MM, 82.0, 0.040),
    "XC430-W150": ThermalSpec(_X430_MM, 65.0, 0.046),
    "XC430-T240BB": ThermalSpec(_X430_MM, 65.0, 0.046),
}


def idle_temperature_c(model: str, volts: float) -> float:
    """Where a powered servo's temperature settles with no motor current."""
    spec = THERMAL[model]
    return AMBIENT_TEMPERATURE_C + volts * spec.standby_current_a * spec.resistance_k_per_w


def steady_temperature_c(model: str, volts: float, current_a: float) -> float:
    """Where the temperature settles at a constant motor current ``current_a``."""
    info, spec = MODELS[model], THERMAL[model]
    power_w = current_a * current_a * volts / info.stall_current_a
    return idle_temperature_c(model, volts) + power_w * spec.resistance_k_per_w
