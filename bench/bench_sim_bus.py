"""The Dynamixel bus emulator's own cost: host time per packet, reply timing.

1. Host time to take one packet and prepare its reply (frame, CRC, dispatch,
   reply CRC), called directly: Sync Write of Goal Position and Fast Sync Read
   of Present Position for 20 servos, and a ping; through the pure-Python packet
   path and the compiled one (sim/_dxl_c.c, where built).
2. Over the pty, wire timing off: ping and Fast Sync Read round trips (pyserial
   client in this process; the emulator thread shares its interpreter).
3. Wire timing on, plain dynamixel-sdk client in this process, MuJoCo puppet on:
   Sync Write + Fast Sync Read cycles per second against the wire-time limit,
   and how late replies left after their wire-time instant.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable

import numpy as np

from firmware_protocol import dynamixel as dx
from handrig.config.rig import load_rig_config
from handrig.config.rig_files import SHIPPED_RIG
from handrig.devices.servo.positions import deg_to_ticks
from sim.dxl_bus import SimBus
from sim.dxl_servo import EmulatedServo

N_SERVOS = 20


def _per_call_us(call: Callable[[], None], n: int) -> float:
    t0 = time.perf_counter()
    for _ in range(n):
        call()
    return (time.perf_counter() - t0) / n * 1e6


def host_time() -> None:
    ids = list(range(1, N_SERVOS + 1))
    bus = SimBus([EmulatedServo(i) for i in ids])
    goal = (2100).to_bytes(4, "little")
    packets = {
        "ping": dx.build_instruction(1, dx.Instruction.PING),
        f"sync write goal x{N_SERVOS}": dx.build_instruction(
            dx.BROADCAST_ID, dx.Instruction.SYNC_WRITE,
            dx.sync_write_params(116, 4, [(i, goal) for i in ids]), do_stuff=False),
        f"fast sync read position x{N_SERVOS}": dx.build_instruction(
            dx.BROADCAST_ID, dx.Instruction.FAST_SYNC_READ,
            dx.sync_read_params(132, 4, ids), do_stuff=False),
    }
    now = time.perf_counter()
    # the bus's own path for a packet off the line (frame, CRC, dispatch, reply), its
    # reply's wire wait left out; the packet path pure Python and, where sim/_dxl_c.c was
    # built, compiled (a tree from before it has one path: both lines are the same)
    bus.wire_timing = True
    bus._send = lambda replies, frame_len, t_rx: None  # type: ignore[method-assign]
    bus._last_advance = float("inf")  # no housekeeping in the packet's path
    for compiled in (False, True):
        bus.compiled = compiled
        print(f"host time per packet (frame, CRC, dispatch, reply), no pty, "
              f"{'compiled' if compiled else 'pure Python'} packet path, best of 5:")
        for name, frame in packets.items():

            def handle(frame: bytes = frame) -> None:
                bus._handle_frame(frame, now)

            handle()
            best = min(_per_call_us(handle, 1000) for _ in range(5))
            print(f"  {name:<32} {best:7.1f} us")


def round_trips() -> None:
    import serial

    ids = list(range(1, N_SERVOS + 1))
    with SimBus([EmulatedServo(i) for i in ids]) as bus:
        ser = serial.Serial(bus.port_path, baudrate=1_000_000, timeout=0)
        cases = {
            "ping": (dx.build_instruction(1, dx.Instruction.PING), 14),
            f"fast sync read x{N_SERVOS}": (dx.build_instruction(
                dx.BROADCAST_ID, dx.Instruction.FAST_SYNC_READ,
                dx.sync_read_params(132, 4, ids), do_stuff=False), 8 + 8 * N_SERVOS),
        }
        print("round trip over the pty, wire timing off (client in the same process):")
        for name, (packet, want) in cases.items():
            times = []
            for _ in range(500):
                t0 = time.perf_counter()
                ser.write(packet)
                got = 0
                while got < want:
                    got += len(ser.read(want - got))
                times.append(time.perf_counter() - t0)
            arr = np.array(times) * 1e6
            print(f"  {name:<32} median {np.median(arr):6.0f} us, p99 "
                  f"{np.percentile(arr, 99):6.0f} us")
        ser.close()


def wire_timed_cycles(seconds: float = 1.5) -> None:
    from dynamixel_sdk import GroupSyncRead, GroupSyncWrite, PacketHandler, PortHandler

    rig = load_rig_config(SHIPPED_RIG)
    n = len(rig.servos)
    print(f"wire timing on, plain SDK Sync Write + Fast Sync Read, {n} servos, puppet on:")
    for baud in (1_000_000, 4_000_000):
        # the servos at the client's rate: a servo answers only at its own Baud Rate
        with SimBus.from_rig(rig, puppet=True, wire_timing=True,
                             bauds={s.id: baud for s in rig.servos}) as bus:
            port = PortHandler(bus.port_path)
            port.openPort()
            port.setBaudRate(baud)
            ph = PacketHandler(2.0)
            for s in rig.servos:
                ph.write1ByteTxRx(port, s.id, 9, 0)
                ph.write1ByteTxRx(port, s.id, 64, 1)
            sw = GroupSyncWrite(port, ph, 116, 4)
            fsr = GroupSyncRead(port, ph, 132, 4)
            for s in rig.servos:
                sw.addParam(s.id, deg_to_ticks(s, 10.0).to_bytes(4, "little"))
                fsr.addParam(s.id)
            bus.stats.late_total_s = bus.stats.late_max_s = 0.0
            bus.stats.replies = 0
            cycles = 0
            failed: Counter[str] = Counter()
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < seconds:
                sw.txPacket()
                result = fsr.fastSyncRead()
                if result != 0:
                    failed[ph.getTxRxResult(result)] += 1
                cycles += 1
            hz = cycles / (time.perf_counter() - t0)
            port.closePort()
            wire_bytes = (14 + 5 * n) + (14 + n) + (8 + 8 * n)
            limit_hz = baud / (10 * wire_bytes)
            st = bus.stats
            print(f"  {baud / 1e6:.0f} Mbps: {hz:6.0f} cycles/s, wire limit {limit_hz:6.0f} "
                  f"({hz / limit_hz:4.2f}), failed {sum(failed.values())}"
                  f"{' ' + str(dict(failed)) if failed else ''}; "
                  f"replies late by mean "
                  f"{st.late_mean_s * 1e6:.0f} us, max {st.late_max_s * 1e6:.0f} us")


def main() -> None:
    host_time()
    round_trips()
    wire_timed_cycles()


if __name__ == "__main__":
    main()
