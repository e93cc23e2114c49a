"""Outputs: VMC bundle and OpenXR hand-joint encode/send cost per frame (side by side,
alternated in one run), recorder add/close, performance load."""

from __future__ import annotations

import socket
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from pythonosc import osc_bundle_builder, osc_message_builder

from handrig import hand
from handrig.clock import FakeClock
from handrig.outputs import openxr, vmc
from handrig.outputs.recorder import Recorder, load_performance
from handrig.pose.openxr_hand import OpenXrHand


def _per_call_us(fn: Callable[[], object], n: int) -> tuple[float, float]:
    """(median, p99) of n timed calls, microseconds."""
    dt = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        fn()
        dt[i] = time.perf_counter() - t0
    return float(np.median(dt) * 1e6), float(np.percentile(dt, 99) * 1e6)


def _python_osc_bundle(quats: np.ndarray, t_s: float) -> bytes:
    b = osc_bundle_builder.OscBundleBuilder(osc_bundle_builder.IMMEDIATELY)
    for bone, q in zip(vmc.BONES, quats, strict=True):
        m = osc_message_builder.OscMessageBuilder("/VMC/Ext/Bone/Pos")
        m.add_arg(bone.name)
        for x in (*bone.offset_m, *q):
            m.add_arg(float(x))
        b.add_content(m.build())
    return b.build().dgram


def _openxr_beside_vmc(pose: np.ndarray, wrist: np.ndarray, n: int) -> None:
    """One frame sent by each output (its whole work on the loop's thread: encode and
    UDP sendto to localhost), the two alternated call by call so both see the same
    machine; and one hand's 26 joints alone."""
    full = np.concatenate([pose, wrist])
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sink:
        sink.bind(("127.0.0.1", 0))
        sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        port = sink.getsockname()[1]
        clock = FakeClock()
        with (vmc.VmcSender("127.0.0.1", port, rate_hz=1e9, clock=clock) as v_tx,
              openxr.OpenXrSender("127.0.0.1", port, rate_hz=1e9, clock=clock) as x_tx):
            hand = OpenXrHand("ri")
            out = np.empty((26, 7))
            dt = np.empty((3, n))
            for i in range(n):
                clock.advance(1.0)
                t0 = time.perf_counter()
                v_tx(1.0, full)
                t1 = time.perf_counter()
                x_tx(1.0, full)
                t2 = time.perf_counter()
                hand.compute(pose[:25], wrist[:2], out=out)
                dt[:, i] = (t1 - t0, t2 - t1, time.perf_counter() - t2)
            assert v_tx.errors == 0 and x_tx.errors == 0
    us = dt * 1e6
    print(f"one frame sent, alternated ({n} each): VMC {len(v_tx.encode(pose, wrist, 0.0))}"
          f" bytes in one bundle; OpenXR 2 x {openxr.DATAGRAM_BYTES} bytes (a datagram a hand)")
    for name, row in (("VMC send (32 bone quaternions + OSC)", us[0]),
                      ("OpenXR send (2 hands x 26 joints)", us[1]),
                      ("  of which one hand's 26 joints", us[2])):
        print(f"  {name:38s} min {row.min():6.1f} us, median {np.median(row):6.1f} us,"
              f" p99 {np.percentile(row, 99):6.1f} us")


def main() -> None:
    rng = np.random.default_rng(0)
    lim = hand.curve_limits_deg()
    pose = rng.uniform(lim[:, 0], lim[:, 1])
    wrist = np.array([10.0, -5.0, 3.0, 2.0])
    n = 3000

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sink:
        sink.bind(("127.0.0.1", 0))
        sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        port = sink.getsockname()[1]
        clock = FakeClock()
        with vmc.VmcSender("127.0.0.1", port, rate_hz=1e9, clock=clock) as sender:
            size = len(sender.encode(pose, wrist, 0.0))
            v = np.concatenate([pose, wrist, [0.0]])
            q_med, q_p99 = _per_call_us(lambda: vmc.bone_quaternions(v), n)
            e_med, e_p99 = _per_call_us(lambda: sender.encode(pose, wrist, 1.0), n)

            def send() -> None:
                clock.advance(1.0)
                sender.send(pose, wrist, 1.0)

            s_med, s_p99 = _per_call_us(send, n)
            skip = vmc.VmcSender("127.0.0.1", port, rate_hz=60, clock=FakeClock())
            skip.send(pose, wrist, 0.0)
            k_med, _ = _per_call_us(lambda: skip.send(pose, wrist, 0.0), n)
            skip.close()
            quats = vmc.bone_quaternions(v)
            o_med, _ = _per_call_us(lambda: _python_osc_bundle(quats, 1.0), 300)
    print(f"VMC bundle: {len(vmc.BONES)} bones, {size} bytes")
    print(f"  pose -> 32 bone quaternions (numpy): median {q_med:6.1f} us, p99 {q_p99:6.1f} us")
    print(f"  full encode (quaternions + OSC):      median {e_med:6.1f} us, p99 {e_p99:6.1f} us")
    print(f"  send (encode + UDP sendto localhost): median {s_med:6.1f} us, p99 {s_p99:6.1f} us")
    print(f"  send skipped by the rate limit:       median {k_med:6.2f} us")
    print(f"  (python-osc builders for the same bones: median {o_med:.0f} us)")
    _openxr_beside_vmc(pose, wrist, n)

    frames = 12_000  # 60 s at 200 Hz
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in ("csv", "bvh"):
            path = Path(tmp) / f"take.{fmt}"
            rec = Recorder(path, rate_hz=200.0)
            dt = np.empty(frames)
            for i in range(frames):
                t0 = time.perf_counter()
                rec.add(i / 200.0, pose, wrist)
                dt[i] = time.perf_counter() - t0
            t0 = time.perf_counter()
            rec.close()
            close_s = time.perf_counter() - t0
            t0 = time.perf_counter()
            load_performance(path)
            load_s = time.perf_counter() - t0
            mb = path.stat().st_size / 1e6
            print(f"recorder {fmt}: add median {np.median(dt) * 1e6:.2f} us,"
                  f" p99 {np.percentile(dt, 99) * 1e6:.2f} us, max {dt.max() * 1e6:.0f} us;"
                  f" 60 s at 200 Hz: close (write) {close_s:.2f} s, {mb:.1f} MB,"
                  f" load {load_s:.2f} s")
