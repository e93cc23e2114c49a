"""The one fake servo bus and the scripted glove the loop's tests run on.

Both subclass the real ABCs (:class:`~handrig.devices.servo.bus.ServoBus`,
:class:`~handrig.devices.glove.source.GloveSource`), so a method the loop needs and
the fake lacks fails loudly. Tests that need a fault subclass :class:`FakeBus` and
override the one method the fault lives in.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Mapping, Sequence

import numpy as np

from handrig.clock import FakeClock
from handrig.devices.glove import GloveSample, GloveSource, GloveStats
from handrig.devices.servo.bus import BusStats, ServoBus, ServoState
from handrig.errors import DeviceError


class ScriptedGlove(GloveSource):
    """Emits one sample per call while ``raw_at(t)`` returns counts; None = silence."""

    def __init__(self, clock: FakeClock, raw_at: Callable[[float], np.ndarray | None],
                 estop_at: float | None = None) -> None:
        super().__init__()
        self.clock = clock
        self.raw_at = raw_at
        self.estop_at = estop_at
        self.n = 0

    def latest(self) -> GloveSample | None:
        t = self.clock.now()
        raw = self.raw_at(t)
        if raw is None:
            return None
        self.n += 1
        estop = self.estop_at is not None and t >= self.estop_at
        quat = np.array([0.0, 0.0, 0.0, 1.0])  # palm down, forearm horizontal
        return GloveSample(np.asarray(raw, float), quat, int(estop), estop, self.n, 0,
                           t, self.n)

    def stats(self) -> GloveStats:
        return GloveStats(frames_ok=self.n)


class FakeBus(ServoBus):
    """Servos named ``names`` on a fake clock. Remembers every goal vector (``goals``);
    a read reports the goals last written as the present positions (they follow one
    read late), or ``position_deg`` for every servo when it is given.

    ``write_cost_s``: each write advances the clock this much; ``fail_after``: the
    write after that many raises DeviceError (the port went away). What a read
    reports besides: ``temperature_c``, ``current_ma`` for every servo,
    ``hardware_errors`` (index -> Hardware Error Status), ``stale`` (indices read
    stale, their reading ``stale_age_s`` old). ``held_deg``: where torque-on holds the
    servos (``last_goals_deg``; None: the ABC's, unknown). ``timeouts``: the bus's
    timeout count to start from; ``port``: its name.
    """

    def __init__(self, names: tuple[str, ...], clock: FakeClock, *,
                 write_cost_s: float = 0.0, fail_after: int | None = None,
                 position_deg: float | None = None, temperature_c: float = 0.0,
                 current_ma: float = 0.0, hardware_errors: Mapping[int, int] | None = None,
                 stale: Sequence[int] = (), stale_age_s: float = 0.05,
                 held_deg: float | None = None, timeouts: int = 0, port: str = "") -> None:
        self._names = names
        self.clock = clock
        self.write_cost_s = write_cost_s
        self.fail_after = fail_after
        self.position_deg = position_deg
        self.temperature_c = temperature_c
        self.current_ma = current_ma
        self.hardware_errors = dict(hardware_errors or {})
        self.stale_indices = tuple(stale)
        self.stale_age_s = stale_age_s
        self.held_deg = held_deg
        self.port = port
        self.goals: list[np.ndarray] = []
        self._stats = BusStats(len(names), timeouts=timeouts)
        self.torque_on = False

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._names

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(range(1, len(self._names) + 1))

    @property
    def last_goals_deg(self) -> np.ndarray:
        if self.held_deg is None:
            return super().last_goals_deg
        return np.full(len(self._names), self.held_deg)

    @property
    def stats(self) -> BusStats:
        return self._stats

    def connect(self) -> None:
        pass

    def close(self) -> None:
        self.torque_on = False

    @contextlib.contextmanager
    def torque(self, *, handle_signals: bool = True) -> Iterator[ServoBus]:
        self.torque_on = True
        try:
            yield self
        finally:
            self.torque_on = False

    def write_goals_deg(self, goals_deg: np.ndarray) -> int:
        if self.fail_after is not None and len(self.goals) >= self.fail_after:
            raise DeviceError("servo port /dev/ttyUSB0 went away (test)")
        self.goals.append(np.array(goals_deg))
        self._stats.writes += 1
        self.clock.advance(self.write_cost_s)
        return 0

    def read_state(self, deadline_s: float | None = None,
                   part: tuple[int, int] | None = None, *, patient: bool = False
                   ) -> ServoState:
        self._stats.reads += 1
        n = len(self._names)
        if self.position_deg is not None:
            pos = np.full(n, self.position_deg)
        else:
            pos = self.goals[-1].copy() if self.goals else np.zeros(n)
        stale = np.zeros(n, bool)
        stale[list(self.stale_indices)] = True
        hw = np.zeros(n, np.uint8)
        for i, code in self.hardware_errors.items():
            hw[i] = code
        return ServoState(pos, np.zeros(n), np.full(n, self.current_ma),
                          np.full(n, self.temperature_c), np.zeros(n, np.uint8), hw, stale,
                          np.where(stale, self.stale_age_s, 0.0), self.clock.now(),
                          self._stats.copy())
