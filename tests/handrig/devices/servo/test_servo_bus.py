"""DynamixelBus against the byte-level emulator (sim.dxl_bus.SimBus) through the real SDK port.

Every assertion about what the servos got is read from the emulated servos' own
registers, not from the driver.
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
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from firmware_protocol import dynamixel as dx
from firmware_protocol.dynamixel import HardwareError
from firmware_protocol.dynamixel import Reg as SimReg
from handrig.clock import FakeClock
from handrig.config.rig import RigConfig, SilenceConfig, load_rig_config
from handrig.devices.servo import DynamixelBus, FaultPolicy, ServoBus
from handrig.devices.servo.bus import ServoState
from handrig.devices.servo.transport import SerialTransport
from handrig.errors import DeviceError, DeviceTimeoutError, SafetyStop, ServoFault
from handrig.loop.silence import SilenceWatch
from sim.dxl_bus import FaultSpec, SimBus

REPO = Path(__file__).resolve().parents[4]
RIG = load_rig_config()


def small_rig(n: int = 6) -> RigConfig:
    return dataclasses.replace(RIG, servos=RIG.servos[:n])


def tick_limits(rig: RigConfig) -> tuple[np.ndarray, np.ndarray]:
    lo = np.array([min(s.deg_to_ticks(s.min_deg), s.deg_to_ticks(s.max_deg)) for s in rig.servos])
    hi = np.array([max(s.deg_to_ticks(s.min_deg), s.deg_to_ticks(s.max_deg)) for s in rig.servos])
    return lo, hi


@pytest.fixture
def sim() -> Iterator[SimBus]:
    with SimBus.from_rig(small_rig()) as bus:
        yield bus


@pytest.fixture
def bus(sim: SimBus) -> Iterator[DynamixelBus]:
    b = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000)
    b.connect()
    yield b
    b.close()


def goals_received(sim: SimBus, rig: RigConfig) -> np.ndarray:
    return np.array([sim.servo(s.id).goal for s in rig.servos])


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
    expected = [s.deg_to_ticks(float(d)) for s, d in zip(rig.servos, inside, strict=True)]
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
    policy = FaultPolicy(read_budget_s=0.05)
    b = DynamixelBus(sim.port_path, rig, baud=1_000_000, fault_policy=policy)
    b.connect()
    # the loop's [silence] tiers decide what a silent servo means (handrig.loop.silence)
    watch = SilenceWatch(b, SilenceConfig(warn_s=0.05, hold_s=0.1, action_s=0.2,
                                          action="stop"), rig.loop.slew_deg_s)
    try:
        first = b.read_state()
        assert first.all_fresh
        sim.servo(3).silent_until = math.inf  # unplugged
        for _ in range(4):
            state = b.read_state()
            assert state.stale.tolist() == [False, False, True, False, False, False]
            assert state.positions_deg[2] == first.positions_deg[2]  # the last good value
            assert state.age_s[2] > 0
        assert b.stats.stale_readings[2] == 4
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
    state = bus.read_state()
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
                # the deadline is generous: this checks that the lock keeps the threads'
                # requests and replies apart, not how fast a loaded machine answers
                assert bus.read_state(bus.clock.now() + 0.5).all_fresh
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


@pytest.mark.parametrize("fast", [True, False], ids=["fast", "sync"])
def test_temperatures_read_every_so_often(sim: SimBus, fast: bool) -> None:
    b = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000, temperature_every=3)
    b.connect()
    try:
        b.use_fast_sync_read = fast
        state = b.read_state(b.clock.now() + 0.05)
        assert np.all(np.isfinite(state.temperatures_c))
        assert np.all((state.temperatures_c > 0) & (state.temperatures_c < 100))
        inst = 0x8A if fast else 0x82
        before = sim.stats.by_instruction[inst]
        for _ in range(3):
            b.read_state(b.clock.now() + 0.05)
        # three state reads and one temperature read (every third state read)
        assert sim.stats.by_instruction[inst] - before == 4
    finally:
        b.close()


def test_falls_back_to_sync_read_without_fast_sync_read() -> None:
    rig = small_rig()
    with SimBus.from_rig(rig) as sim:
        # servos whose firmware ignores Fast Sync Read (a broadcast gets no error status);
        # the emulator has no switch for it, so its fast-read handler is replaced
        sim._fast_read = lambda requests, now: []  # type: ignore[method-assign]
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000)
        b.connect()
        try:
            assert not b.use_fast_sync_read
            assert b.stats.fallbacks == 1
            assert any("falling back from Fast Sync Read to Sync Read" in line
                       for line in b.commissioning)
            assert b.read_state().all_fresh
        finally:
            b.close()


def test_falls_back_at_runtime_after_failed_fast_reads(sim: SimBus, bus: DynamixelBus) -> None:
    assert bus.use_fast_sync_read
    sim._fast_read = lambda requests, now: []  # type: ignore[method-assign]
    states = [bus.read_state(bus.clock.now() + 0.02) for _ in range(12)]
    assert not bus.use_fast_sync_read and bus.stats.fallbacks == 1
    assert states[-1].all_fresh


def test_write_and_read_sends_goals_with_the_read(sim: SimBus, bus: DynamixelBus) -> None:
    rig = small_rig()
    goals = np.array([s.max_deg + 50.0 for s in rig.servos])  # all beyond the limits
    clamped, state = bus.write_and_read(goals)
    assert clamped == 6 and state.all_fresh
    _, hi = tick_limits(rig)
    for _ in range(100):
        if goals_received(sim, rig).tolist() == hi.tolist():
            break
        time.sleep(0.01)
    assert goals_received(sim, rig).tolist() == hi.tolist()
    assert bus.stats.writes == 1
    np.testing.assert_array_equal(bus.last_goals_deg, [s.max_deg for s in rig.servos])


@pytest.mark.parametrize("level", [0, 1])
def test_status_return_level_raised_to_two(level: int) -> None:
    rig = small_rig(2)
    with SimBus.from_rig(rig) as sim:
        sim.servo(2).set(SimReg.STATUS_RETURN_LEVEL, level)
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000)
        b.connect()
        try:
            assert sim.servo(2).status_return_level == 2
            assert any(f"STATUS_RETURN_LEVEL {level}" in line and "-> 2" in line
                       for line in b.commissioning)
            with b.torque():
                assert sim.servo(2).torque_enabled
        finally:
            b.close()


def test_fresh_readings_are_true_under_faults() -> None:
    """Whatever the faults, a reading marked fresh is the servo's actual position."""
    rig = RIG
    spec = FaultSpec(drop=0.1, corrupt=0.1, wrong_id=0.1, truncate=0.2, seed=11)
    with SimBus.from_rig(rig) as sim:
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000)
        b.connect()
        try:
            # distinct positions per servo, so a reading given to the wrong servo shows
            with sim.lock:
                for k, s in enumerate(rig.servos):
                    sim.servo(s.id).set_motion(s.zero_ticks + 7.0 * (k + 1), 0.0, 0.0)
            sim.faults = spec
            fresh = 0
            for _ in range(200):
                state = b.read_state(b.clock.now() + 0.02)
                true = np.array([s.ticks_to_deg(sim.servo(s.id).present) for s in rig.servos])
                ok = ~state.stale
                np.testing.assert_allclose(state.positions_deg[ok], true[ok], atol=1e-9)
                fresh += int(ok.sum())
            sim.faults = FaultSpec()
            assert fresh > 1000 and b.stats.retries > 10
        finally:
            b.close()


