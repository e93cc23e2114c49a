"""What a glove's status flags mean, in words (``firmware_protocol/SPEC.md``, "Flags").

Pure functions: the flags byte of a frame (without bit 0) to names and messages,
and which raw channels a "sensor pinned" flag points at. Used by
:class:`~handrig.devices.glove.SerialGlove` (an event each time the flags change) and by
``handrig glove monitor``.
"""

from __future__ import annotations

from collections.abc import Sequence

from firmware_protocol.glove import (
    FLAG_IMU_ABSENT,
    FLAG_IMU_UNCALIBRATED,
    FLAG_OVERRUN,
    FLAG_SENSOR_RAIL,
    FLAG_WATCHDOG_RESET,
)

STATUS_NAMES: dict[int, str] = {
    FLAG_IMU_ABSENT: "imu-absent",
    FLAG_IMU_UNCALIBRATED: "imu-uncalibrated",
    FLAG_SENSOR_RAIL: "sensor-pinned",
    FLAG_WATCHDOG_RESET: "watchdog-reset",
    FLAG_OVERRUN: "overrun",
}
"""Status bit -> the short name the monitor and the summary print."""

RAIL_MARGIN = 16
"""Counts from 0 or full scale within which a channel counts as pinned (the firmware's
``GC_RAIL_LOW``)."""
FULL_SCALES = (1023, 4095, 65535)
"""Full scales a pinned-high channel may sit at: 10-bit, 12-bit and 16-bit readings."""


def status_names(status: int) -> list[str]:
    """Names of the status bits set in ``status``, lowest bit first."""
    return [name for bit, name in STATUS_NAMES.items() if status & bit]


def pinned_channels(raw: Sequence[float]) -> list[tuple[int, str]]:
    """(index, "0" or "full scale") of each channel reading at a rail."""
    out: list[tuple[int, str]] = []
    for i, v in enumerate(raw):
        if v <= RAIL_MARGIN:
            out.append((i, "0"))
        elif any(full - RAIL_MARGIN <= v <= full for full in FULL_SCALES):
            out.append((i, "full scale"))
    return out


def channel_label(index: int, names: Sequence[str]) -> str:
    """``"channel 4 (riPinkyMCPy)"``, or ``"channel 4"`` when it has no name."""
    name = names[index] if index < len(names) and names[index] else ""
    return f"channel {index} ({name})" if name else f"channel {index}"


def pinned_message(raw: Sequence[float], names: Sequence[str]) -> str:
    """Which sensors a "sensor pinned" flag means, by name, with the fix."""
    found = pinned_channels(raw)
    if not found:
        return "a sensor is pinned at 0 or full scale (it has just come back)"
    what = ", ".join(f"{channel_label(i, names)} at {rail} ({raw[i]:.0f})" for i, rail in found)
    return (f"sensor pinned: {what}; check its wire and divider resistor "
            "(firmware/README.md, 'Wiring')")


def change_messages(old: int, new: int, raw: Sequence[float],
                    names: Sequence[str] = ()) -> list[str]:
    """What changed between two status bytes, one message per bit that changed."""
    out: list[str] = []
    went = new & ~old
    back = old & ~new
    if went & FLAG_IMU_ABSENT:
        out.append("glove reports its IMU lost (no answer on I2C): the forearm pose is the "
                   "[forearm] of the glove config until it is back")
    if back & FLAG_IMU_ABSENT:
        out.append("glove reports its IMU back")
    if went & FLAG_IMU_UNCALIBRATED:
        out.append("glove reports its IMU not calibrated yet (move the forearm in a figure "
                   "of eight; inclination is usable meanwhile)")
    if back & FLAG_IMU_UNCALIBRATED:
        out.append("glove reports its IMU calibrated")
    if went & FLAG_SENSOR_RAIL:
        out.append("glove reports a " + pinned_message(raw, names))
    if back & FLAG_SENSOR_RAIL:
        out.append("glove reports no sensor pinned any more")
    if went & FLAG_WATCHDOG_RESET:
        out.append("glove reports its firmware was restarted by the watchdog (it hung); "
                   "if this repeats, check the IMU wiring and the power supply")
    if went & FLAG_OVERRUN:
        out.append("glove reports a missed sample tick (its loop ran late)")
    return out
