"""What the live view's tests share: a stand-in for the rig's three key actions."""

from __future__ import annotations


class Controls:
    """Records what the buttons asked for (the rig's three key actions)."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    def toggle_relax(self) -> None:
        self.calls.append("relax")

    def request_stop(self, reason: str = "") -> None:
        self.calls.append("stop")

    def estop(self, reason: str = "") -> None:
        self.calls.append("estop")