def test_tripped_watchdog_found_and_rearmed(sim: SimBus) -> None:
    rig = small_rig()
    b = DynamixelBus(sim.port_path, rig, baud=1_000_000, temperature_every=1)
    b.connect()
    try:
        with b.torque():
            time.sleep(0.3)  # the host "hangs": every servo's watchdog (100 ms) trips
            assert all(sim.servo(s.id).get(SimReg.BUS_WATCHDOG) in (-1, 0xFF) for s in rig.servos)
            b.read_state(b.clock.now() + 0.05)
            assert b.stats.watchdog_trips == 6
            assert all(sim.servo(s.id).get(SimReg.BUS_WATCHDOG) == 5 for s in rig.servos)
            goals = np.array([0.5 * s.max_deg for s in rig.servos])
            b.write_goals_deg(goals)
            want = [s.deg_to_ticks(float(g)) for s, g in zip(rig.servos, goals, strict=True)]
            for _ in range(100):
                if goals_received(sim, rig).tolist() == want:
                    break
                time.sleep(0.01)
            assert goals_received(sim, rig).tolist() == want  # goals accepted again
    finally:
        b.close()


def test_goals_after_a_silence_rearm_the_watchdog_first(sim: SimBus) -> None:
    """A host pause longer than the Bus Watchdog (a long garbage collection, say) trips
    it and the servos refuse goals; the next goal write re-arms it before the goals."""
    rig = small_rig()
    b = DynamixelBus(sim.port_path, rig, baud=1_000_000, temperature_every=0)
    b.connect()
    try:
        with b.torque():
            time.sleep(0.3)  # silent: every servo's watchdog (100 ms) trips
            assert all(sim.servo(s.id).get(SimReg.BUS_WATCHDOG) in (-1, 0xFF) for s in rig.servos)
            goals = np.array([0.5 * s.max_deg for s in rig.servos])
            b.write_goals_deg(goals)  # no read in between: the write alone must recover
            want = [s.deg_to_ticks(float(g)) for s, g in zip(rig.servos, goals, strict=True)]
            for _ in range(100):
                if goals_received(sim, rig).tolist() == want:
                    break
                time.sleep(0.01)
            assert goals_received(sim, rig).tolist() == want
            assert b.stats.watchdog_gaps == 1
            assert all(sim.servo(s.id).get(SimReg.BUS_WATCHDOG) == 5 for s in rig.servos)
            b.write_goals_deg(goals)  # no silence this time: nothing re-armed
            assert b.stats.watchdog_gaps == 1
    finally:
        b.close()


