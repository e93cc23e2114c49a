"""A fake transport for the servo driver: the byte-level emulator in-process, on a fake clock.

:class:`EmulatorTransport` subclasses the driver's :class:`Transport` ABC. Each
write is fed to the emulator (``sim.dxl_bus.SimBus.feed``: the emulator's own
codec in ``firmware_protocol``, its servos and its fault switches) without a pty
or a thread; each reply is delivered when the wire would have carried it, on the
driver's :class:`FakeClock`, so timing tests are deterministic. The emulator's
own fake clock measures its fault delays, which are added to the delivery time.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

from handrig.clock import FakeClock
from handrig.config.rig import RigConfig
from handrig.devices.servo.transport import Transport
from sim.dxl_bus import FaultSpec, SimBus, _Reply

BITS_PER_BYTE = 10


class PeerBus(SimBus):
    """The emulated bus with its output collected instead of written to a pty."""

    def __init__(self, rig: RigConfig, faults: FaultSpec | None = None) -> None:
        super().__init__(rig, faults=faults, clock=FakeClock(0.0), realtime=False)
        self._kinematic = list(self.servos)  # servos move toward their goals as time passes
        self.emitted: list[tuple[float, bytes]] = []
        self.ignore_fast_sync_read = False  # firmware without Fast Sync Read: no reply

    def _emit(self, data: bytes) -> None:
        self.emitted.append((self.clock.now(), bytes(data)))

    def _fast_read(self, requests: Sequence[tuple[int, int, int]], now: float) -> list[_Reply]:
        if self.ignore_fast_sync_read:
            return []
        return super()._fast_read(requests, now)


class EmulatorTransport(Transport):
    """Bytes to and from :class:`PeerBus` ``peer``; replies arrive at wire time on ``clock``."""

    def __init__(self, peer: PeerBus, clock: FakeClock, baud: int = 1_000_000) -> None:
        super().__init__("fake:emulator", baud, clock)
        self.peer = peer
        self.fake_clock = clock
        self.byte_s = BITS_PER_BYTE / baud
        self.writes: list[bytes] = []  # every write, as given
        self._open = False
        self._line_free = 0.0
        self._arrivals: deque[tuple[float, bytes]] = deque()
        self.extra_delay_s = 0.0  # added to the next reply's delivery (then reset)

    @property
    def is_open(self) -> bool:
        return self._open

    def open(self) -> None:
        self._open = True

    def close(self) -> None:
        self._open = False

    def write(self, data: bytes | memoryview) -> None:
        self._check_open()
        data = bytes(data)
        self.writes.append(data)
        self.bytes_written += len(data)
        t = max(self.clock.now(), self._line_free) + len(data) * self.byte_s
        peer_clock = self.peer.clock
        assert isinstance(peer_clock, FakeClock)
        peer_clock.sleep_until(t)
        self.peer.emitted.clear()
        self.peer.feed(data, now=t)
        for emitted_at, reply in self.peer.emitted:
            t = max(t, emitted_at) + len(reply) * self.byte_s + self.extra_delay_s
            self.extra_delay_s = 0.0
            self._arrivals.append((t, reply))
        self._line_free = t

    def _receive(
        self, deadline_s: float, spin_from_s: float | None, spin_until_s: float
    ) -> bytes:
        if self._arrivals and self._arrivals[0][0] <= deadline_s:
            at, data = self._arrivals.popleft()
            self.fake_clock.sleep_until(at)
            return data
        self.fake_clock.sleep_until(deadline_s)
        return b""

    def _take_pending(self) -> bytes:
        out = bytearray()
        while self._arrivals and self._arrivals[0][0] <= self.clock.now():
            out += self._arrivals.popleft()[1]
        return bytes(out)
