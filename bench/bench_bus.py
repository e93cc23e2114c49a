"""Servo bus cycle (goal Sync Write + Fast Sync Read) against the emulator, vs the wire limit.

Runs ``handrig bench bus`` at 4 Mbps and 1 Mbps with 20 servos, each side by side
with the plain dynamixel-sdk way.
"""

from __future__ import annotations

from handrig.cli.bench_bus import bench


def main() -> None:
    for baud in (4_000_000, 1_000_000):
        bench(20, baud, seconds=2.0)
        print()


if __name__ == "__main__":
    main()
