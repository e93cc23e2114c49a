"""Every hand's summary has the same shape: a two-hand run on two buses, a servo of each
hand missing at start-up and plugged back mid-run, the critical path timed.

The fields the two-hand summary used to lack (servos left out, servos admitted, torque
read back, stage timings) appear for both hands, each with its own servos. The buses are
two in-process emulators on ptys (``sim.dxl_bus.SimBus``), the gloves the demo
recording, the rest the real session, driver and loops.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from handrig.app.hands import build_session_parts
from handrig.app.session import LiveOptions, run_live
from handrig.app.summary import format_hands_summary
from handrig.config.rig import hand_rig
from sim.demo_recording import DEMO_RECORDING
from sim.dxl_bus import SimBus
from sim.dxl_faults import FaultSpec

MISSING = {"ri": 5, "le": 25}  # a servo of each hand, unplugged at start-up


def test_both_hands_summaries_name_their_servos_left_out_admitted_and_torque_read_back(
) -> None:
    parts = build_session_parts("puppet_two_buses", glove_per_hand=True)
    assert parts.buses == ((0,), (1,))  # [left_bus]: a bus each, as the rig file says
    rigs = {h: hand_rig(parts.rig_config, h) for h in MISSING}
    who = {h: f"servo {i} ({rigs[h].servo(i).joint})" for h, i in MISSING.items()}
    sims = {h: SimBus.from_rig(rigs[h], faults=FaultSpec(missing=frozenset({i})))
            for h, i in MISSING.items()}
    plugged: list[bool] = []

    def on_hands(loops: dict[str, Any], every: Any) -> None:
        assert set(loops) == {"ri", "le"}

        def plug_back() -> None:  # once both loops run, the missing servos answer
            deadline = time.monotonic() + 30.0
            while (min(loop.stats.frames for loop in loops.values()) < 40
                   and time.monotonic() < deadline):
                time.sleep(0.01)
            for sim in sims.values():
                with sim.lock:
                    sim.faults = FaultSpec()
            plugged.append(True)
        threading.Thread(target=plug_back, daemon=True).start()

    replay = f"replay:{DEMO_RECORDING}"
    with sims["ri"] as right, sims["le"] as left:
        result = run_live(parts, LiveOptions(
            glove=replay, glove_left=replay, bus=right.port_path, bus_left=left.port_path,
            duration_s=1.5, profile=True, on_hands=on_hands, log=lambda line: None))
    s = result.summary
    assert result.started and "error" not in s, s.get("error")
    assert plugged and s["buses"] == "two" and s["torque_off"] is True
    hands = s["hands"]
    assert list(hands) == ["right", "left"]
    assert set(hands["right"]) == set(hands["left"])  # the same shape for every hand
    for h, name in (("ri", "right"), ("le", "left")):
        part = hands[name]
        assert part["servos_left_out"] == [who[h]], part.get("servos_left_out")
        assert part["servos_admitted"] == [who[h]], part.get("servos_admitted")
        assert part["silence"]["admitted"] == 1
        assert part["torque_off"] is True and "torque_off_unconfirmed" not in part
        assert part["stages_us"] and part["glove_source"] == replay
        assert part["bus"]["writes"] >= part["frames"] > 100
    text = format_hands_summary(s)
    right_part, left_part = text.split("--- left hand")
    for section in (right_part, left_part):
        assert "servos left out" in section and "admitted" in section