def test_late_replies_are_never_taken_for_a_later_read() -> None:
    """A reply delayed past its read's deadline arrives during the next read: dropped."""
    rig = small_rig()
    with SimBus.from_rig(rig) as sim:
        # no retries: one request per read, so the emulator (which answers in turn,
        # sleeping through each delayed reply) never builds a queue
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000,
                         fault_policy=FaultPolicy(read_retries=0))
        b.connect()
        try:
            sim.faults = FaultSpec(delay=0.15, delay_s=0.006, seed=4)
            fresh = 0
            for k in range(120):
                # new, distinct positions before every read: an old reply would show
                with sim.lock:  # the emulator thread moves its servos under this lock
                    for j, s in enumerate(rig.servos):
                        sim.servo(s.id).set_motion(s.zero_ticks + 5.0 * j + (k % 40), 0.0, 0.0)
                state = b.read_state(b.clock.now() + 0.004)
                true = np.array([s.ticks_to_deg(sim.servo(s.id).present) for s in rig.servos])
                ok = ~state.stale
                np.testing.assert_allclose(state.positions_deg[ok], true[ok], atol=1e-9)
                fresh += int(ok.any())
                time.sleep(0.001)  # the next read starts before the late reply arrives
            sim.faults = FaultSpec()
            assert b.stats.late_replies > 0 and fresh > 60
        finally:
            b.close()


def test_one_late_reply_does_not_make_every_later_read_late() -> None:
    """With wire timing, a late reply still on the wire delays the next one (the bus is
    half duplex); the driver waits for the line to go quiet instead of piling up."""
    rig = RIG  # 20 servos at 1 Mbps: a cycle takes 3.2 ms of wire, the read budget 4 ms
    with SimBus.from_rig(rig, wire_timing=True) as sim:
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000, read_fields="position")
        b.connect()
        try:
            sim.faults = FaultSpec(delay=0.02, delay_s=0.004, seed=8)
            failed = 0
            for _ in range(250):
                b.write_goals_deg(np.zeros(20))
                failed += int(b.read_state().stale.any())
            sim.faults = FaultSpec()
            assert sim.fault_counts["delayed"] >= 2
            assert failed < 50, (failed, b.stats.summary())
        finally:
            b.close()


