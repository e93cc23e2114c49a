"""What the live view costs the loop: the rig at 200 Hz / 1 Mbps without ``--view``
and with it and two pages connected, side by side in one run.

The rig is :mod:`bench.bench_rig`'s (the real rig between the glove and bus
emulators in processes of their own, 20 servos with wire timing) in the default
rig's glove-triggered mode with a 200 Hz glove. The cases, in turn, each round:
no view; the view with two WebSocket clients reading every frame (the view's own
cost); the view with two headless chromium pages (which draw in software, with
SwiftShader, on the same two cores as the rig and its emulated servos); and the same
pages under the idle scheduling class (``chrt --idle 0``: they get only the CPU
the rig and the emulators leave). Reported per round and pooled over rounds:
end-to-end latency in the process (frame arrival to Sync Write handed to the OS)
and from outside (glove emulator send to the bus emulator's receipt), p50/p99;
the rig process's CPU; the view's CPU (its feeder thread in the rig's process,
its own process); the pages' own CPU; frames encoded,
sent and skipped by slow pages.

Browsers: Debian's chromium through chromium-driver (``make browser-deps``); where
they are missing the chromium cases are left out and the output says so.
``HANDRIG_BENCH_SECONDS`` sets each round's length (default 20 s; QUICK: 8 s),
``HANDRIG_BENCH_ROUNDS`` the rounds (default 2).
"""

from __future__ import annotations

import contextlib
import os
import resource
import shutil
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from bench.bench_rig import (
    INDEX_CHANNEL,
    _glove_file,
    _rig_file,
    emulator,
    outside_latencies,
    step_recording,
)
from handrig.app.factory import build_parts
from handrig.app.session import LiveOptions, run_live
from handrig.app.view.process import ViewProcess
from handrig.devices.glove_recording import write_glove_recording

RATE_HZ = 200.0
BAUD = 1_000_000
CLK_TCK = os.sysconf("SC_CLK_TCK")


def thread_cpu_s(tid: int | None) -> float:
    """CPU seconds (user + system) of one thread of this process so far."""
    if tid is None:
        return 0.0
    try:
        fields = Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def pid_cpu_s(pid: int | None) -> float:
    """CPU seconds (user + system) of process ``pid`` so far."""
    if pid is None:
        return 0.0
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def process_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def chromium_cpu_s(marker: str) -> float:
    """CPU seconds so far of the processes whose command line holds ``marker`` (the
    pages' own profile folder: their browser, renderer and GPU processes)."""
    total = 0.0
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            if marker.encode() not in (proc / "cmdline").read_bytes():
                continue
            fields = (proc / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += (int(fields[11]) + int(fields[12])) / CLK_TCK
    return total


def chromium_available() -> bool:
    return bool(shutil.which("chromium") and shutil.which("chromedriver"))


@contextlib.contextmanager
def browsers(url: str, n: int, folder: Path, real: bool, idle: bool = False
             ) -> Iterator[str]:
    """``n`` pages on ``url``: headless chromium (``real``; ``idle``: under the idle
    scheduling class, ``chrt --idle 0``), else WebSocket clients that read every
    frame; yields what they are."""
    chromium, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if real and chromium and driver:
        if idle:
            wrapper = folder / "chromium-idle"
            wrapper.write_text(f'#!/bin/sh\nexec chrt --idle 0 {chromium} "$@"\n')
            wrapper.chmod(0o755)
            chromium = str(wrapper)
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        pages = []
        try:
            for i in range(n):
                opts = webdriver.ChromeOptions()
                opts.binary_location = chromium
                for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                            "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
                            "--window-size=1200,900",
                            f"--user-data-dir={folder / f'pages{i}'}"):
                    opts.add_argument(arg)
                page = webdriver.Chrome(options=opts, service=Service(executable_path=driver))
                pages.append(page)
                page.get(url)
            yield f"{n} headless chromium pages"
        finally:
            for page in pages:
                page.quit()
        return
    from websockets.sync.client import connect

    stop = threading.Event()

    def read() -> None:
        with connect(url.replace("http://", "ws://").split("?")[0].rstrip("/") + "/ws") as ws:
            while not stop.is_set():
                with contextlib.suppress(TimeoutError):
                    ws.recv(timeout=0.5)

    threads = [threading.Thread(target=read, daemon=True) for _ in range(n)]
    for t in threads:
        t.start()
    try:
        yield f"{n} WebSocket clients"
    finally:
        stop.set()
        for t in threads:
            t.join(timeout=2)


