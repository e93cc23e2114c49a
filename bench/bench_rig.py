"""The realtime path, measured end to end on the simulated rig.

A glove emulator (subprocess, 200 Hz handrig frames on a pty) feeds the real
SerialGlove reader, pipeline and Dynamixel driver, which drive 20 emulated
servos of ``handrig sim-bus`` (MuJoCo puppet, wire timing at 1 Mbps). Prints
loop rate, jitter, host latency from a glove frame's last byte read to the Sync
Write handed to the OS (percentiles, from the loop's fixed-size histograms),
where that latency goes stage by stage, overruns and tracking.

Targets: latency median <= 100 us, p99 <= 300 us; 200 Hz with no overruns over
60 s. ``HANDRIG_BENCH_QUICK=1`` runs 10 s instead of 60 s.
"""

from __future__ import annotations

import os

from handrig.app import build_parts, port_process
from handrig.live import LiveOptions, run_live
from sim.demo_recording import DEMO_RECORDING


def main() -> None:
    seconds = 10.0 if os.environ.get("HANDRIG_BENCH_QUICK") else 60.0
    parts = build_parts()
    rate = parts.rig_config.loop.rate_hz
    n = len(parts.rig_config.servos)
    baud = parts.rig_config.bus.baud
    with port_process(["sim-glove", str(DEMO_RECORDING), "--rate", "200", "--loop"],
                      "the glove emulator") as (_, glove_port):
        result = run_live(parts, LiveOptions(glove=glove_port, bus="sim", profile=True,
                                             duration_s=seconds, log=lambda s: None))
    s = result.summary
    lat = s["latency_us"]
    print(f"rig loop: {n} servos, {baud} baud (wire timing on), target {rate:g} Hz, "
          f"{seconds:g} s")
    print(f"  rate            {s['rate_hz']} Hz over {s['frames']} cycles "
          f"(jitter {s['jitter_us']} us)")
    print(f"  overruns        {s['overruns']} (max {s['overrun_max_us']} us late, "
          f"{s['missed_cycles']} cycles missed)")
    print(f"  latency         p50 {lat['p50']} us, p99 {lat['p99']} us, max {lat['max']} us "
          f"over {lat['samples']} glove frames (target p50 <= 100, p99 <= 300)")
    stages = ", ".join(f"{k} {v['p50']}" for k, v in s.get("stages_us", {}).items())
    print(f"  where (p50 us)  {stages}")
    print(f"  tracking        rms {s['tracking_rms_deg']} deg (present vs goal), "
          f"stale reads {s['stale_reads']}/{s['reads']}")
    print(f"  glove           {s['glove']}")
    print(f"  stopped         {s['stop_reason']}" + (f" (error: {s['error']})" if "error" in s
                                                      else ""))
    print(f"  torque off      {s['torque_off']}")


if __name__ == "__main__":
    main()
