"""The LEAP preset end to end: the demo's glove recording, the expansion, the retarget, the
real driver at 4 Mbps, ``handrig sim-bus --rig leap`` (emulated XC330-M288s in
current-based position mode on the LEAP MJCF), torque off at the end."""

from __future__ import annotations

import numpy as np
import pytest

from handrig.app import factory as app
from handrig.app import simulator
from handrig.app.session import torque_is_off
from handrig.clock import MonotonicClock
from handrig.loop.modes import Mode

pytest.importorskip("mujoco")
FRAMES = 1600  # 8 s at 200 Hz: the recording's first index and thumb motions


def test_index_and_thumb_follow_their_glove_channels_and_torque_ends_off() -> None:
    parts = app.build_parts("leap")
    rig_cfg = parts.rig_config
    assert rig_cfg.bus.baud == 4_000_000
    clock = MonotonicClock()
    controls, goals, present = [], [], []
    # no wire timing: on a loaded test machine the emulator answers sooner, not later
    with app.servo_bus("sim", parts, clock, wire_timing=False, log=lambda _: None) as opened:
        bus = opened.bus
        glove = app.open_glove(f"replay:{simulator.demo_recording()}", parts.glove_config,
                               clock)
        with glove:
            bus.connect()
            assert bus.models == {s.id: 1240 for s in rig_cfg.servos}
            rig = app.build_rig(parts, glove, bus, clock, log=lambda _: None)

            def capture(t_s: float, pose: np.ndarray) -> None:
                state = rig.last_state
                if state is not None and state.all_fresh and rig.mode is Mode.RUNNING:
                    controls.append(rig.cycle.controls.copy())
                    goals.append(np.array(bus.last_goals_deg))
                    present.append(np.array(state.positions_deg))
            rig.outputs = (capture,)
            with bus.torque(handle_signals=False):
                stats = rig.run(frames=FRAMES)
            assert torque_is_off(bus) is True
    assert stats.frames >= FRAMES and stats.stop_reason
    c, g, p = np.array(controls), np.array(goals), np.array(present)
    assert len(c) > FRAMES // 8  # a fresh read every read_every cycles, while running
    names = list(parts.pipeline.servo_joints)
    ctl = list(parts.expander.controls)
    low = np.array([s.min_deg for s in rig_cfg.servos])
    high = np.array([s.max_deg for s in rig_cfg.servos])
    assert np.all(g >= low - 1e-9) and np.all(g <= high + 1e-9)
    for joint, channel in (("if_mcp", "riIndexMCPy"), ("th_cmc", "riThumbCMCy"),
                           ("th_axl", "riThumbCMCx")):
        x, y = c[:, ctl.index(channel)], p[:, names.index(joint)]
        assert np.std(x) > 3.0, channel  # the recording moves this channel
        r = float(np.corrcoef(x, y)[0, 1])
        assert r > 0.85, (joint, channel, r)
    tracking = np.sqrt(np.mean((p - g) ** 2))
    assert tracking < 5.0