def run_round(case: str, seconds: float, folder: Path, rec_path: Path,
              values: np.ndarray) -> dict[str, Any]:
    """One round of ``case``: "none" (no view), "sockets" (the view, two WebSocket
    clients) or "chromium" (the view, two headless chromium pages)."""
    with_view = case != "none"
    rig_path = _rig_file(folder, "glove", RATE_HZ, BAUD)
    tag = f"{case}_{time.monotonic_ns()}"
    glove_log, bus_log = folder / f"glove_{tag}.log", folder / f"bus_{tag}.log"
    parts = build_parts(rig_path, _glove_file(folder))
    server: ViewProcess | None = None
    out: dict[str, Any] = {"case": case}
    with contextlib.ExitStack() as stack:
        bus_port = stack.enter_context(emulator(
            ["bus", "--rig", str(rig_path), "--log", str(bus_log)], "the bus emulator"))
        glove_port = stack.enter_context(emulator(
            ["glove", str(rec_path), "--rate", f"{RATE_HZ:g}", "--log", str(glove_log)],
            "the glove emulator"))
        on_rig = None
        if with_view:
            server = stack.enter_context(ViewProcess("127.0.0.1:0", parts.rig_config))
            out["browsers"] = stack.enter_context(
                browsers(server.url, 2, folder, real=case.startswith("chromium"),
                         idle=case == "chromium-idle"))
            on_rig = server.attach_rig
        cpu0, pages0 = process_cpu_s(), chromium_cpu_s(str(folder / "pages"))
        child0 = pid_cpu_s(server.pid) if server else 0.0
        t0 = time.monotonic()
        result = run_live(parts, LiveOptions(glove=glove_port, bus=bus_port, duration_s=seconds,
                                             log=lambda s: None, on_rig=on_rig))
        wall = time.monotonic() - t0
        out["cpu_pct"] = 100.0 * (process_cpu_s() - cpu0) / wall
        out["pages_cpu_pct"] = 100.0 * (chromium_cpu_s(str(folder / "pages")) - pages0) / wall
        if server is not None:
            out["feeder_cpu_pct"] = 100.0 * thread_cpu_s(server.feeder_thread_id) / wall
            out["view_cpu_pct"] = 100.0 * (pid_cpu_s(server.pid) - child0) / wall
    if server is not None:
        out["stats"] = server.stats  # the child's counters, sent as it ends
    sends = [(float(a), int(c)) for a, _, c in
             (line.split() for line in glove_log.read_text().splitlines() if line)]
    writes = [(float(f[0]), tuple(int(v) for v in f[1:]))
              for f in (line.split() for line in bus_log.read_text().splitlines()) if f]
    out["outside_us"] = np.array(outside_latencies(sends, values, writes)) * 1e6
    out["summary"] = result.summary
    return out


def _pct(xs: np.ndarray, q: float) -> float:
    return float(np.percentile(xs, q)) if len(xs) else float("nan")


CASES = {"none": "no view", "sockets": "view + 2 WebSocket clients",
         "chromium": "view + 2 chromium pages",
         "chromium-idle": "view + 2 chromium pages at idle priority"}


