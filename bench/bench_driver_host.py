"""The driver's own host time per cycle: write_goals_deg + read_state on an instant port.

A transport that answers every Fast Sync Read at once with a reply built by the
emulator's codec (no pty, no emulator thread, no wire time) leaves only the
driver's work: the goal Sync Write built and written, the request sent, the
state allocated, the reply checked and decoded. Back to back (warm caches) and
after a 2 ms sleep each (cold caches, as in the realtime loop).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from firmware_protocol import dynamixel as dx
from handrig.clock import MonotonicClock
from handrig.config.rig import load_rig_config
from handrig.config.rig_files import SHIPPED_RIG
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.transport import Transport


class InstantTransport(Transport):
    """Answers each Fast Sync Read request (the end of a write) at once."""

    def __init__(self, n_servos: int, clock: MonotonicClock) -> None:
        super().__init__("instant", 4_000_000, clock)
        self._request_len = 14 + n_servos
        self._replies: dict[bytes, bytes] = {}
        self._pending = b""

    @property
    def is_open(self) -> bool:
        return True

    def open(self) -> None:
        pass

    def close(self) -> None:
        pass

    def write(self, data: bytes | memoryview) -> None:
        data = bytes(data)
        self.bytes_written += len(data)
        request = data[-self._request_len :]
        if len(request) == self._request_len and request[7] == dx.Instruction.FAST_SYNC_READ:
            reply = self._replies.get(request)
            if reply is None:
                _, _, ids = dx.split_sync_read(dx.parse_instruction(request).params)
                reply = dx.build_fast_read_reply(
                    [(i, 0, (2048 + i).to_bytes(4, "little")) for i in ids])
                self._replies[request] = reply
            self._pending = reply

    def _receive(self, deadline_s: float, spin_from_s: float | None,
                 spin_until_s: float) -> bytes:
        out, self._pending = self._pending, b""
        return out

    def _take_pending(self) -> bytes:
        out, self._pending = self._pending, b""
        return out


def main(repeats: int = 5) -> None:
    rig = load_rig_config(SHIPPED_RIG)
    n = len(rig.servos)
    rig = dataclasses.replace(rig, bus=dataclasses.replace(rig.bus, baud=4_000_000))
    clock = MonotonicClock()
    bus = DynamixelBus("instant", rig, clock=clock, read_fields="position", temperature_every=0,
                       transport=InstantTransport(n, clock))
    goals = [np.linspace(-10.0, 10.0, n) + 0.01 * k for k in range(64)]

    def cycle(k: int) -> None:
        bus.write_goals_deg(goals[k & 63])
        if bus.read_state().stale.any():
            raise RuntimeError("the instant transport's reply was not taken")

    for k in range(2000):
        cycle(k)
    warm, cold = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for k in range(5000):
            cycle(k)
        warm.append((time.perf_counter() - t0) / 5000)
        after_sleep = []
        for k in range(300):
            time.sleep(0.002)
            t0 = time.perf_counter()
            cycle(k)
            after_sleep.append(time.perf_counter() - t0)
        cold.append(float(np.median(after_sleep)))
    print(f"driver host time per cycle, {n} servos, instant replies (best of {repeats}): "
          f"{min(warm) * 1e6:.1f} us back to back, {min(cold) * 1e6:.1f} us median after a "
          f"2 ms sleep; whole reads {bus.stats.reads}, last short way: {bus.last_read_whole}")


if __name__ == "__main__":
    main()
