"""What the live view costs the loop: the rig at 200 Hz / 1 Mbps without ``--view``
and with it and two pages connected, side by side in one run.

The rig is :mod:`bench.bench_rig`'s (the real rig between the glove and bus
emulators in processes of their own, 20 servos with wire timing) in the default
rig's glove-triggered mode with a 200 Hz glove. In every case the loop thread runs
as the rig file says (``[loop] realtime_priority = 20``: SCHED_FIFO where the host
allows it, which the header says; ``pin_cpu``: on the last CPU, the emulators and
the view's process on the others): the same in the case without the view.
The cases, in turn, each round:

* no view;
* the view with two WebSocket clients reading every frame, in a process of their
  own (the view's own cost, without a browser's drawing);
* the view with two headless chromium pages, at normal priority on any CPU: they
  draw WebGL in software (SwiftShader), on the same two cores as the rig and its
  emulated servos, so the page spares the CPU as it does wherever WebGL is software
  (at most 15 draws a second);
* the same two pages kept off the loop's CPU (``taskset -c`` the CPUs the emulators
  get), at normal priority: a browser started as docs/view.md advises for a machine
  without a GPU that also runs the rig.

``HANDRIG_BENCH_VIEW_CASES`` picks cases (comma-separated keys of :data:`CASES`);
``chromium-full`` (the pages with ``?full`` in the URL: up to 30 draws a second, as
the page drew everywhere before it learnt to spare a GPU-less machine) and
``chromium-confined`` (off the loop's CPU and under the idle scheduling class,
``chrt --idle 0``) are there for asking.

Reported per round and pooled over rounds: end-to-end latency in the process (frame
arrival to Sync Write handed to the OS) and from outside (glove emulator send to
the bus emulator's receipt), p50/p99, and the difference to no view in %; the rig
process's CPU; the view's CPU (its feeder thread in the rig's process, its own
process); the pages' (or clients') own CPU and the frames they drew a second; frames
encoded, sent and skipped by slow pages; load average and steal.

Browsers: Debian's chromium through chromium-driver (``make browser-deps``); where
they are missing the chromium cases are left out and the output says so. They run
with ``--disable-gpu-compositing``: with no GPU, chromium's compositing on
SwiftShader costs about as much again as the page's drawing (docs/view.md).
``HANDRIG_BENCH_SECONDS`` sets each round's length (default 20 s; QUICK: 8 s),
``HANDRIG_BENCH_ROUNDS`` the rounds (default 2).

``HANDRIG_BENCH_VIEW=pages`` measures only what one page costs: a ``handrig demo
--view`` run and one headless chromium page on it, at the full rate (``?full``)
and as it draws by default where WebGL is software, in turn each round; CPU by
chromium process (GPU process, renderer, the rest), frames drawn a second, and CPU
milliseconds per frame drawn (the figure that does not depend on how starved the
page was).
"""

from __future__ import annotations

import contextlib
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from bench.bench_rig import _rig_file
from bench.rig_steps import (
    INDEX_CHANNEL,
    ROOT,
    _glove_file,
    cpu_times,
    emulator,
    outside_latencies,
    steal_percent,
    step_recording,
)
from handrig.app.factory import port_process
from handrig.app.parts import build_parts
from handrig.app.session import LiveOptions, run_live
from handrig.app.view.process import ViewProcess
from handrig.devices.glove_recording import write_glove_recording
from handrig.realtime import cpu_split, realtime_priority
from sim.dxl_line import REALTIME_PRIORITY

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


def fifo_process(pid: int) -> bool:
    """Every thread of process ``pid`` under SCHED_FIFO at the emulated bus thread's
    priority (below the loop's); False where the host refuses."""
    try:
        for task in Path(f"/proc/{pid}/task").iterdir():
            os.sched_setscheduler(int(task.name), os.SCHED_FIFO,
                                  os.sched_param(REALTIME_PRIORITY))
    except (OSError, ValueError):
        return False
    return True