def _row(i: int, r: dict[str, Any]) -> str:
    s, lat, st = r["summary"], r["outside_us"], r.get("stats")
    frames = (f"{st.get('frames_encoded')} / {st.get('frames_sent')} / "
              f"{st.get('frames_skipped')}" if st is not None else "-")
    return (f"| {i} | {CASES[r['case']]} | {s['latency_us']['p50']} / {s['latency_us']['p99']} "
            f"| {_pct(lat, 50):.0f} / {_pct(lat, 99):.0f} | {s['rate_hz']} | {s['overruns']} "
            f"| {r['cpu_pct']:.1f} | {r.get('feeder_cpu_pct', 0.0):.2f} "
            f"| {r.get('view_cpu_pct', 0.0):.1f} "
            f"| {r['pages_cpu_pct']:.1f} | {frames} |")


def main() -> None:
    quick = bool(os.environ.get("HANDRIG_BENCH_QUICK"))
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", 8.0 if quick else 20.0))
    rounds = int(os.environ.get("HANDRIG_BENCH_ROUNDS", 2))
    cases = ["none", "sockets"] + (["chromium", "chromium-idle"] if chromium_available()
                                   and shutil.which("chrt") else
                                   ["chromium"] if chromium_available() else [])
    results: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="bench_view_") as tmp:
        folder = Path(tmp)
        rec = step_recording()
        rec_path = folder / "steps.csv"
        write_glove_recording(rec_path, rec)
        values = rec.raw[:, INDEX_CHANNEL].copy()
        print(f"rig at {RATE_HZ:g} Hz glove-triggered, {BAUD / 1e6:g} Mbps, 20 emulated servos "
              f"with wire timing; {rounds} rounds of {seconds:g} s of each case, in turn",
              flush=True)
        if "chromium" not in cases:
            print("chromium or chromium-driver is not installed (make browser-deps): the "
                  "case with two chromium pages is left out", flush=True)
        print("| round | case | in-process p50 / p99 us | outside p50 / p99 us | rate Hz "
              "| overruns | rig process CPU % | its feeder thread CPU % | view process CPU % "
              "| pages' CPU % | frames encoded / sent / skipped |", flush=True)
        print("|---|---|---|---|---|---|---|---|---|---|---|", flush=True)
        for i in range(rounds):
            for case in cases:
                r = run_round(case, seconds, folder, rec_path, values)
                results.append(r)
                print(_row(i + 1, r), flush=True)
    pooled: dict[str, tuple[float, float, float, float]] = {}
    for case in cases:
        rs = [r for r in results if r["case"] == case]
        lat = np.concatenate([r["outside_us"] for r in rs])
        pooled[case] = (float(np.median([r["summary"]["latency_us"]["p50"] for r in rs])),
                        float(np.median([r["summary"]["latency_us"]["p99"] for r in rs])),
                        _pct(lat, 50), _pct(lat, 99))
    base = pooled["none"]
    for case in cases[1:]:
        p = pooled[case]
        rel = [100.0 * (b - a) / a for a, b in zip(base, p, strict=True)]
        print(f"{CASES[case]} vs no view: in-process p50 {base[0]:.0f} -> {p[0]:.0f} us "
              f"({rel[0]:+.1f} %), p99 {base[1]:.0f} -> {p[1]:.0f} us ({rel[1]:+.1f} %); "
              f"outside p50 {base[2]:.0f} -> {p[2]:.0f} us ({rel[2]:+.1f} %), "
              f"p99 {base[3]:.0f} -> {p[3]:.0f} us ({rel[3]:+.1f} %)")
    for case in cases[1:]:
        rs = [r for r in results if r["case"] == case]
        print(f"{CASES[case]}: in the rig's process the feeder thread "
              f"{np.mean([r['feeder_cpu_pct'] for r in rs]):.2f} % of a core; the view's "
              f"process {np.mean([r['view_cpu_pct'] for r in rs]):.1f} %; the pages' own processes "
              f"{np.mean([r['pages_cpu_pct'] for r in rs]):.1f} %")


if __name__ == "__main__":
    main()
