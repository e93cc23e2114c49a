"""DynamixelBus against the byte-level emulator (sim.dxl_bus.SimBus) through the real SDK port:
connecting, limits, torque and signals, reply faults and the overload policy.
(Reads, housekeeping and the wire: test_servo_bus_reads.py; silent servos, a port that
never drains, the warm-up: test_servo_bus_silence.py.)

Every assertion about what the servos got is read from the emulated servos' own
registers, not from the driver. The ``sim`` and ``bus`` fixtures are this folder's
conftest.py's.
"""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from firmware_protocol.dynamixel import HardwareError
from firmware_protocol.dynamixel import Reg as SimReg
from handrig.clock import FakeClock
from handrig.config.rig import SilenceConfig
from handrig.devices.servo import DynamixelBus, FaultPolicy, ServoBus
from handrig.devices.servo.positions import deg_to_ticks
from handrig.devices.servo.transport import SerialTransport
from handrig.errors import DeviceError, DeviceTimeoutError, SafetyStop, ServoFault
from handrig.loop.silence import SilenceWatch
from sim.dxl_bus import FaultSpec, SimBus
from tests.helpers.servos import RIG, goals_received, small_rig, tick_limits

REPO = Path(__file__).resolve().parents[4]


def test_is_a_servo_bus(bus: DynamixelBus) -> None:
    assert isinstance(bus, ServoBus)
    assert bus.joint_names == tuple(s.joint for s in small_rig().servos)


def test_commissioning_sets_return_delay_and_reports(sim: SimBus, bus: DynamixelBus) -> None:
    for s in small_rig().servos:
        servo = sim.servo(s.id)
        assert servo.get(SimReg.RETURN_DELAY_TIME) == 0
        assert servo.get(SimReg.OPERATING_MODE) == 3
        assert not servo.torque_enabled
    text = "\n".join(bus.commissioning)
    assert f"no USB latency timer on {os.path.realpath(bus.port)}: skipped" in text
    assert "RETURN_DELAY_TIME 250 -> 0" in text
    assert "Fast Sync Read" in text
    assert bus.models == {s.id: 1200 for s in small_rig().servos}


def test_missing_servo_is_named_at_connect() -> None:
    rig = small_rig()
    with SimBus.from_rig(rig, faults=FaultSpec(missing=frozenset({4}))) as sim:
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000)
        with pytest.raises(DeviceError) as info:
            b.connect()
        msg = str(info.value)
        assert (f"servo 4 (riThumbMCPz) did not answer on {sim.port_path} at 1000000 baud: "
                "check power and ID") in msg
        assert "IDs answering a broadcast ping" in msg and "[1, 2, 3, 5, 6]" in msg
        assert "servo 3" not in msg


def test_wrong_model_is_named_at_connect() -> None:
    rig = small_rig(3)
    wrong = r"servo 1 \(riThumbCMCx\) is model 1020 \(XM430-W350\), the rig says XL330-M288"
    with SimBus.from_rig(rig, model="XM430-W350") as sim, pytest.raises(DeviceError, match=wrong):
        DynamixelBus(sim.port_path, rig, baud=1_000_000).connect()


def test_port_that_does_not_exist() -> None:
    with pytest.raises(DeviceError, match="cannot open servo port /dev/nonexistent-dxl"):
        DynamixelBus("/dev/nonexistent-dxl", small_rig()).connect()


def test_goals_clamped_whatever_the_caller_asks(sim: SimBus, bus: DynamixelBus) -> None:
    rig = small_rig()
    lo, hi = tick_limits(rig)
    rng = np.random.default_rng(3)
    clamped_total = 0
    for k in range(200):
        goals = rng.normal(0.0, 400.0, len(rig.servos))
        if k % 7 == 0:
            goals[k % len(goals)] = math.nan
        if k % 11 == 0:
            goals[(k + 1) % len(goals)] = -math.inf
        clamped_total += bus.write_goals_deg(goals)
        bus.read_state()  # a read after each write: the emulator has handled the write
        got = goals_received(sim, rig)
        assert np.all(got >= lo) and np.all(got <= hi), (k, got, lo, hi)
    assert clamped_total > 0
    assert bus.stats.clamps == clamped_total
    # an in-range goal goes through exactly (to the tick)
    inside = np.array([0.5 * (s.min_deg + s.max_deg) for s in rig.servos])
    assert bus.write_goals_deg(inside) == 0
    expected = [deg_to_ticks(s, float(d)) for s, d in zip(rig.servos, inside, strict=True)]
    for _ in range(100):  # the emulator thread may not have handled the write yet
        if goals_received(sim, rig).tolist() == expected:
            break
        time.sleep(0.01)
    assert goals_received(sim, rig).tolist() == expected