@contextlib.contextmanager
def glove_emulator(argv: list[str]) -> Iterator[tuple[str, bool]]:
    """The glove emulator (off the loop's CPU) with its threads under SCHED_FIFO, as the
    emulated bus's bus thread is: a glove's frames leave on time whatever the host
    does, as a real glove's do. Yields its port and whether SCHED_FIFO was granted."""
    with port_process(argv, "the glove emulator", module="bench.latency_emulators",
                      cwd=ROOT) as (proc, port):
        yield port, fifo_process(proc.pid)


def chromium_available() -> bool:
    return bool(shutil.which("chromium") and shutil.which("chromedriver"))


CHROMIUM_FLAGS = ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                  "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
                  "--disable-gpu-compositing", "--window-size=1200,900")


def page_cost(seconds: float, rounds: int) -> None:
    """``HANDRIG_BENCH_VIEW=pages``: one page's CPU per frame drawn (module docstring)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    chromium, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if not (chromium and driver):
        print("chromium or chromium-driver is not installed (make browser-deps)")
        return
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    demo = subprocess.Popen([sys.executable, "-m", "handrig.cli", "demo", "--frames", "1000000",
                             "--view", "127.0.0.1:0", "--json"], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        assert demo.stderr is not None
        url = ""
        for line in demo.stderr:
            found = re.search(r"view: (http://\S+)", line)
            if found:
                url = found.group(1)
                break
        threading.Thread(target=demo.stderr.read, daemon=True).start()
        if not url:
            print("the demo printed no view URL")
            return
        print(f"one page on a handrig demo --view run, {rounds} rounds of {seconds:g} s of "
              f"each setting, in turn; {_load()}")
        print("| round | page | CPU % | GPU process % | renderer % | rest % "
              "| frames drawn/s | CPU ms per frame drawn |")
        print("|---|---|---|---|---|---|---|---|")
        settings = {"?full: up to 30/s": with_full(url),
                    "default where WebGL is software: up to 15/s": url}
        with tempfile.TemporaryDirectory(prefix="bench_view_pages_") as tmp:
            for i in range(rounds):
                for k, (name, page_url) in enumerate(settings.items()):
                    marker = f"{tmp}/page{i}_{k}"
                    opts = webdriver.ChromeOptions()
                    opts.binary_location = chromium
                    for arg in (*CHROMIUM_FLAGS, f"--user-data-dir={marker}"):
                        opts.add_argument(arg)
                    page = webdriver.Chrome(options=opts,
                                            service=Service(executable_path=driver))
                    try:
                        page.get(page_url)
                        deadline = time.monotonic() + 60
                        while _frames_drawn(page) < 10 and time.monotonic() < deadline:
                            time.sleep(0.2)  # the scene is in and frames are drawn
                        before, t0 = chromium_cpu_by_kind(marker), time.monotonic()
                        d0 = _frames_drawn(page)
                        time.sleep(seconds)
                        after, d1 = chromium_cpu_by_kind(marker), _frames_drawn(page)
                        wall = time.monotonic() - t0
                    finally:
                        page.quit()
                    cpu = {k: after[k] - before.get(k, 0.0) for k in after}
                    total = sum(cpu.values())
                    gpu, rend = cpu.get("gpu-process", 0.0), cpu.get("renderer", 0.0)
                    rate = (d1 - d0) / wall
                    per = 1e3 * total / (d1 - d0) if d1 > d0 else float("nan")
                    print(f"| {i + 1} | {name} | {100 * total / wall:.1f} | {100 * gpu / wall:.1f} "
                          f"| {100 * rend / wall:.1f} | {100 * (total - gpu - rend) / wall:.1f} "
                          f"| {rate:.1f} | {per:.1f} |", flush=True)
        print(f"at the end: {_load()}")
    finally:
        demo.kill()
        demo.wait()


def with_full(url: str) -> str:
    """The page's URL asking for the full rate where WebGL is software."""
    return url + ("&" if "?" in url else "?") + "full"


def _frames_drawn(page: Any) -> int:
    return int(page.execute_script("return window.handrigView.framesDrawn()"))


