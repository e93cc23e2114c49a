"""The show console: the panel drawn from plain snapshots, the plain-line fallback, the
snapshot of a running rig, and the key reader on a real pseudo-terminal."""

from __future__ import annotations

import contextlib
import io
import os
import termios
import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest
from rich.console import Console

from handrig.app.keys import KeyReader
from handrig.app.panel import (
    BusHealth,
    GloveLink,
    LivePanel,
    PanelSnapshot,
    ServoLine,
    plain_line,
    render,
)
from handrig.app.parts import build_parts
from handrig.app.rig_snapshot import RigSnapshot
from handrig.clock import FakeClock
from handrig.config.rig import load_rig_config
from handrig.devices.glove import GloveSample, GloveSource, GloveStats
from handrig.outputs.base import PanelCell
from tests.helpers.fakes import FakeBus
from tests.helpers.loop import make_rig

VMC_CELL = PanelCell("VMC", "127.0.0.1:39539", rate=True, rate_hz=60.0)
REC_CELL = PanelCell("rec", "/shows/take1.bvh", size_bytes=3_400_000, duration_s=201.0)


def show_snapshot(**kw: object) -> PanelSnapshot:
    rig = load_rig_config()
    servos = tuple(
        ServoLine(s.id, s.joint, goal_deg=10.0 - i, present_deg=9.5 - i, stale=i in (3, 12),
                  temperature_c=30.0 + i, temperature_limit_c=70.0, current_ma=-25.0 * i,
                  hardware_error=0x20 if s.id == 8 else 0)
        for i, s in enumerate(rig.servos))
    base = {
        "mode": "relaxing", "reason": "glove silent for 0.25 s: easing to the relaxed pose",
        "elapsed_s": 754.0, "loop_rate_hz": 200.0, "overruns": 2, "latency_p50_us": 92.0,
        "latency_p99_us": 197.0,
        "glove": GloveLink("/dev/ttyACM0", 199.5, 150000, 3, 0.31, 1),
        "bus": BusHealth("/dev/ttyUSB0", 50.0, 200.0, 19, 1, 2, 0.12),
        "servos": servos,
        "outputs": (VMC_CELL, REC_CELL),
        "events": ("commissioned", "glove silent for 0.25 s: easing to the relaxed pose"),
    }
    base.update(kw)
    return PanelSnapshot(**base)  # type: ignore[arg-type]


def screen(snap: PanelSnapshot, height: int = 24) -> list[str]:
    console = Console(width=80, height=height, record=True, file=io.StringIO(),
                      force_terminal=True)
    console.print(render(snap, height))
    return console.export_text().splitlines()


def test_the_panel_fits_80x24_and_shows_what_a_show_needs() -> None:
    lines = screen(show_snapshot())
    assert len(lines) <= 24 and max(len(line) for line in lines) <= 80
    text = "\n".join(lines)
    assert lines[0].startswith("handrig  RELAXING") and "glove silent for 0.25 s" in lines[0]
    assert lines[0].endswith("12:34")
    assert "/dev/ttyACM0  199.5 Hz  errors 3  last 310 ms  reconnects 1" in text
    assert "latency p50 92 us  p99 197 us  overruns 2" in text
    assert "reads 50/s  timeouts 19  errors 1  stale 2 (worst 120 ms)" in text
    assert "VMC 127.0.0.1:39539 60 Hz" in text and "rec /shows/take1.bvh 3.2 MB 3:21" in text
    # all 20 servos, two to a line, with temperature, current and errors
    rows = [line for line in lines if "│" in line][1:]
    assert len(rows) == 10
    assert rows[0].split("│")[0].split() == ["1", "ThumbCMCx", "+10.0", "+9.5", "30", "0", "-"]
    assert rows[7].split("│")[0].split()[-1] == "L"  # servo 8: overload
    assert rows[9].split("│")[1].split()[:2] == ["20", "WristDev"]
    assert "stale" not in "".join(rows)  # stale readings are counted, not spelled per servo
    assert "space" in lines[-1] and "e-stop" in lines[-1]


