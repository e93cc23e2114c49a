"""The glove contract: :class:`GloveSource`, the samples it hands out and its counters.

The loop calls :meth:`~GloveSource.latest` once per cycle: it returns the newest
sample not handed out before, or ``None`` when nothing new has arrived, and never
blocks. Concrete sources: :class:`~handrig.devices.glove.serial_glove.SerialGlove`
(a serial port or pty) and :class:`~handrig.devices.glove.replay.ReplayGlove`
(a recording played against the injected clock).

Each source keeps :class:`GloveStats` (good frames, CRC and other errors,
frames dropped for an unexpected channel count, resyncs, garbage bytes, sequence
gaps, disconnects and reconnects, time since the last good frame). A port that
goes away sets :attr:`GloveSource.failure` to a :class:`DeviceError` with a
clear message; ``latest()`` then simply returns ``None`` (the loop's glove
timeout eases the puppet to the relaxed pose) and :meth:`GloveSource.check`
raises it for callers that prefer to stop. What happened to the port (gone,
back after how long) is also queued as text for :meth:`GloveSource.drain_events`.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType

import numpy as np
from numpy.typing import NDArray

from handrig.errors import DeviceError

FloatArray = NDArray[np.float64]

BEHIND_KEPT = 2
"""Samples kept behind the newest while never handed out (:meth:`GloveSource.take_behind`:
a loop held up catches up on them); older ones are superseded for good."""
MAX_EVENTS = 64
"""Port events kept for :meth:`GloveSource.drain_events` (the oldest go first)."""

@dataclass(frozen=True, slots=True, eq=False)
class GloveSample:
    """One glove sample as the loop sees it.

    ``raw`` (k,) float64: raw channel counts in the glove's channel order (for
    OpenGloves the 13 channels of ``firmware_protocol.opengloves.CHANNEL_KEYS``).
    ``quat`` (4,) float64: forearm IMU orientation x, y, z, w (scalar last, ENU
    world frame, IMU body to world), or ``None`` when the glove has no valid IMU
    reading. ``buttons``: bitfield, bit 0 = relax / e-stop (``estop``).
    ``seq``: the glove's sequence number (wraps at 65536; for OpenGloves, lines
    received). ``sensor_time_us``: the glove's timestamp (wraps at 2**32; 0 for
    OpenGloves). ``host_time_s``: Clock time at which the read that delivered the
    frame's last byte returned (glove-to-servo latency is measured from it).
    ``count``: 1-based running count of samples from this source. ``status``: the
    frame's status flags (``firmware_protocol.glove.FLAG_IMU_ABSENT`` ...; 0 for other
    sources), in words by :mod:`handrig.devices.glove_status`.
    """

    raw: FloatArray
    quat: FloatArray | None
    buttons: int
    estop: bool
    seq: int
    sensor_time_us: int
    host_time_s: float
    count: int
    status: int = 0


@dataclass(frozen=True)
class GloveStats:
    """A snapshot of a source's counters (monotonic since it was opened).

    For :class:`ReplayGlove`, ``frames_lost`` counts recorded samples that came
    due but were superseded before the loop asked (the loop ran slower than the
    recording).
    """

    frames_ok: int = 0
    crc_errors: int = 0
    decode_errors: int = 0
    """Rejected frames other than CRC mismatches (bad stuffing, length, version,
    malformed or cut OpenGloves lines, overlong runs)."""
    resyncs: int = 0
    garbage_bytes: int = 0
    seq_gaps: int = 0
    frames_lost: int = 0
    bytes_read: int = 0
    reconnects: int = 0
    """Times the port came back after it went away."""
    time_since_last_good_s: float = math.inf
    failure: str = ""
    channel_errors: int = 0
    """Frames dropped for a channel count other than :attr:`expected_channels`
    (also counted in ``decode_errors``)."""
    expected_channels: int = 0
    """The channel count frames must have; 0 until the glove has settled on one."""
    disconnects: int = 0
    """Times the port went away (unplugged, hung up, unreadable)."""
    last_outage_s: float = 0.0
    """How long the port was gone the last time it came back, seconds."""

    @property
    def errors(self) -> int:
        """Rejected frames of every kind."""
        return self.crc_errors + self.decode_errors


class GloveSource(ABC):
    """A glove: raw samples in, without ever blocking the loop; everything the loop uses.

    Use as a context manager (``with SerialGlove(...) as glove:``), which calls
    :meth:`start` and :meth:`close`. Subclasses call :meth:`_arrived` with each new
    sample and implement :meth:`stats`; the hooks (:meth:`fileno` and :meth:`pump`
    for a port the loop waits on, :meth:`next_due_s` and :meth:`newest_due_s` for a
    source that knows when its samples come) have defaults that say "nothing to
    wait on": the loop then runs at its floor rate and takes what :meth:`latest` has.
    """

    pump_counts: bool = False
    """Whether :meth:`pump` returns how many good frames it decoded (else 0 always)."""

    def __init__(self) -> None:
        self._newest: GloveSample | None = None
        self._behind: deque[GloveSample] = deque(maxlen=BEHIND_KEPT)  # never taken
        self._taken = 0
        self._failure: DeviceError | None = None
        self._events: deque[str] = deque(maxlen=MAX_EVENTS)
        self._taps: tuple[Callable[[GloveSample], None], ...] = ()

    @property
    def name(self) -> str:
        """Where the samples come from, for a person (a port path, "replay")."""
        return type(self).__name__

    def start(self) -> None:  # noqa: B027 - optional hook
        """Begin reading (open the port, start the thread). Idempotent."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Stop reading and release the device. Idempotent."""

    def latest(self) -> GloveSample | None:
        """The newest sample not returned before, or ``None`` if nothing new. Never blocks."""
        s = self._newest
        if s is None or s.count == self._taken:
            return None
        self._taken = s.count
        return s

    def peek(self) -> GloveSample | None:
        """The newest sample so far (new or not), without marking it taken."""
        return self._newest

    def add_tap(self, tap: Callable[[GloveSample], None]) -> None:
        """Have ``tap(sample)`` called with every good sample as it arrives (in the thread
        that reads the port: it must only queue it, e.g. a glove take's recorder)."""
        self._taps = (*self._taps, tap)

    def _tapped(self, sample: GloveSample) -> None:
        """Hand ``sample`` to the taps (:meth:`add_tap`); a source that does not call
        :meth:`_arrived` calls this itself."""
        for tap in self._taps:
            tap(sample)

    def _arrived(self, sample: GloveSample) -> None:
        """``sample`` is the newest now; the one it replaces is kept behind it while it
        has not been taken (:data:`BEHIND_KEPT` of them: a loop that fell further behind
        skips the older ones). The taps (:meth:`add_tap`) get it."""
        if self._taps:
            self._tapped(sample)
        old, behind = self._newest, self._behind
        if old is None or old.count == self._taken:
            behind.clear()
        else:
            behind.append(old)
        self._newest = sample

    def take(self) -> GloveSample | None:
        """:meth:`latest` without reading the device first (a loop that has just pumped
        it); by default the same as :meth:`latest`."""
        return self.latest()

    def fileno(self) -> int | None:
        """A descriptor that turns readable when bytes arrive, for a loop that blocks on
        it and then calls :meth:`pump`; None (the default): nothing to wait on."""
        return None

    def pump(self) -> int:
        """Read and decode what has arrived, stamped with the clock now; never blocks.
        Returns how many good frames that gave (see :attr:`pump_counts`)."""
        return 0

    def rehearse(self) -> None:  # noqa: B027 - optional hook
        """Decode the bytes of the newest frame again, into nothing: the decode's code and
        tables are then in the CPU's caches when the next frame comes (the loop calls it
        shortly before a frame is expected, :class:`handrig.loop.trigger.GloveTrigger`'s
        warm-up). Changes nothing a caller can see; default: nothing to rehearse."""

    def next_due_s(self) -> float | None:
        """When the next sample not yet returned comes due, clock time (a replay);
        None (the default): the source does not know."""
        return None

    def newest_due_s(self) -> float | None:
        """When the newest sample due by now came due (a replay: its arrival time);
        None (the default): use the sample's ``host_time_s``."""
        return None

    def has_behind(self) -> bool:
        """Whether a sample before the newest came and was never taken (it was superseded
        before the loop asked), while the newest is new too."""
        behind = self._behind
        if not behind:  # the usual case: the loop took the one before the newest
            return False
        s, taken = self._newest, self._taken
        if s is None or s.count == taken:
            return False
        return any(b.count > taken for b in behind)

    def take_behind(self) -> GloveSample | None:
        """The oldest sample kept behind the newest that was never taken
        (:meth:`has_behind`), marked taken so that the ones after it and the newest stay
        new; else ``None``."""
        if not self.has_behind():
            return None
        behind = self._behind
        while behind[0].count <= self._taken:
            behind.popleft()
        b = behind.popleft()
        self._taken = b.count
        return b

    def has_new(self) -> bool:
        """Whether :meth:`latest` has a sample not returned before (without taking it)."""
        s = self._newest
        return s is not None and s.count != self._taken

    @abstractmethod
    def stats(self) -> GloveStats:
        """A snapshot of the counters."""

    @property
    def failure(self) -> DeviceError | None:
        """Why the device stopped delivering (port gone, unreadable), or ``None``."""
        return self._failure

    def check(self) -> None:
        """Raise :attr:`failure` if the device has failed."""
        if self._failure is not None:
            raise self._failure

    def drain_events(self) -> list[str]:
        """What happened to the device since the last call (port gone, port back), oldest
        first; at most :data:`MAX_EVENTS` are kept. Safe to call from any thread."""
        out = []
        while self._events:
            try:
                out.append(self._events.popleft())
            except IndexError:
                break
        return out

    def __enter__(self) -> GloveSource:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