def chromium_cpu_by_kind(marker: str) -> dict[str, float]:
    """CPU seconds so far of the chromium processes whose command line holds ``marker``,
    by kind (``--type=``: gpu-process, renderer, utility, ...; "browser" without)."""
    out: dict[str, float] = {}
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes()
            if marker.encode() not in cmd:
                continue
            fields = (proc / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        found = re.search(rb"--type=([\w-]+)", cmd)  # chromium rewrites its children's argv
        kind = found.group(1).decode() if found else "browser"
        out[kind] = out.get(kind, 0.0) + (int(fields[11]) + int(fields[12])) / CLK_TCK
    return out


def read_frames(url: str, n: int) -> None:
    """``n`` WebSocket clients on the view at ``url`` reading every frame until killed
    (run in a process of its own, as a browser is: ``python -c``)."""
    from websockets.sync.client import connect

    def read() -> None:
        with connect(url.replace("http://", "ws://").split("?")[0].rstrip("/") + "/ws") as ws:
            while True:
                ws.recv()

    threads = [threading.Thread(target=read, daemon=True) for _ in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()


@contextlib.contextmanager
def browsers(url: str, n: int, folder: Path, real: bool, confined: bool = False,
             full: bool = False, off_cpu: bool = False
             ) -> Iterator[tuple[str, Callable[[], float], Callable[[], float]]]:
    """``n`` pages on ``url``: headless chromium (``real``; ``confined``: off the loop's
    CPU and under the idle scheduling class; ``off_cpu``: off it at normal priority;
    ``full``: ``?full`` in the URL), else
    WebSocket clients in a process of their own that read every frame. Yields what they
    are, a function giving their CPU seconds so far, and one giving the frames their
    pages drew so far (0: clients)."""
    chromium, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if real and chromium and driver:
        if confined or off_cpu:
            _, others = cpu_split()
            cpus = ",".join(str(c) for c in sorted(others))
            wrapper = folder / "chromium-confined"
            idle = "chrt --idle 0 " if confined else ""
            wrapper.write_text(f'#!/bin/sh\nexec taskset -c {cpus} {idle}{chromium} "$@"\n')
            wrapper.chmod(0o755)
            chromium = str(wrapper)
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        pages = []
        marker = str(folder / "pages")
        try:
            for i in range(n):
                opts = webdriver.ChromeOptions()
                opts.binary_location = chromium
                for arg in (*CHROMIUM_FLAGS, f"--user-data-dir={marker}{i}"):
                    opts.add_argument(arg)
                page = webdriver.Chrome(options=opts, service=Service(executable_path=driver))
                pages.append(page)
                page.get(with_full(url) if full else url)
            for page in pages:  # each has the scene and draws before the round starts
                deadline = time.monotonic() + 60
                while (page.execute_script("return window.handrigView.framesDrawn()") < 2
                       and time.monotonic() < deadline):
                    time.sleep(0.1)

            def drawn() -> float:
                return float(sum(p.execute_script("return window.handrigView.framesDrawn()")
                                 for p in pages))

            yield (f"{n} headless chromium pages", lambda: chromium_cpu_s(marker), drawn)
        finally:
            for page in pages:
                page.quit()
        return
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from bench.bench_view import "
                             "read_frames; read_frames(sys.argv[1], int(sys.argv[2]))",
                             url, str(n)], cwd=ROOT)
    try:
        time.sleep(1.0)  # connected and reading
        yield f"{n} WebSocket clients", lambda: pid_cpu_s(proc.pid), lambda: 0.0
    finally:
        proc.kill()
        proc.wait()


