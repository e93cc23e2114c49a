"""The live view: the rig in a browser (``--view [HOST:]PORT`` of run, demo, play).

:func:`add_view_flag` adds the flag; :func:`view_session` serves the page for the
length of a run and gives the function that attaches the rig once it is built. The
page shows the rig's MuJoCo model posed from the servos' reports (goals as a ghost),
a human-hand skeleton of the full pose, the glove, the loop's figures, each servo and
the outputs, with buttons for relax/resume, stop and e-stop. See docs/view.md.
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

from handrig.app.view.address import (
    DEFAULT_HOST,
    DEFAULT_PORT,
    browser_advice,
    is_loopback,
    parse_view_address,
    secrets_token,
)
from handrig.app.view.encode import FrameEncoder, HandsSnapshot
from handrig.app.view.playback import view_playback
from handrig.app.view.scene import ModelScene
from handrig.app.view.server import RigControls, ViewServer, ViewStats

if TYPE_CHECKING:
    from handrig.app.view.process import ViewProcess
    from handrig.config.rig import RigConfig

__all__ = ["FrameEncoder", "HandsSnapshot", "ModelScene", "RigControls", "ViewServer", "ViewStats",
           "add_view_flag", "build_server", "is_loopback", "parse_view_address", "view_playback",
           "view_session"]

def add_view_flag(parser: argparse.ArgumentParser) -> None:
    """``--view [HOST:]PORT``: serve the live view (127.0.0.1 unless a host is given)."""
    parser.add_argument(
        "--view", default=None, metavar="[HOST:]PORT",
        help=f"serve a live view of the rig in the browser, e.g. --view {DEFAULT_PORT} "
        f"(on {DEFAULT_HOST} only; with a HOST such as 0.0.0.0 other machines may open "
        "it, with the token in the URL printed at the start; PORT 0: any free port)")


def build_server(address: str, rig_config: RigConfig, *, rate_hz: float = 30.0,
                 title: str = "handrig",
                 actions: tuple[str, ...] = ("relax", "stop", "estop")) -> ViewServer:
    """The server for ``--view address`` drawing the rig's models (not started); a
    token when the host is not a loopback address."""
    from handrig.app import simulator

    host, port = parse_view_address(address)
    models = {h: ModelScene(m) for h, m in simulator.view_models(rig_config).items()}
    skeletons = {h: ModelScene(m) for h, m in simulator.human_hand_models().items()}
    encoder = FrameEncoder(models, skeletons, title=title, actions=actions)
    token = None if is_loopback(host) else secrets_token()
    return ViewServer(host, port, encoder, token=token, rate_hz=rate_hz)


@contextlib.contextmanager
def view_session(address: str | None, rig_config: RigConfig, log: Callable[[str], None]
                 ) -> Iterator[ViewProcess | None]:
    """Serve the view for the block when ``address`` is given, in a process of its own
    (:class:`handrig.app.view.process.ViewProcess`), and yield it: the session hands it
    its loops by hand (``attach_hands``, ``LiveOptions.on_hands``); yields None without
    ``--view``. The server closes when the block ends, however it ends."""
    if address is None:
        yield None
        return
    from handrig.app.view.process import ViewProcess

    view = ViewProcess(address, rig_config).start()
    try:
        log(f"view: {view.url}")
        if advice := browser_advice(view.url):
            log(advice)
        yield view
    finally:
        view.close()