def test_a_small_terminal_keeps_the_head_and_the_keys() -> None:
    lines = screen(show_snapshot(events=tuple(f"event {i}" for i in range(9))), height=18)
    assert len(lines) <= 18
    assert lines[0].startswith("handrig") and "space" in lines[-1]


def test_forty_servos_keep_the_keys_in_24_lines_and_all_show_in_a_taller_terminal() -> None:
    one = show_snapshot().servos
    forty = one + tuple(ServoLine(s.id + 20, "le" + s.joint[2:], goal_deg=s.goal_deg)
                        for s in one)
    snap = show_snapshot(servos=forty, hands=("right hand: running", "left hand: running"))
    lines = screen(snap, height=24)
    assert len(lines) <= 24 and "space" in lines[-1] and "e-stop" in lines[-1]
    assert any("more rows of servos: a taller terminal shows them" in line for line in lines)
    assert any(line.startswith("er: V voltage") for line in lines)  # the legend stays
    lines = screen(snap, height=34)  # a taller terminal: every one of the 40, 20 rows
    rows = [line for line in lines if "│" in line][1:]
    assert len(rows) == 20 and "more rows" not in "\n".join(lines)
    assert rows[19].split("│")[1].split()[0] == "40" and "space" in lines[-1]


def test_without_outputs_or_readings_it_says_so() -> None:
    snap = PanelSnapshot(servos=(ServoLine(1, "riIndexMCPy"),), keys=False)
    text = "\n".join(screen(snap))
    assert "WAITING" in text and "out    none" in text
    assert "last never" in text and "stale none" in text
    assert "keys off" in text
    line = plain_line(snap)
    assert line.startswith("0:00 waiting") and "outputs none" in line


def test_plain_line_carries_the_same_figures() -> None:
    line = plain_line(show_snapshot())
    for part in ("12:34 relaxing (glove silent", "glove 200 Hz err 3 last 310 ms reconnects 1",
                 "latency p50 92 p99 197 us", "timeouts 19", "stale 2 (worst 120 ms)",
                 "servos max 49 C, 1 with errors", "VMC 127.0.0.1:39539 60 Hz",
                 "rec /shows/take1.bvh 3.2 MB 3:21"):
        assert part in line, part
    assert "\n" not in line


def test_heat_tiers_colour_the_temperatures_and_name_the_warm_servos() -> None:
    rig = load_rig_config()
    temps = {18: 56.0, 19: 61.0}  # past warn_c 55; past act_c 60 (capped)
    servos = tuple(ServoLine(s.id, s.joint, temperature_c=temps.get(s.id, 35.0),
                             temperature_limit_c=70.0 if s.id < 19 else 80.0,
                             warn_c=55.0, act_c=60.0) for s in rig.servos)
    snap = show_snapshot(servos=servos)
    assert "servos max 61 C (past [heat] warn_c: 18, 19), 0 with errors" in plain_line(snap)
    console = Console(width=80, height=30, record=True, file=io.StringIO(),
                      force_terminal=True, color_system="standard")
    console.print(render(snap, 30))
    styled = console.export_text(styles=True)
    assert "\x1b[1;31m 61" in styled  # bold red from act_c
    assert "\x1b[33m 56" in styled  # yellow from warn_c
    assert "\x1b[33m 35" not in styled and "\x1b[1;31m 35" not in styled


