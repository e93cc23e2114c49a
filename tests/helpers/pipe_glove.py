"""A glove on a pipe, for the triggers' tests: each byte written is one frame."""

from __future__ import annotations

import os
import threading

import numpy as np

from handrig.clock import MonotonicClock
from handrig.devices.glove import GloveSample, GloveSource, GloveStats
from handrig.loop.trigger import GloveTrigger, Tick


class PipeGlove(GloveSource):
    """A glove on a pipe: ``pump()`` decodes each byte as one frame stamped now."""

    def __init__(self, clock: MonotonicClock) -> None:
        super().__init__()
        self.clock = clock
        self.r, self.w = os.pipe()
        os.set_blocking(self.r, False)
        self.count = 0
        self.taken = 0
        self.newest: GloveSample | None = None
        self.pumps = 0

    def fileno(self) -> int:
        return self.r

    def pump(self) -> int:
        self.pumps += 1
        try:
            data = os.read(self.r, 4096)
        except BlockingIOError:
            return 0
        now = self.clock.now()
        for _ in data:
            self.count += 1
            self.newest = GloveSample(np.zeros(5), None, 0, False, self.count, 0, now,
                                      self.count)
        return 0

    def stats(self) -> GloveStats:
        return GloveStats(frames_ok=self.count)

    def has_new(self) -> bool:
        return self.newest is not None and self.count != self.taken

    def peek(self) -> GloveSample | None:
        return self.newest

    def latest(self) -> GloveSample | None:
        self.pump()
        if not self.has_new():
            return None
        self.taken = self.count
        return self.newest

    def send(self, n: int = 1) -> float:
        t = self.clock.now()
        os.write(self.w, b"x" * n)
        return t

    def close(self) -> None:
        os.close(self.r)
        os.close(self.w)


def play_and_tick(glove: PipeGlove, trig: GloveTrigger, frames: int, period_s: float) -> int:
    """A thread plays ``frames`` frames every ``period_s`` into ``glove`` while this one
    waits on ``trig`` (started here) until the last is taken; returns the frame ticks."""
    clock = glove.clock
    stop = threading.Event()

    def play() -> None:
        start = clock.now() + 0.02
        for k in range(frames):
            clock.sleep_until(start + k * period_s)
            glove.send()
        stop.set()

    player = threading.Thread(target=play, daemon=True)
    trig.start(clock.now())
    tick = Tick()
    player.start()
    ticks = 0
    while not (stop.is_set() and not glove.has_new()):
        trig.wait(tick)
        if tick.frame:
            ticks += 1
            glove.latest()
    player.join(5.0)
    return ticks