def test_whole_reads_return_their_own_snapshot(sim: SimBus, bus: DynamixelBus) -> None:
    """The usual read (every servo's reply intact, no alert) takes a shorter way through
    the driver; what it returns is the same: fresh readings of the emulated servos, the
    counters as they are at return, arrays that belong to that state alone."""
    rig = small_rig()
    first = bus.read_state()  # the first read also fetches the temperatures
    states = [bus.read_state() for _ in range(3)]
    assert bus.last_read_whole  # the last one went the short way
    for k, s in enumerate(states):
        assert not s.stale.any() and (s.age_s == 0).all()
        assert (s.hardware_errors == 0).all() and (s.status_errors == 0).all()
        assert s.stats.reads == first.stats.reads + k + 1
        assert np.isfinite(s.temperatures_c).all()
        np.testing.assert_array_equal(s.temperatures_c, first.temperatures_c)
    assert states[-1].stats.summary() == bus.stats.summary()
    assert states[-1].stats is not bus.stats
    # a caller scribbling on one state changes neither the driver nor the next state
    states[0].positions_deg[:] = 999.0
    states[0].stale[:] = True
    states[0].stats.reads = -1
    nxt = bus.read_state()
    true = np.array([s.ticks_to_deg(sim.servo(s.id).present) for s in rig.servos])
    np.testing.assert_allclose(nxt.positions_deg, true, atol=1e-9)
    assert not nxt.stale.any() and bus.stats.reads == nxt.stats.reads > 0
    for a, b in zip(vars(states[-1]).values(), vars(nxt).values(), strict=True):
        if isinstance(a, np.ndarray):
            assert not np.shares_memory(a, b)
    assert nxt.timestamp_s > states[-1].timestamp_s


@pytest.mark.parametrize("read", [True, False])
def test_servos_move_while_the_bus_is_busy_with_wire_timing(read: bool) -> None:
    """The emulator's housekeeping (kinematic motion, watchdogs) runs in the replies'
    wire time, or once overdue when no reply leaves such time (goal writes only)."""
    rig = RIG  # 20 servos: at 4 Mbps a Fast Sync Read reply takes 420 us of wire
    goals = np.array([0.5 * s.max_deg for s in rig.servos])
    # the servos at 4 Mbps too: a servo answers only at its own Baud Rate
    with SimBus.from_rig(rig, wire_timing=True,
                         bauds={s.id: 4_000_000 for s in rig.servos}) as sim:
        advances: list[float] = []  # when the emulated servos' motion was advanced
        housekeeping = sim._housekeeping

        def spy(now: float) -> None:
            before = sim._last_advance
            housekeeping(now)
            if sim._last_advance != before:
                advances.append(sim._last_advance)

        sim._housekeeping = spy  # type: ignore[method-assign]
        b = DynamixelBus(sim.port_path, rig, baud=4_000_000, read_fields="position")
        b.connect()
        try:
            with b.torque():
                t_end = time.monotonic() + 3.0
                k = 0
                while time.monotonic() < t_end:  # back to back: the bus never idles
                    b.write_goals_deg(goals)
                    if read:
                        b.read_state()
                    else:
                        time.sleep(0.0002)
                    k += 1
                    if k % 50 == 0:
                        with sim.lock:
                            true = np.array([s.ticks_to_deg(sim.servo(s.id).present)
                                             for s in rig.servos])
                        if np.allclose(true, goals, atol=0.2):
                            break
                np.testing.assert_allclose(true, goals, atol=0.2)
                assert b.stats.watchdog_gaps == 0
                # every 2 ms in the replies' wire time; once overdue (10 ms) without replies.
                # The bound with reads only has to tell the first from the second: a full
                # fresh-clone run on a host losing CPU to other guests gave a 4.4 ms median
                step = float(np.median(np.diff(advances[-50:])))
                assert step < (0.006 if read else 0.015), step
        finally:
            b.close()


def test_a_read_the_wire_cannot_carry_by_its_deadline_is_not_sent(sim: SimBus) -> None:
    """On a half-duplex bus a reply still arriving when the next goals go out collides
    with them: a read that cannot fit before its deadline is skipped, its servos stale;
    reads that never fit stop the bus with the reason."""
    rig = small_rig()
    for servo in sim.servos:  # a servo answers only at its own Baud Rate
        servo.set(SimReg.BAUD_RATE, 1)  # 57600
    b = DynamixelBus(sim.port_path, rig, baud=57_600,
                     fault_policy=FaultPolicy(max_stale_reads=3))
    b.connect()
    fsr = 0x8A
    try:
        fresh = b.read_state()
        wire_s = b.read_wire_s(len(rig.servos))  # about 19 ms at 57600 baud
        reads = sim.stats.by_instruction[fsr]
        state = b.read_state(b.clock.now() + 0.5 * wire_s)
        assert state.stale.all() and (state.age_s > 0).all()
        np.testing.assert_array_equal(state.positions_deg, fresh.positions_deg)
        # the goals write_and_read sends first count: the read no longer fits after them
        goal_wire_s = (14 + 5 * len(rig.servos)) * 10 / 57_600
        _, state = b.write_and_read(np.zeros(len(rig.servos)),
                                    b.clock.now() + wire_s + 0.5 * goal_wire_s)
        assert state.stale.all()
        assert sim.stats.by_instruction[fsr] == reads  # no read was sent
        # fewer than max_stale_reads in a row: not a fault
        assert b.stats.skipped_reads == 2 and b.stats.timeouts == 0
        b.clock.sleep(2 * goal_wire_s)  # the goals are off the wire
        assert not b.read_state(b.clock.now() + 2 * wire_s + 0.01).stale.any()
        for _ in range(2):
            assert b.read_state(b.clock.now() + 0.5 * wire_s).stale.all()
        with pytest.raises(DeviceTimeoutError, match="fitted its deadline 3 times in a row"):
            b.read_state(b.clock.now() + 0.5 * wire_s)
    finally:
        b.close()


