"""Torque-off writes whose acknowledgements were lost, while the servos did switch off.

At an e-stop on a starved host, a servo's torque-off write can go unacknowledged
although the broadcast before it reached the servo: the torque context then raises
:class:`~handrig.errors.TorqueOffError`. The session reads Torque Enable back at exit;
when every servo reads off, the run is not a failure: exit status 0, no ``error``, and
the summary says what happened (``torque_off_note``). When the read-back does not
confirm it, the error stands.

The toy vendor of test_second_vendor_session.py runs a whole session on a fake clock.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from handrig.app.result import LiveResult, print_result
from handrig.clock import FakeClock
from handrig.devices.servo.bus import ServoBus
from handrig.errors import DeviceError, TorqueOffError
from tests.handrig.app.test_second_vendor_session import ToyVendorBus, _session

LOST = "torque off failed: servo 7 (riIndexMCPy): no status after 3 attempts"


class AcksLostBus(ToyVendorBus):
    """Torque goes off, but the torque context reports servo 7's write unacknowledged."""

    @contextlib.contextmanager
    def torque(self, *, handle_signals: bool = True) -> Iterator[ServoBus]:  # type: ignore[override]
        with super().torque(handle_signals=handle_signals) as bus:
            yield bus
        raise TorqueOffError(LOST)


class StillOnBus(AcksLostBus):
    """The same, and the read-back cannot confirm servo 7."""

    def confirm_torque_off(self, budget_s: float) -> tuple[bool | None, list[str]]:
        return None, ["servo 7 (riIndexMCPy): no status"]


def test_lost_acknowledgements_with_torque_read_back_off_are_not_a_failure(capsys) -> None:
    summary, buses, _, started = _session(AcksLostBus, FakeClock(10.0), script=False)
    assert started and not buses[0].torque_on
    assert "error" not in summary, summary["error"]
    assert summary["torque_off"] is True
    assert LOST in summary["torque_off_note"] and "only the acknowledgements" in (
        summary["torque_off_note"])
    assert summary["stop_reason"] == "3 s done"
    status = print_result(LiveResult(summary, [], (), started=True), as_json=False)
    assert status == 0
    out = capsys.readouterr().out
    assert "torque off        True" in out and "note" in out and LOST in out


def test_lost_acknowledgements_the_read_back_cannot_confirm_are_an_error() -> None:
    summary, _, _, started = _session(StillOnBus, FakeClock(10.0), script=False)
    assert started
    assert summary["error"] == LOST
    assert summary["torque_off"] is None and "torque_off_note" not in summary
    assert print_result(LiveResult(summary, [], (), error=TorqueOffError(LOST),
                                   started=True), as_json=True) == 1


class FailsMidRunBus(AcksLostBus):
    """The run ends on a device error of its own; then the torque-off acknowledgements
    are lost as well."""

    def write_goals_deg(self, goals_deg):  # type: ignore[no-untyped-def]
        if len(self.goals) >= 100:
            raise DeviceError("servo port went away")
        return super().write_goals_deg(goals_deg)


def test_the_runs_own_error_is_not_hidden_by_lost_acknowledgements() -> None:
    summary, _, _, started = _session(FailsMidRunBus, FakeClock(10.0), script=False)
    assert started
    assert "servo port went away" in summary["error"], summary["error"]
    assert "torque off failed" not in summary["error"]
