"""The view of ``handrig play``: a recorded performance on the human-hand model.

There is no rig in a playback: the page shows both hands of the human-hand model
(as the puppet and as the skeleton) posed from the recording, the playback's
progress as its mode, and one button, stop, which ends the playback.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator

import numpy as np
from numpy.typing import NDArray

from handrig.app.view.address import is_loopback, parse_view_address, secrets_token
from handrig.app.view.encode import FrameEncoder
from handrig.app.view.scene import ModelScene
from handrig.app.view.server import ViewServer
from handrig.hand import ALL_JOINT_NAMES
from handrig.loop.telemetry import PUBLISH_EVERY_S, LoopSnapshot, Telemetry


class PlaybackView:
    """What ``play`` hands each frame to (:meth:`show`, cheap: a snapshot at most every
    1/30 s); ``stop_requested`` once the page's stop button was pressed."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.telemetry = Telemetry()
        self.stop_requested = False
        self._frames = 0
        self._seq = 0
        self._t0 = self._last_s = time.monotonic()

    def show(self, pose: NDArray[np.float64], wrist: NDArray[np.float64] | None,
             elapsed_s: float) -> None:
        self._frames += 1
        now = time.monotonic()
        if self._seq and now - self._last_s < PUBLISH_EVERY_S:
            return
        self._seq += 1
        self._last_s = now
        values = np.concatenate([pose, wrist if wrist is not None else np.zeros(4)])
        self.telemetry.publish(LoopSnapshot(
            t_s=now, seq=self._seq, mode="playing", mode_reason=f"{self.name} at {elapsed_s:.1f} s",
            rate_hz=self._frames / max(now - self._t0, 1e-9), latency_p50_us=None,
            latency_p99_us=None, frames_lost=0, cycles=self._frames, overruns=0,
            elapsed_s=elapsed_s, pose_deg=tuple(values.tolist()),
            curve_names=ALL_JOINT_NAMES[:len(values)]))

    # the page's buttons: only stop does something in a playback
    def toggle_relax(self) -> None:
        pass

    def request_stop(self, reason: str = "stop button (view)") -> None:
        self.stop_requested = True

    def estop(self, reason: str = "e-stop button (view)") -> None:
        self.stop_requested = True


@contextlib.contextmanager
def view_playback(address: str | None, name: str, log: Callable[[str], None]
                  ) -> Iterator[PlaybackView]:
    """A :class:`PlaybackView` for the block, served on ``address`` when given (else
    it shows nothing); the server closes when the block ends."""
    from handrig.app import simulator

    view = PlaybackView(name)
    if address is None:
        yield view
        return
    host, port = parse_view_address(address)
    hands = {h: ModelScene(m) for h, m in simulator.human_hand_models().items()}
    encoder = FrameEncoder(hands, {h: ModelScene(m) for h, m in
                                   simulator.human_hand_models().items()},
                           title=f"handrig play {name}", actions=("stop",))
    server = ViewServer(host, port, encoder,
                        token=None if is_loopback(host) else secrets_token()).start()
    try:
        server.attach(view.telemetry.latest, view)
        log(f"view: {server.url}")
        yield view
    finally:
        server.close()