def run_round(case: str, seconds: float, folder: Path, rec_path: Path,
              values: np.ndarray) -> dict[str, Any]:
    """One round of ``case`` (a key of :data:`CASES`)."""
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
        glove_port, out["glove_fifo"] = stack.enter_context(glove_emulator(
            ["glove", str(rec_path), "--rate", f"{RATE_HZ:g}", "--log", str(glove_log)]))
        on_hands = None
        pages_cpu: Callable[[], float] = lambda: 0.0  # noqa: E731
        drawn: Callable[[], float] = lambda: 0.0  # noqa: E731
        if with_view:
            server = stack.enter_context(ViewProcess("127.0.0.1:0", parts.rig_config))
            out["browsers"], pages_cpu, drawn = stack.enter_context(
                browsers(server.url, 2, folder, real=case.startswith("chromium"),
                         confined=case == "chromium-confined",
                         off_cpu=case == "chromium-offcpu",
                         full=case == "chromium-full"))
            on_hands = server.attach_hands
        cpu0, pages0, drawn0 = process_cpu_s(), pages_cpu(), drawn()
        child0 = pid_cpu_s(server.pid) if server else 0.0
        ticks0 = cpu_times()
        t0 = time.monotonic()
        result = run_live(parts, LiveOptions(glove=glove_port, bus=bus_port, duration_s=seconds,
                                             log=lambda s: None, on_hands=on_hands))
        wall = time.monotonic() - t0
        out["steal_pct"] = steal_percent(ticks0, cpu_times())
        out["cpu_pct"] = 100.0 * (process_cpu_s() - cpu0) / wall
        out["pages_cpu_pct"] = 100.0 * (pages_cpu() - pages0) / wall
        out["drawn_hz"] = (drawn() - drawn0) / wall / 2
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
         "chromium-full": "view + 2 chromium pages at 30/s (?full)",
         "chromium-offcpu": "view + 2 chromium pages off the loop's CPU (taskset)",
         "chromium-confined": "view + 2 chromium pages, off the loop's CPU, idle class"}


def _row(i: int, r: dict[str, Any]) -> str:
    s, lat, st = r["summary"], r["outside_us"], r.get("stats")
    frames = (f"{st.get('frames_encoded')} / {st.get('frames_sent')} / "
              f"{st.get('frames_skipped')}" if st is not None else "-")
    drawn = f"{r['drawn_hz']:.1f}" if r["case"].startswith("chromium") else "-"
    return (f"| {i} | {CASES[r['case']]} | {s['latency_us']['p50']} / {s['latency_us']['p99']} "
            f"| {_pct(lat, 50):.0f} / {_pct(lat, 99):.0f} | {s['rate_hz']} | {s['overruns']} "
            f"| {r['cpu_pct']:.1f} | {r.get('feeder_cpu_pct', 0.0):.2f} "
            f"| {r.get('view_cpu_pct', 0.0):.1f} "
            f"| {r['pages_cpu_pct']:.1f} | {drawn} | {frames} | {r['steal_pct']} |")


def loop_scheduling(rig_path: Path) -> str:
    """What the rig file asks for the loop thread and what this host grants (every case)."""
    loop = build_parts(rig_path, _glove_file(rig_path.parent)).rig_config.loop
    granted: list[bool] = []

    def probe() -> None:
        with realtime_priority(loop.realtime_priority) as ok:
            granted.append(ok)

    t = threading.Thread(target=probe)
    t.start()
    t.join()
    loop_cpu, _ = cpu_split()
    fifo = (f"SCHED_FIFO {loop.realtime_priority}" if granted and granted[0]
            else "normal priority (SCHED_FIFO refused here)")
    pin = (f"pinned to CPU {loop_cpu}, emulators and the view's process on the others"
           if loop.pin_cpu and loop_cpu is not None else "not pinned")
    return f"the loop thread in every case: {fifo}, {pin}"