def test_wrong_shape_rejected(bus: DynamixelBus) -> None:
    with pytest.raises(ValueError, match=r"shape \(6,\)"):
        bus.write_goals_deg(np.zeros(5))


def test_torque_context_moves_and_reads_back(sim: SimBus, bus: DynamixelBus) -> None:
    rig = small_rig()
    goals = np.array([0.8 * s.max_deg for s in rig.servos])
    with bus.torque():
        for s in rig.servos:
            assert sim.servo(s.id).torque_enabled
            assert sim.servo(s.id).get(SimReg.BUS_WATCHDOG) == RIG.bus.watchdog_ms // 20
        t_end = time.monotonic() + 3.0
        while time.monotonic() < t_end:
            bus.write_goals_deg(goals)
            state = bus.read_state()
            if not state.stale.any() and np.allclose(state.positions_deg, goals, atol=0.2):
                break
            time.sleep(0.005)
        assert not state.stale.any()
        np.testing.assert_allclose(state.positions_deg, goals, atol=0.2)
        assert state.positions_deg.shape == state.velocities_dps.shape == (6,)
        assert np.all(np.isfinite(state.currents_ma))
        assert np.all(state.age_s < 0.05)
    for s in rig.servos:
        assert not sim.servo(s.id).torque_enabled
        assert sim.servo(s.id).get(SimReg.BUS_WATCHDOG) == 0


def test_torque_off_after_exception(sim: SimBus, bus: DynamixelBus) -> None:
    with pytest.raises(RuntimeError, match="boom"), bus.torque():
        assert all(sim.servo(s.id).torque_enabled for s in small_rig().servos)
        raise RuntimeError("boom")
    assert not any(sim.servo(s.id).torque_enabled for s in small_rig().servos)
    assert not bus.torque_enabled


def test_torque_contexts_do_not_nest(bus: DynamixelBus) -> None:
    with bus.torque(), pytest.raises(DeviceError, match="do not nest"), bus.torque():
        pass


def test_close_turns_torque_off(sim: SimBus) -> None:
    b = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000)
    b.connect()
    ctx = b.torque(handle_signals=False)
    ctx.__enter__()
    assert sim.servo(1).torque_enabled
    b.close()
    b.close()
    assert not any(sim.servo(s.id).torque_enabled for s in small_rig().servos)


def test_signal_inside_torque_raises_then_torque_off(sim: SimBus, bus: DynamixelBus) -> None:
    with pytest.raises(SafetyStop, match="SIGTERM"), bus.torque():
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):
            bus.write_goals_deg(np.zeros(6))
            time.sleep(0.001)
    assert not any(sim.servo(s.id).torque_enabled for s in small_rig().servos)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_on_signal_callback_gets_first_signal(bus: DynamixelBus) -> None:
    seen: list[str] = []
    with bus.torque(on_signal=seen.append):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.01)
        assert seen == ["SIGINT"]
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.5)


@pytest.mark.parametrize(
    "spec, counter",
    [
        (FaultSpec(drop=0.3, seed=1), "timeouts"),
        (FaultSpec(corrupt=0.3, seed=2), "crc_errors"),
        (FaultSpec(wrong_id=0.3, seed=3), "stale"),
        (FaultSpec(truncate=0.3, seed=4), "timeouts"),
        (FaultSpec(delay=0.1, delay_s=0.012, seed=5), "timeouts"),
    ],
    ids=["drop", "corrupt", "wrong_id", "truncate", "delay"],
)
def test_reply_faults_counted_marked_stale_never_out_of_limits(
    sim: SimBus, bus: DynamixelBus, spec: FaultSpec, counter: str
) -> None:
    rig = small_rig()
    lo, hi = tick_limits(rig)
    rng = np.random.default_rng(0)
    with bus.torque():
        sim.faults = spec  # faults on after commissioning
        stale_reads = 0
        fresh_reads = 0
        for _ in range(150):
            bus.write_goals_deg(rng.normal(0.0, 300.0, 6))
            state = bus.read_state(bus.clock.now() + 0.008)
            stale_reads += int(state.stale.any())
            fresh_reads += int(not state.stale.all())
            # a stale entry is never younger than this read
            assert np.all(state.age_s[state.stale] > 0)
            got = goals_received(sim, rig)
            assert np.all(got >= lo) and np.all(got <= hi)
        sim.faults = FaultSpec()
    st = bus.stats
    injected = sum(sim.fault_counts.values())
    assert injected > 10
    assert fresh_reads > 30
    if counter == "stale":
        assert stale_reads > 0 or st.retries > 0
    else:
        assert getattr(st, counter) > 0
    assert st.retries > 0
    assert not any(sim.servo(s.id).torque_enabled for s in rig.servos)


