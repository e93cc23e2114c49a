"""``handrig servos scan`` without ``--bauds`` looks at every baud the X series supports:
the live scans of test_servos_command.py name their bauds (~2 s on the bus instead of
~10 s, most of it the broadcast ping's wait at 9600 bps), so the default is checked here."""

from __future__ import annotations

import inspect

from handrig.cli import build_parser
from handrig.devices.servo import dynamixel_bringup as bringup
from handrig.devices.servo.models import BAUD_RATES


def test_scan_without_bauds_tries_every_baud_of_the_x_series() -> None:
    args = build_parser("servos").parse_args(["servos", "scan", "--port", "/dev/null"])
    assert args.bauds == list(BAUD_RATES)
    assert {9600, 57600, 115200, 1_000_000, 2_000_000, 3_000_000, 4_000_000} == set(BAUD_RATES)
    # the driver's own default is the same list
    assert inspect.signature(bringup.scan).parameters["bauds"].default == BAUD_RATES


def test_bauds_names_a_subset_in_the_order_given() -> None:
    args = build_parser("servos").parse_args(
        ["servos", "scan", "--port", "/dev/null", "--bauds", "1000000,57600"])
    assert args.bauds == [1_000_000, 57600]