def test_a_reply_behind_writes_still_on_the_wire_is_waited_for() -> None:
    """Torque-on arms the Bus Watchdogs by two broadcast Sync Writes, then reads them
    back: with wire timing the reply starts only once those writes are off the wire,
    later than the reply gap after the request. It must not count as a timeout.

    Counting the writes wrong times every such read out; a host that stalls the
    emulator's thread for tens of milliseconds (this machine does) times out one now
    and then: of three rounds of three, one must be clean."""
    with SimBus.from_rig(RIG, wire_timing=True) as sim:
        b = DynamixelBus(sim.port_path, RIG, baud=1_000_000, read_fields="position")
        b.connect()
        try:
            rounds = []
            for _ in range(3):
                before = b.stats.timeouts
                stale = 0
                for _ in range(3):
                    with b.torque():
                        b.write_goals_deg(np.zeros(len(RIG.servos)))
                        stale += int(b.read_state().stale.any())
                rounds.append((stale, b.stats.timeouts - before))
                if rounds[-1] == (0, 0):
                    break
            assert rounds[-1] == (0, 0), (rounds, b.stats.summary())
        finally:
            b.close()


def test_after_a_failed_read_the_wait_for_a_quiet_line_counts_against_the_deadline(
    sim: SimBus, bus: DynamixelBus
) -> None:
    """A reply that failed may still be on the wire: the next request waits for a quiet
    line first, so a read that fits only without that wait is not sent."""
    n = len(small_rig().servos)
    sim.faults = FaultSpec(drop=1.0)
    assert bus.read_state(bus.clock.now() + 0.01).stale.all()  # every reply lost
    sim.faults = FaultSpec()
    wire_s = bus.read_wire_s(n)
    sent = bus.stats.reads
    tight = bus.read_state(bus.clock.now() + wire_s + 0.5 * bus.reply_gap_s)
    assert tight.stale.all() and bus.stats.reads == sent and bus.stats.skipped_reads == 1
    # once the line has been quiet that long, the same tight deadline is enough again
    # (counted from the failure, not from each request: no read is kept out for good)
    time.sleep(bus.reply_gap_s)
    assert not bus.read_state(bus.clock.now() + wire_s + 0.5 * bus.reply_gap_s).stale.any()



def test_housekeeping_between_reads_when_due_and_when_the_wire_has_room(sim: SimBus) -> None:
    b = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000, temperature_every=2)
    b.connect()  # its read did the housekeeping: due again 2 reads later
    try:
        b.read_state(b.clock.now() + 0.05)
        assert not b.housekeeping(b.clock.now() + 0.05)  # not due yet
        b.reader.stats.reads += 1  # a read without time for the housekeeping leaves it due
        assert not b.housekeeping(b.clock.now() + 0.0001)  # due, but no room on the wire
        before = sim.stats.by_instruction[0x8A]
        assert b.housekeeping(b.clock.now() + 0.05)
        assert sim.stats.by_instruction[0x8A] - before == 1  # one temperature read
        assert not b.housekeeping(b.clock.now() + 0.05)  # done: not due again
        assert np.isfinite(b.read_state(b.clock.now() + 0.05).temperatures_c).all()
    finally:
        b.close()