def test_servo_gone_at_runtime_is_stale_then_a_fault(sim: SimBus) -> None:
    rig = small_rig()
    # room for the retry that takes the servos after the silent one in the chain (they fail
    # with it in a Fast Sync Read) even when a loaded machine makes replies late
    policy = FaultPolicy(read_budget_s=0.2)
    b = DynamixelBus(sim.port_path, rig, baud=1_000_000, fault_policy=policy)
    b.connect()
    # the loop's [silence] tiers decide what a silent servo means (handrig.loop.silence)
    watch = SilenceWatch(b, SilenceConfig(warn_s=0.05, hold_s=0.1, action_s=0.2,
                                          action="stop"), rig.loop.slew_deg_s)
    try:
        first = b.read_state()
        assert first.all_fresh
        sim.servo(3).silent_until = math.inf  # unplugged
        reads = 0
        for _ in range(4):
            # the servos after it in the chain come in the read's retry; on a loaded
            # machine that retry's reply can come after its deadline (they are stale
            # then, and said so): such a read is taken once more, up to 5 times
            for _ in range(5):
                state = b.read_state()
                reads += 1
                if not np.delete(state.stale, 2).any():
                    break
            assert state.stale.tolist() == [False, False, True, False, False, False]
            assert state.positions_deg[2] == first.positions_deg[2]  # the last good value
            assert state.age_s[2] > 0
        assert b.stats.stale_readings[2] == reads
        with pytest.raises(DeviceTimeoutError, match=r"no valid reply from servo 3 "
                           r"\(riThumbCMCz\) for .* check its cable, power and ID"):
            for _ in range(100):
                watch.note_read(b.clock.now())
                watch.update(b.read_state(), b.clock.now())
                time.sleep(0.01)
    finally:
        b.close()


def test_overload_then_reboot_policy(sim: SimBus, bus: DynamixelBus) -> None:
    rig = small_rig()
    with bus.torque():
        bus.write_goals_deg(np.zeros(6))
        servo = sim.servo(5)
        servo.inject_hardware_error(HardwareError.OVERLOAD)
        # one-shot (the default): the status stays until a reboot clears it
        assert not servo.torque_enabled
        state = bus.read_state(bus.clock.now() + 0.5)
        assert state.hardware_errors[4] == 0x20
        assert bus.stats.hardware_errors[4] == 1
        assert bus.stats.reboots[4] == 1
        assert servo.counters["reboots"] == 1
        assert servo.hardware_error == 0
        assert servo.torque_enabled  # given back by the driver after the reboot
        assert all(sim.servo(s.id).torque_enabled for s in rig.servos)
        assert bus.read_state().all_fresh


def test_overload_stop_policy_names_servo_and_bit(sim: SimBus) -> None:
    rig = small_rig()
    b = DynamixelBus(sim.port_path, rig, baud=1_000_000,
                     fault_policy=FaultPolicy(on_hardware_error="stop"))
    b.connect()
    try:
        with pytest.raises(ServoFault) as info, b.torque():
            sim.servo(2).inject_hardware_error(HardwareError.OVERLOAD)
            for _ in range(10):
                b.write_goals_deg(np.zeros(6))
                b.read_state()
        assert info.value.servo_id == 2 and info.value.bits == 0x20
        assert "servo 2 (riThumbCMCy) hardware error 0x20: overload (bit 5)" in str(info.value)
        assert not any(sim.servo(s.id).torque_enabled for s in rig.servos)
    finally:
        b.close()


def test_overload_that_stays_stops_after_max_reboots(sim: SimBus) -> None:
    b = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000,
                     fault_policy=FaultPolicy(max_reboots=2))
    b.connect()
    try:
        with pytest.raises(ServoFault, match="still there after 2 reboots"), b.torque():
            sim.servo(6).inject_hardware_error(HardwareError.OVERLOAD, persistent=True)
            for _ in range(10):
                b.read_state(b.clock.now() + 0.5)
        assert b.stats.reboots[5] == 2
    finally:
        b.close()