def _load() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> None:
    quick = bool(os.environ.get("HANDRIG_BENCH_QUICK"))
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", 8.0 if quick else 20.0))
    rounds = int(os.environ.get("HANDRIG_BENCH_ROUNDS", 2))
    if os.environ.get("HANDRIG_BENCH_VIEW") == "pages":
        page_cost(seconds, rounds)
        return
    asked = os.environ.get("HANDRIG_BENCH_VIEW_CASES")
    cases = (["none"] + [c for c in asked.split(",") if c and c != "none"] if asked
             else ["none", "sockets", "chromium", "chromium-offcpu"])
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise SystemExit(f"HANDRIG_BENCH_VIEW_CASES: unknown case {unknown[0]!r} "
                         f"(one of {', '.join(CASES)})")
    confine = bool(shutil.which("chrt") and shutil.which("taskset") and cpu_split()[0] is not None)
    if not confine:
        cases = [c for c in cases if c not in ("chromium-confined", "chromium-offcpu")]
    if not chromium_available():
        cases = [c for c in cases if not c.startswith("chromium")]
    results: list[dict[str, Any]] = []
    ticks0 = cpu_times()
    with tempfile.TemporaryDirectory(prefix="bench_view_") as tmp:
        folder = Path(tmp)
        rec = step_recording()
        rec_path = folder / "steps.csv"
        write_glove_recording(rec_path, rec)
        values = rec.raw[:, INDEX_CHANNEL].copy()
        print(f"rig at {RATE_HZ:g} Hz glove-triggered, {BAUD / 1e6:g} Mbps, 20 emulated servos "
              f"with wire timing; {rounds} rounds of {seconds:g} s of each case, in turn",
              flush=True)
        print(loop_scheduling(_rig_file(folder, "glove", RATE_HZ, BAUD)), flush=True)
        print(f"at the start: {_load()}", flush=True)
        if not chromium_available():
            print("chromium or chromium-driver is not installed (make browser-deps): the "
                  "cases with chromium pages are left out", flush=True)
        print("| round | case | in-process p50 / p99 us | outside p50 / p99 us | rate Hz "
              "| overruns | rig process CPU % | its feeder thread CPU % | view process CPU % "
              "| pages' (clients') CPU % | frames drawn/s per page "
              "| frames encoded / sent / skipped | steal % |", flush=True)
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|", flush=True)
        for i in range(rounds):
            for case in cases:
                r = run_round(case, seconds, folder, rec_path, values)
                results.append(r)
                print(_row(i + 1, r), flush=True)
    print(f"at the end: {_load()}; steal over the run {steal_percent(ticks0, cpu_times())} %")
    fifo = sum(bool(r["glove_fifo"]) for r in results)
    print(f"the glove emulator's threads under SCHED_FIFO {REALTIME_PRIORITY} (as the emulated "
          f"bus thread; a real glove's frames leave on time whatever the host does): "
          f"{fifo} of {len(results)} rounds, every case alike")
    pooled: dict[str, tuple[float, float, float, float]] = {}
    for case in cases:
        rs = [r for r in results if r["case"] == case]
        lat = np.concatenate([r["outside_us"] for r in rs])
        pooled[case] = (float(np.median([r["summary"]["latency_us"]["p50"] for r in rs])),
                        float(np.median([r["summary"]["latency_us"]["p99"] for r in rs])),
                        _pct(lat, 50), _pct(lat, 99))
    base = pooled["none"]
    print("pooled (in process: the median over rounds; outside: all steps of all rounds):")
    for case in cases[1:]:
        p = pooled[case]
        rel = [100.0 * (b - a) / a for a, b in zip(base, p, strict=True)]
        within = ("p50 and p99 within 10 %" if max(abs(x) for x in rel[:2]) < 10.0
                  else "NOT within 10 %")
        print(f"- {CASES[case]} vs no view: in-process p50 {base[0]:.0f} -> {p[0]:.0f} us "
              f"({rel[0]:+.1f} %), p99 {base[1]:.0f} -> {p[1]:.0f} us ({rel[1]:+.1f} %) "
              f"[{within}]; outside p50 {base[2]:.0f} -> {p[2]:.0f} us ({rel[2]:+.1f} %), "
              f"p99 {base[3]:.0f} -> {p[3]:.0f} us ({rel[3]:+.1f} %)")
    for case in cases[1:]:
        rs = [r for r in results if r["case"] == case]
        drawn = (f", drawing {np.mean([r['drawn_hz'] for r in rs]):.1f} frames/s each"
                 if case.startswith("chromium") else "")
        encoded = sum(int(r["stats"].get("frames_encoded", 0)) for r in rs)
        encode_us = (1e6 * sum(float(r["stats"].get("encode_s", 0.0)) for r in rs) / encoded
                     if encoded else float("nan"))
        print(f"- {CASES[case]}: in the rig's process the feeder thread "
              f"{np.mean([r['feeder_cpu_pct'] for r in rs]):.2f} % of a core; the view's "
              f"process {np.mean([r['view_cpu_pct'] for r in rs]):.1f} % (a frame's kinematics "
              f"and JSON {encode_us:.0f} us of its CPU); the pages' (clients') "
              f"own processes {np.mean([r['pages_cpu_pct'] for r in rs]):.1f} %{drawn}")


if __name__ == "__main__":
    main()