def test_housekeeping_waits_for_the_room_it_took_before_but_not_for_ever(sim: SimBus) -> None:
    from handrig.devices.servo.reader import HOUSEKEEPING_FORCE_S

    b = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000, temperature_every=2)
    b.connect()  # its read did the housekeeping, and timed it
    try:
        r = b.reader
        assert r._housekeeping_s > 0.0
        r.stats.reads += 2  # due again
        r._housekeeping_s = 0.2  # as if it had taken 200 ms on this bus
        assert not b.housekeeping(b.clock.now() + 0.05)  # the wire has room; the past not
        assert r._housekeeping_due() and r._housekeeping_due_at is not None
        r._housekeeping_due_at -= HOUSEKEEPING_FORCE_S  # put off for a second: it runs
        assert b.housekeeping(b.clock.now() + 0.05)
        assert not r._housekeeping_due() and r._housekeeping_s < 0.2
    finally:
        b.close()


def test_a_retry_starts_only_with_room_for_what_requests_have_taken_here(
        sim: SimBus, bus: DynamixelBus) -> None:
    reader = bus.reader
    assert not bus.read_state().stale.any()
    assert reader._attempt_extra_s >= 0.0  # learnt from the answered request
    reader._attempt_extra_s = 0.0  # answers as fast as the wire
    sim.servo(3).silent_until = math.inf  # one servo silent: every read fails on it
    time.sleep(0.01)
    before = bus.stats.retries
    bus.read_state(bus.clock.now() + 0.1)  # room for a retry
    assert bus.stats.retries > before
    time.sleep(0.01)
    reader._attempt_extra_s = 1.0  # as if answers took a second here
    before = bus.stats.retries
    state = bus.read_state(bus.clock.now() + 0.1)
    assert bus.stats.retries == before  # the wire has room; what it has taken does not
    assert state.stale.any()
    sim.servo(3).silent_until = 0.0


def test_a_read_of_one_part_asks_only_those_servos_and_marks_only_them(
        sim: SimBus, bus: DynamixelBus) -> None:
    first = bus.read_state()
    assert first.all_fresh and first.asked is None
    sim.servo(5).silent_until = math.inf  # rig index 4: in part 0 of 2 (indices 0, 2, 4)
    time.sleep(0.01)
    odd = bus.read_state(part=(1, 2))  # indices 1, 3, 5: servo 5 is not asked
    assert odd.asked.tolist() == [False, True, False, True, False, True]
    assert not odd.stale.any()
    assert odd.age_s[[1, 3, 5]].max() < odd.age_s[[0, 2, 4]].min()  # the others are older
    even = bus.read_state(part=(0, 2))
    assert even.asked.tolist() == [True, False, True, False, True, False]
    assert even.stale.tolist() == [False, False, False, False, True, False]
    assert even.positions_deg[4] == first.positions_deg[4]  # the last good value
    assert bus.stats.stale_readings.tolist() == [0, 0, 0, 0, 1, 0]
    sim.servo(5).silent_until = 0.0
    # a part read is shorter on the wire than a whole one
    reader = bus.reader
    assert reader.read_wire_s(3) < reader.read_wire_s(6)
    with pytest.raises(ValueError, match="read parts"):
        bus.read_state(part=(0, 7))



WARM_UP_CHECK = """
import numpy as np
from handrig.devices.servo import DynamixelBus, codec
from sim.dxl_bus import SimBus
from tests.handrig.devices.servo.test_servo_bus import small_rig

kernels = {n: k for n in dir(codec) if hasattr(k := getattr(codec, n), "signatures")}
with SimBus.from_rig(small_rig()) as sim:
    bus = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000)
    bus.connect()  # warms the kernels up
    before = {n: len(k.signatures) for n, k in kernels.items()}
    assert before["fast_sync_whole"] and before["fast_sync_take"] and before["goal_packet"]
    with bus.torque():
        bus.write_goals_deg(np.zeros(6))
        whole = bus.read_state()
        assert bus.reader.last_whole  # the whole-reply kernel took it
        part = bus.read_state(part=(1, 2))
    bus.close()
assert whole.all_fresh and not part.stale.any()
print({n: [str(s) for s in k.signatures[before[n]:]] for n, k in kernels.items()
       if len(k.signatures) > before[n]})
"""


def test_reads_and_writes_compile_nothing_after_the_warm_up() -> None:
    """The bus warms every kernel with the argument types the driver passes, at
    connect: a kernel compiled (or loaded from the cache) at the first real read would
    cost that cycle milliseconds, and a 500 Hz glove's frames pile up meanwhile. In a
    process of its own, so that no earlier test has compiled them already."""
    out = subprocess.run([sys.executable, "-c", WARM_UP_CHECK], capture_output=True,
                         text=True, timeout=120, cwd=Path(__file__).resolve().parents[4])
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "{}"