def wait_for(condition: Callable[[], bool], timeout_s: float = 5.0) -> None:
    """Until ``condition()`` holds (checked every 10 ms), at most ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)


def test_live_panel_without_a_terminal_prints_plain_lines_after_the_header_once() -> None:
    out = io.StringIO()
    console = Console(file=out, width=200)
    assert not console.is_terminal
    snaps = iter([show_snapshot(elapsed_s=float(i)) for i in range(100)])
    with LivePanel(lambda: next(snaps), console=console, header=["bus: 20 servos"],
                   plain_every_s=0.05):
        wait_for(lambda: len(out.getvalue().splitlines()) >= 3)
    lines = out.getvalue().splitlines()
    assert lines[0] == "bus: 20 servos" and lines.count("bus: 20 servos") == 1
    assert len(lines) >= 3 and all(" | glove " in line for line in lines[1:])


def test_live_panel_on_a_terminal_draws_below_the_header() -> None:
    out = io.StringIO()
    console = Console(file=out, width=80, height=24, force_terminal=True)
    panel = LivePanel(show_snapshot, refresh_hz=20.0, console=console,
                      header=["servo bus /dev/ttyUSB0: 20 servos commissioned"])
    with panel:
        wait_for(lambda: "RELAXING" in out.getvalue())
        panel.log("a line above the panel")
    text = out.getvalue()
    assert text.count("20 servos commissioned") == 1
    assert text.index("20 servos commissioned") < text.index("RELAXING")
    assert "a line above the panel" in text and panel.failure == ""


def test_a_failing_snapshot_stops_the_panel_not_the_show() -> None:
    out = io.StringIO()

    def broken() -> PanelSnapshot:
        raise KeyError("bus")

    with LivePanel(broken, console=Console(file=out), plain_every_s=0.02) as panel:
        time.sleep(0.1)
    assert "panel stopped: the snapshot failed: KeyError('bus')" in out.getvalue()
    assert panel.failure


# -- a running rig's snapshot ----------------------------------------------------------


class SteadyGlove(GloveSource):
    def __init__(self, clock: FakeClock) -> None:
        super().__init__()
        self.clock = clock
        self.n = 0

    def latest(self) -> GloveSample | None:
        self.n += 1
        t = self.clock.now()
        raw = np.array([2000.0, 2100.0, 2000.0, 2100.0, 2100.0])
        return GloveSample(raw, np.array([0.0, 0.0, 0.0, 1.0]), 0, False, self.n, 0, t, self.n)

    def stats(self) -> GloveStats:
        return GloveStats(frames_ok=self.n, crc_errors=2, reconnects=1,
                          time_since_last_good_s=0.004)


def warm_bus(names: tuple[str, ...], clock: FakeClock) -> FakeBus:
    """Servos 2 and 5 stale; temperatures and currents reported."""
    return FakeBus(names, clock, position_deg=3.0, temperature_c=41.0, current_ma=-120.0,
                   hardware_errors={6: 0x04}, stale=(1, 4), stale_age_s=0.05,
                   held_deg=0.0, timeouts=4, port="/dev/ttyUSB9")


def test_rig_snapshot_reads_a_running_rig() -> None:
    parts = build_parts()
    clock = FakeClock()
    bus = warm_bus(tuple(parts.pipeline.servo_joints), clock)
    rig = make_rig(parts, SteadyGlove(clock), bus, clock)
    snapshot = RigSnapshot(rig, glove_source="/dev/ttyACM0", temperature_limit_c={1: 45.0},
                           keys=True)
    rig.run(frames=100)
    first = snapshot()
    clock.advance(1.0)
    snap = snapshot()
    assert first.mode == snap.mode
    assert snap.glove.source == "/dev/ttyACM0" and snap.glove.errors == 2
    assert snap.glove.reconnects == 1 and snap.glove.last_frame_age_s == pytest.approx(0.004)
    assert snap.bus.port == "/dev/ttyUSB9" and snap.bus.timeouts == 4
    assert snap.bus.stale_servos == 2
    assert snap.bus.stale_worst_age_s == pytest.approx(1.05, abs=0.02)  # 50 ms + 1 s since
    assert len(snap.servos) == 20
    sv = snap.servos[6]
    assert (sv.temperature_c, sv.current_ma, sv.hardware_error) == (41.0, -120.0, 0x04)
    assert snap.servos[0].temperature_limit_c == 45.0
    assert snap.servos[1].stale and not snap.servos[0].stale
    assert np.isfinite(snap.latency_p50_us) and snap.elapsed_s > 1.0
    text = "\n".join(screen(snap))
    assert "stale 2 (worst" in text and "/dev/ttyUSB9" in text and "e-stop" in text
    assert "keys off" in "\n".join(screen(RigSnapshot(rig)()))  # until a KeyReader listens


# -- keys ----------------------------------------------------------------------------------


@pytest.fixture
def pty_pair() -> Iterator[tuple[int, int]]:
    master, slave = os.openpty()
    try:
        yield master, slave
    finally:
        for fd in (master, slave):
            with contextlib.suppress(OSError):
                os.close(fd)


def test_keys_call_their_callbacks_without_blocking(pty_pair: tuple[int, int]) -> None:
    master, slave = pty_pair
    calls: list[str] = []
    before = termios.tcgetattr(slave)
    reader = KeyReader.for_show(slave, toggle_relax=lambda: calls.append("relax"),
                                stop=lambda: calls.append("stop"),
                                estop=lambda: calls.append("estop"))
    with reader:
        lflag = termios.tcgetattr(slave)[3]
        assert not lflag & termios.ECHO and not lflag & termios.ICANON  # keys, not lines
        assert lflag & termios.ISIG  # Ctrl-C still interrupts
        t0 = time.monotonic()
        assert reader.poll() == 0  # nothing typed: returns at once
        assert time.monotonic() - t0 < 0.05
        os.write(master, b" x\x1b[Aq")  # space, an unbound key, an arrow key, q
        assert reader.poll(1.0) >= 1
        reader.poll(0.2)
        os.write(master, b"E")
        reader.poll(1.0)
    assert calls == ["relax", "stop", "estop"]
    assert reader.pressed == [" ", "q", "E"]
    assert termios.tcgetattr(slave) == before  # the terminal is given back as it was


def test_the_key_thread_reads_until_closed_and_keeps_a_failing_callback(
        pty_pair: tuple[int, int]) -> None:
    master, slave = pty_pair
    calls: list[str] = []

    def broken() -> None:
        raise RuntimeError("estop wiring")

    reader = KeyReader(slave, {" ": lambda: calls.append("relax"), "e": broken}, poll_s=0.01)
    reader.start()
    try:
        os.write(master, b"  ")
        deadline = time.monotonic() + 2.0
        while len(calls) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert calls == ["relax", "relax"]
        os.write(master, b"e")
        deadline = time.monotonic() + 2.0
        while reader.error is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert isinstance(reader.error, RuntimeError)
    finally:
        reader.close()
    errors: list[BaseException] = []
    with KeyReader(slave, {"e": broken}, on_error=errors.append) as again:
        os.write(master, b"e")
        again.poll(1.0)
    assert len(errors) == 1


def test_a_key_reader_on_a_pipe_leaves_it_alone() -> None:
    r, w = os.pipe()
    try:
        calls: list[str] = []
        with KeyReader(r, {"q": lambda: calls.append("q")}) as reader:
            os.write(w, b"q")
            reader.poll(1.0)
            os.close(w)
            reader.poll(0.5)
        assert calls == ["q"] and reader.eof
    finally:
        os.close(r)


def test_a_glove_take_shows_on_the_outputs_line_within_80_columns() -> None:
    glove = PanelCell("glove", "/shows/glove1.csv", frames=40200)
    lines = screen(show_snapshot(outputs=(VMC_CELL, REC_CELL, glove)))
    assert max(len(line) for line in lines) <= 80
    out = next(line for line in lines if line.startswith("out"))
    assert "rec " in out and "3.2 MB 3:21" in out and out.rstrip().endswith("glove 40k")
    assert "glove /shows/glove1.csv 40k" in plain_line(show_snapshot(
        outputs=(VMC_CELL, REC_CELL, glove)))
