"""Cues over OSC: the loop's cycle with a client firing 1,000 messages a second, beside none,
and how long a cue takes to act.

Each case is a live run on the simulated rig (the demo glove recording streamed at 200 Hz
by ``handrig sim-glove`` in a process of its own, the MuJoCo loopback bus at the rig
file's baud), alternated ``HANDRIG_BENCH_ROUNDS`` times (default 3) so the machine's load
falls on every case alike:

* ``none``: no ``--osc-in``;
* ``osc idle``: ``--osc-in`` bound, nothing sent;
* ``osc 1k/s``: a client in a process of its own sends 1,000 datagrams a second to the
  port (``/handrig/level`` with a float, an address cues do not know: each parsed,
  counted and ignored: the receiving thread's whole load, none of it an action);
* ``osc 1k/s + cues``: the same flood, and every 0.25 s a ``/handrig/relax`` or
  ``/handrig/resume`` from this process: the cue -> action latency, from the
  datagram's send to the loop acting on it (the mode machine's event line, told from
  the loop's thread), p50/p99/max over the run's cues.

Per case: the loop's latency (glove frame's arrival -> Sync Write handed to the OS)
p50/p99, its compute p50/p99, the loop thread's CPU per cycle, overruns, and the
messages the cue port counted. ``HANDRIG_BENCH_SECONDS`` sets each run's length
(default 10 s).
"""

from __future__ import annotations

import os
import socket
import statistics
import subprocess
import sys
import threading
import time
from typing import Any

import numpy as np

from handrig.app.cues.live import CueOptions
from handrig.app.cues.osc import encode_message
from handrig.app.parts import build_parts
from handrig.app.port_processes import PortProcess
from handrig.app.session import LiveOptions, run_live
from sim.demo_recording import DEMO_RECORDING

CASES = ("none", "osc idle", "osc 1k/s", "osc 1k/s + cues")
FLOOD_HZ = 1000.0
CUE_EVERY_S = 0.25

FLOOD = """
import socket, sys, time
port, hz = int(sys.argv[1]), float(sys.argv[2])
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
msg = bytes.fromhex(sys.argv[3])
period, t = 1.0 / hz, time.monotonic()
while True:
    t += period
    delay = t - time.monotonic()
    if delay > 0:
        time.sleep(delay)
    try:
        s.sendto(msg, ("127.0.0.1", port))
    except OSError:
        pass
"""


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run_case(case: str, seconds: float) -> dict[str, Any]:
    parts = build_parts()
    port = _free_port()
    acted: list[tuple[str, float]] = []

    running = threading.Event()

    def log(text: str) -> None:
        if text.startswith("first frame"):
            running.set()
        if text.startswith(("relax (OSC):", "resume (OSC):")):
            acted.append((text.split(" ", 1)[0], time.monotonic()))

    sent: list[tuple[str, float]] = []
    stop = threading.Event()

    def cues() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            k = 0
            while not running.wait(0.05):  # the loop runs: the port is open
                if stop.is_set():
                    return
            end = time.monotonic() + seconds - 1.0  # none while the run ends
            while not stop.wait(CUE_EVERY_S) and time.monotonic() < end:
                what = ("relax", "resume")[k % 2]
                sent.append((what, time.monotonic()))
                s.sendto(encode_message(f"/handrig/{what}"), ("127.0.0.1", port))
                k += 1

    flood = None
    if case.startswith("osc 1k/s"):
        flood = subprocess.Popen([sys.executable, "-c", FLOOD, str(port), str(FLOOD_HZ),
                                  encode_message("/handrig/level", 0.5).hex()])
    prober = threading.Thread(target=cues, daemon=True) if case.endswith("cues") else None
    try:
        with PortProcess(["sim-glove", str(DEMO_RECORDING), "--rate", "200"],
                         "the glove emulator") as glove:
            opts = LiveOptions(
                glove=glove.port(), bus="sim", duration_s=seconds, panel=False, log=log,
                cues=CueOptions(osc_in=f"127.0.0.1:{port}") if case != "none" else None)
            if prober is not None:
                prober.start()
            result = run_live(parts, opts)
    finally:
        stop.set()
        if flood is not None:
            flood.kill()
            flood.wait()
    if result.error is not None:
        raise result.error
    s = result.summary
    lat = []
    for what, t_sent in sent:  # each cue's first action after it was sent
        after = [t for w, t in acted if w == what and t >= t_sent]
        if after:
            lat.append((min(after) - t_sent) * 1e6)
    return {"latency_us": s["latency_us"], "compute_us": s["compute_us"],
            "cpu_per_cycle_us": s["cpu_per_cycle_us"], "overruns": s["overruns"],
            "frames": s["frames"], "cues": s.get("cues", {}), "cue_us": lat,
            "sent": len(sent)}


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", "10"))
    rounds = int(os.environ.get("HANDRIG_BENCH_ROUNDS", "3"))
    load = os.getloadavg()
    print(f"cues bench: {rounds} rounds x {len(CASES)} cases of {seconds:g} s, alternated; "
          f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    results: dict[str, list[dict[str, Any]]] = {c: [] for c in CASES}
    for r in range(rounds):
        order = CASES if r % 2 == 0 else tuple(reversed(CASES))
        for case in order:
            results[case].append(run_case(case, seconds))
    print(f"{'case':<17} {'lat p50':>8} {'lat p99':>8} {'cmp p50':>8} {'cmp p99':>8} "
          f"{'cpu/cyc':>8} {'overr':>5} {'recv':>7} {'acted':>5}   (us; each the median "
          "of the rounds, min in brackets)")
    for case in CASES:
        runs = results[case]

        def col(get: Any, runs: list[dict[str, Any]] = runs) -> str:
            values = [float(get(x)) for x in runs]
            return f"{statistics.median(values):.0f}({min(values):.0f})"
        recv = sum(int(x["cues"].get("received", 0)) for x in runs)
        acted = sum(int(x["cues"].get("acted", 0)) for x in runs)
        print(f"{case:<17} {col(lambda x: x['latency_us']['p50']):>8} "
              f"{col(lambda x: x['latency_us']['p99']):>8} "
              f"{col(lambda x: x['compute_us']['p50']):>8} "
              f"{col(lambda x: x['compute_us']['p99']):>8} "
              f"{col(lambda x: x['cpu_per_cycle_us']):>8} "
              f"{sum(int(x['overruns']) for x in runs):>5} {recv:>7} {acted:>5}")
    cue_us = np.array([v for x in results["osc 1k/s + cues"] for v in x["cue_us"]])
    sent = sum(x["sent"] for x in results["osc 1k/s + cues"])
    if len(cue_us):
        p50, p99 = np.percentile(cue_us, [50, 99])
        print(f"cue -> action (datagram sent -> the loop acts, under the 1k/s flood): "
              f"p50 {p50:.0f} us, p99 {p99:.0f} us, max {cue_us.max():.0f} us over "
              f"{len(cue_us)} of {sent} cues")


if __name__ == "__main__":
    main()