def test_a_write_the_port_never_drains_ends_at_its_deadline_naming_the_port() -> None:
    master, slave = os.openpty()  # nobody reads the master: a wedged adapter
    path = os.ttyname(slave)
    clock = FakeClock(0.0)
    t = SerialTransport(path, 1_000_000, clock)
    t.open()
    try:
        with pytest.raises(DeviceTimeoutError, match=f"{path} took no bytes.*stopped draining"):
            for _ in range(10_000):
                t.write(bytes(114))  # a goal Sync Write to 20 servos
        assert t.wedged
        assert clock.now() >= 0.2  # waited its deadline, no longer than a few polls more
        assert clock.now() < 0.3
    finally:
        started = time.monotonic()
        t.close()  # the bytes still queued are dropped: closing does not wait on them
        assert time.monotonic() - started < 1.0
        os.close(slave)
        os.close(master)


def test_torque_off_on_a_bus_that_stopped_answering_is_bounded_and_names_the_servos(
        sim: SimBus, bus: DynamixelBus) -> None:
    started = math.nan
    with (pytest.raises(DeviceError, match="torque off failed") as info,
          bus.torque(handle_signals=False)):
        sim.faults = FaultSpec(drop=1.0)
        started = time.monotonic()
    took = time.monotonic() - started
    sim.faults = FaultSpec()
    assert took < 1.5, f"torque off took {took:.2f} s"
    text = str(info.value)
    for s in small_rig().servos:
        assert f"servo {s.id} ({s.joint})" in text
    # the broadcast reached them all the same
    assert not any(sim.servo(s.id).torque_enabled for s in small_rig().servos)


def _silence_by_sync_write(port: str, servo_id: int) -> None:
    """Status Return Level 0 on one servo, by a Sync Write from another opener of the
    port (how the issue silenced a servo mid-run): it still obeys, never replies."""
    fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
    try:
        os.write(fd, dx.build_instruction(
            dx.BROADCAST_ID, dx.Instruction.SYNC_WRITE,
            dx.sync_write_params(dx.Reg.STATUS_RETURN_LEVEL, 1, [(servo_id, bytes([0]))])))
    finally:
        os.close(fd)


@pytest.mark.parametrize("parts", [1, 2], ids=["whole", "parts"])
def test_one_silent_servo_mid_chain_costs_that_servo_only(parts: int) -> None:
    rig = load_rig_config()  # 20 servos; servo 7 sits mid-chain
    silent = [s.id for s in rig.servos].index(7)
    with SimBus.from_rig(rig) as sim:
        bus = DynamixelBus(sim.port_path, rig, baud=rig.bus.baud, temperature_every=0)
        bus.connect()
        try:
            def read(k: int) -> ServoState:
                # a deadline with room for one read of the servos asked and no retry,
                # as the loop fits its reads between glove frames
                n = len(bus.reader.part_indices((k % parts, parts)))
                now = bus.clock.now()
                start = max(now, bus.link.request_start(now))
                return bus.read_state(start + bus.read_wire_s(n) + 0.002,
                                      part=(k % parts, parts) if parts > 1 else None)

            for k in range(10):
                assert not read(k).stale.any()
            sim_servo = sim.servo(7)
            _silence_by_sync_write(sim.port_path, 7)
            deadline = time.monotonic() + 5
            while sim_servo.status_return_level != 0:
                assert time.monotonic() < deadline
                time.sleep(0.001)
            stale = np.zeros(len(rig.servos), np.int64)
            its_reads = 0
            for k in range(10, 10 + 40 * parts):
                state = read(k)
                # a read the host was too late to send (a loaded machine) asks nobody
                asked = state.stale if state.asked is None else state.stale[state.asked]
                # a read whose reply came after its deadline (a loaded machine) got
                # nobody: the host's lateness, not the silent servo's
                if k >= 10 + 4 * parts and state.sent and not asked.all():
                    stale += state.stale
                    its_reads += bool(state.asked is None or state.asked[silent])
            others = np.delete(stale, silent)
            assert its_reads >= 25 and stale[silent] == its_reads
            assert not others.any(), f"servos after it starved: {others.tolist()}"
            assert bus.stats.partial_replies > 0  # its cut replies were seen for what they are
            assert bus.stats.chain_ends > 0
            assert bus.stats.fallbacks == 0
            # it answers again: asked at the end of the chain, it is read at once
            sim_servo.mem[dx.Reg.STATUS_RETURN_LEVEL] = 2
            state = read(silent % parts)
            for _ in range(5):  # a read the host was too late to send asks nobody
                if state.sent:
                    break
                state = read(silent % parts)
            assert not state.stale.any()
        finally:
            bus.close()


