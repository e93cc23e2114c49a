"""The two emulators of the outside latency measurement, each in a process of its own.

``python -m bench.latency_emulators glove REC.csv --rate HZ --log FILE`` streams a
recording (looping) and logs ``send_time_s seq sample_index`` per frame;
``python -m bench.latency_emulators bus --rig RIG.toml --log FILE`` runs the emulated
bus (kinematic servos, wire timing) and logs ``receipt_time_s goal_ticks...`` (by servo
order in the packet) per Sync Write of Goal Position. Both times are CLOCK_MONOTONIC,
so one process's stamps compare with the other's. Each prints ``port: PATH`` first
and runs until SIGTERM or SIGINT; the logs are written line by line as they happen.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from types import FrameType

from handrig.realtime import apply_cpus_from_env

GOAL_POSITION = 116  # X-series Goal Position address (REFERENCE.md section 2)


def _wait_for_signal() -> None:
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, on_signal)
    while not stop.wait(0.25):
        pass


def _glove(args: argparse.Namespace) -> int:
    from handrig.devices.glove_recording import read_glove_recording
    from sim.glove_emulator import GloveEmulator

    rec = read_glove_recording(args.recording)
    with open(args.log, "w", buffering=1, encoding="ascii") as log:
        def on_send(t_s: float, seq: int, index: int) -> None:
            log.write(f"{t_s:.7f} {seq} {index}\n")

        with GloveEmulator(rec, "frames", rate_hz=args.rate, loop=True,
                           on_send=on_send) as emu:
            print(f"port: {emu.port_path}", flush=True)
            _wait_for_signal()
            emu.on_send = None
    return 0


def _bus(args: argparse.Namespace) -> int:
    from handrig.app import simulator
    from handrig.config.rig import hand_rig, load_rig_config
    from handrig.config.rig_files import SHIPPED_RIG

    rig = load_rig_config(args.rig or SHIPPED_RIG)
    if args.hand:  # one hand's servos of a two-hand rig, on that hand's bus
        rig = hand_rig(rig, args.hand)
    # kinematic servos: no physics thread in this process to hold up the receipt stamps
    bus, _ = simulator.servo_bus(rig, puppet=False, wire_timing=True)
    with open(args.log, "w", buffering=1, encoding="ascii") as log:
        def on_sync_write(t_s: float, address: int, items: list[tuple[int, bytes]]) -> None:
            if address != GOAL_POSITION:
                return
            goals = " ".join(str(int.from_bytes(d[:4], "little", signed=True))
                             for _, d in items)
            log.write(f"{t_s:.7f} {goals}\n")

        bus.on_sync_write = on_sync_write
        bus.start()
        try:
            print(f"port: {bus.port_path}", flush=True)
            _wait_for_signal()
        finally:
            bus.on_sync_write = None
            bus.stop()
    return 0


def main(argv: list[str] | None = None) -> int:
    apply_cpus_from_env()
    p = argparse.ArgumentParser(prog="python -m bench.latency_emulators")
    sub = p.add_subparsers(dest="which", required=True)
    g = sub.add_parser("glove")
    g.add_argument("recording")
    g.add_argument("--rate", type=float, required=True)
    g.add_argument("--log", required=True)
    b = sub.add_parser("bus")
    b.add_argument("--rig", required=True)
    b.add_argument("--log", required=True)
    b.add_argument("--hand", choices=("ri", "le"), default=None)
    args = p.parse_args(argv)
    return _glove(args) if args.which == "glove" else _bus(args)


if __name__ == "__main__":
    sys.exit(main())