def test_sync_read_path(sim: SimBus, bus: DynamixelBus) -> None:
    bus.use_fast_sync_read = False
    # patient: this checks the Sync Read path, not how soon a loaded machine answers
    state = bus.read_state(bus.clock.now() + 0.5, patient=True)
    assert state.all_fresh
    assert sim.stats.by_instruction[0x82] >= 1
    sim.faults = FaultSpec(drop=0.5, seed=9)
    stale = sum(int(bus.read_state().stale.sum()) for _ in range(30))
    sim.faults = FaultSpec()
    assert stale > 0 and bus.stats.timeouts > 0


def test_two_threads_share_the_bus(bus: DynamixelBus) -> None:
    errors: list[BaseException] = []

    def reader() -> None:
        try:
            for _ in range(100):
                # the deadline is generous, and the read waits for replies until it
                # (patient: a starved emulator failed the loop's reply deadline in a CI run
                # beside a busy core): this checks that the lock keeps the threads'
                # requests and replies apart, not how fast a loaded machine answers
                assert bus.read_state(bus.clock.now() + 0.5, patient=True).all_fresh
        except BaseException as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=reader) for _ in range(2)]
    for t in threads:
        t.start()
    for _ in range(200):
        bus.write_goals_deg(np.zeros(6))
    for t in threads:
        t.join()
    assert not errors
    assert bus.stats.malformed == bus.stats.crc_errors == bus.stats.late_replies == 0


def test_transport_deadline_on_a_fake_clock(sim: SimBus) -> None:
    clock = FakeClock(100.0)
    t = SerialTransport(sim.port_path, 1_000_000, clock)
    t.open()
    try:
        assert t.read_packet(100.002) is None
        assert clock.now() == pytest.approx(100.002)
        assert t.read_exact(5, 100.004, spin_from_s=100.003) == b""
        assert clock.now() >= 100.004
    finally:
        t.close()


DRIVER_LOOP = textwrap.dedent("""
    import dataclasses, sys
    import numpy as np
    from handrig.config.rig import load_rig_config
    from handrig.devices.servo import DynamixelBus
    rig = load_rig_config()
    rig = dataclasses.replace(rig, servos=rig.servos[:6])
    bus = DynamixelBus(sys.argv[1], rig, baud=1_000_000)
    bus.connect()
    try:
        with bus.torque():
            print("running", flush=True)
            k = 0
            while True:
                bus.write_goals_deg(np.full(6, 5.0 * np.sin(k / 50)))
                bus.read_state()
                k += 1
    finally:
        bus.close()
""")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_torque_off_after_signal_to_a_driver_process(sim: SimBus, sig: int) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", DRIVER_LOOP, sim.port_path], cwd=REPO,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "running"
        time.sleep(0.2)
        assert all(sim.servo(s.id).torque_enabled for s in small_rig().servos)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode != 0
    assert ("SafetyStop" if sig == signal.SIGTERM else "KeyboardInterrupt") in err
    assert not any(sim.servo(s.id).torque_enabled for s in small_rig().servos)
    assert all(sim.servo(s.id).get(SimReg.BUS_WATCHDOG) == 0 for s in small_rig().servos)


def test_signs_direction_gear_and_zero_read_back() -> None:
    base = small_rig(3).servos
    servos = (
        dataclasses.replace(base[0], direction=-1, gear_ratio=1.5, zero_ticks=2500),
        dataclasses.replace(base[1], direction=1, gear_ratio=2.0, zero_ticks=1500),
        dataclasses.replace(base[2], direction=-1, gear_ratio=1.0, zero_ticks=2048),
    )
    rig = dataclasses.replace(RIG, servos=servos)
    goals = np.array([30.0, -20.0, 25.0])
    with SimBus.from_rig(rig) as sim:
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000)
        b.connect()
        try:
            with b.torque():
                b.write_goals_deg(goals)
                b.read_state()
                want = [2500 - round(30 * 1.5 * 4096 / 360), 1500 - round(20 * 2 * 4096 / 360),
                        2048 - round(25 * 4096 / 360)]
                assert goals_received(sim, rig).tolist() == want
                for _ in range(100):
                    time.sleep(0.002)
                    moving = b.read_state()
                    if np.all(moving.velocities_dps != 0):
                        break
                # on the way, each joint moves toward its goal whatever the servo's direction
                assert np.all(np.sign(moving.velocities_dps) == np.sign(goals))
                for _ in range(300):
                    b.write_goals_deg(goals)
                    state = b.read_state()
                    if np.allclose(state.positions_deg, goals, atol=0.1):
                        break
                    time.sleep(0.005)
                np.testing.assert_allclose(state.positions_deg, goals, atol=0.1)
        finally:
            b.close()