def test_a_silent_servo_does_not_end_the_run_when_tripped_watchdogs_are_rearmed(
        sim: SimBus) -> None:
    rig = small_rig()
    b = DynamixelBus(sim.port_path, rig, baud=1_000_000, temperature_every=1)
    b.connect()
    try:
        with b.torque():
            sim.servo(3).mem[dx.Reg.STATUS_RETURN_LEVEL] = 0  # hears, obeys, never answers
            time.sleep(0.3)  # the host "hangs": every servo's watchdog (100 ms) trips
            # the re-arm's checked writes get no answer from servo 3: left to the loop's
            # silence tiers, not a DeviceTimeoutError ending the run
            b.read_state(b.clock.now() + 0.2)
            assert b.stats.watchdog_trips >= 1 and b.torque_enabled
            sim.servo(3).mem[dx.Reg.STATUS_RETURN_LEVEL] = 2  # its torque-off confirmed
    finally:
        b.close()


def test_a_servo_port_in_use_is_reported_busy(sim: SimBus) -> None:
    first = SerialTransport(sim.port_path, 1_000_000, FakeClock(0.0))
    first.open()
    try:
        second = SerialTransport(sim.port_path, 1_000_000, FakeClock(0.0))
        with pytest.raises(DeviceError, match=f"servo port {sim.port_path} is busy.*fuser"):
            second.open()
        assert not second.is_open
    finally:
        first.close()
    again = SerialTransport(sim.port_path, 1_000_000, FakeClock(0.0))
    again.open()  # free once closed
    again.close()


def test_a_silent_servo_does_not_starve_the_temperature_reads_of_those_after_it() -> None:
    rig = load_rig_config()  # 20 servos; servo 7 sits mid-chain
    silent = [s.id for s in rig.servos].index(7)
    with SimBus.from_rig(rig) as sim:
        bus = DynamixelBus(sim.port_path, rig, baud=rig.bus.baud, temperature_every=0)
        bus.connect()
        try:
            sim.servo(7).mem[dx.Reg.STATUS_RETURN_LEVEL] = 0
            for _ in range(4):  # found out: the reads' replies stop at it
                bus.read_state(bus.clock.now() + 0.05)
            assert bus.reader.suspect[silent] >= 2
            bus.reader.temperature_every = 1
            state = bus.read_state(bus.clock.now() + 0.2)
            for _ in range(5):  # a loaded machine may leave no room for it at once
                if np.isfinite(np.delete(state.temperatures_c, silent)).all():
                    break
                state = bus.read_state(bus.clock.now() + 0.2)
            temps = state.temperatures_c
            assert np.isfinite(np.delete(temps, silent)).all(), temps.tolist()
            assert np.isnan(temps[silent])
            sim.servo(7).mem[dx.Reg.STATUS_RETURN_LEVEL] = 2  # its torque-off confirmed
        finally:
            bus.close()


def test_a_patient_read_waits_for_late_replies_the_loops_read_does_not() -> None:
    """Replies 15 ms late (a loaded machine, a USB adapter's latency timer): the loop's
    read gives up at its reply deadline and marks the servos stale; a patient read (the
    robot API's) waits for them until its own deadline and has every reading."""
    rig = small_rig()
    with SimBus.from_rig(rig) as sim:
        bus = DynamixelBus(sim.port_path, rig, baud=1_000_000, temperature_every=0)
        bus.connect()
        try:
            assert not bus.read_state(bus.clock.now() + 0.1, patient=True).stale.any()
            sim.faults = FaultSpec(delay=1.0, delay_s=0.015)  # every reply late
            impatient = bus.read_state(bus.clock.now() + 0.1)
            assert impatient.stale.all()
            time.sleep(0.05)  # the late replies of that read have come and gone
            bus.link.quiet_line(bus.clock.now() + 0.05)
            t0 = time.monotonic()
            patient = bus.read_state(bus.clock.now() + 0.1, patient=True)
            took = time.monotonic() - t0
            assert not patient.stale.any() and took >= 0.015
        finally:
            sim.faults = FaultSpec()
            bus.close()
