"""The show console of ``handrig run``: a live panel and the keys a puppeteer presses.

The panel draws a :class:`PanelSnapshot`, a plain record of figures (mode and
its reason, glove link, latency, bus health, per-servo state, outputs), so it
is tested without a rig and fed by whatever runs the loop:

* :func:`render` lays a snapshot out for a terminal of 80 x 24 (:mod:`rich`);
* :func:`plain_line` is the same as one line of text, for a log or a pipe;
* :class:`LivePanel` redraws from a snapshot source a few times a second from
  its own thread (the realtime loop never waits for the terminal): on a
  terminal below the lines printed before it (commissioning, once), else as a
  plain line every few seconds;
* :class:`~handrig.app.rig_snapshot.RigSnapshot` takes the snapshot of a running
  :class:`~handrig.loop.rig.Rig`;
* :class:`~handrig.app.keys.KeyReader` reads keys from a terminal without blocking
  and calls their callbacks (:data:`~handrig.app.keys.SHOW_KEYS`).
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from rich.console import Console, Group
from rich.live import Live
from rich.text import Text

from handrig.app.keys import SHOW_KEYS
from handrig.devices.servo.bus import fault_letters
from handrig.devices.servo.models import temperature_limit_c
from handrig.outputs.base import PanelCell

WIDTH = 80
HEIGHT = 24
SERVO_COLUMNS = 2
NAN = math.nan


MODE_STYLES = {"running": "bold green", "waiting": "bold cyan", "relaxing": "bold yellow",
               "resuming": "bold cyan", "stopping": "bold red", "e-stop": "bold white on red",
               "stopped": "bold"}


# -- the snapshot --------------------------------------------------------------------


@dataclass(frozen=True)
class GloveLink:
    """The glove as the loop sees it."""

    source: str = ""  # port, opengloves:PORT or replay:FILE
    rate_hz: float = NAN  # good frames per second, recently
    frames_ok: int = 0
    errors: int = 0  # rejected frames of every kind (CRC, decoding)
    last_frame_age_s: float = math.inf  # since the last good frame arrived
    reconnects: int = 0
    failure: str = ""  # why the link is down, if it is


@dataclass(frozen=True)
class BusHealth:
    """The servo bus: rates and faults."""

    port: str = ""
    read_rate_hz: float = NAN  # present-state reads per second, recently
    write_rate_hz: float = NAN  # goal Sync Writes per second, recently
    timeouts: int = 0
    errors: int = 0  # CRC, malformed and refused replies
    stale_servos: int = 0  # servos whose newest reading is stale
    stale_worst_age_s: float = 0.0  # age of the oldest of those readings
    left_out: int = 0  # servos left out at start-up, not (yet) admitted
    admitted: int = 0  # of those, admitted when they answered
    host_timeouts: int = 0  # of the timeouts, the host's: it held a reply, not the bus


@dataclass(frozen=True)
class ServoLine:
    """One servo's row. NaN: never read."""

    id: int
    joint: str
    goal_deg: float = NAN
    present_deg: float = NAN  # the newest good reading (stale ones are marked by ``stale``)
    stale: bool = False
    temperature_c: float = NAN
    temperature_limit_c: float = NAN  # the servo's Temperature Limit, if known
    warn_c: float = NAN  # [heat] warn_c: yellow from here
    act_c: float = NAN  # [heat] act_c: red from here (its effort is capped)
    current_ma: float = NAN  # Present Current (or load, as mA equivalent)
    hardware_error: int = 0  # ServoFault bits (the bus contract's), 0 = none


@dataclass(frozen=True)
class PanelSnapshot:
    """Everything the panel shows, at one moment. Times in seconds, rates in Hz."""

    mode: str = "waiting"  # waiting, running, relaxing, resuming, stopping, e-stop, stopped
    reason: str = ""  # why the mode is what it is (relaxing, stopping)
    elapsed_s: float = 0.0
    loop_rate_hz: float = NAN
    overruns: int = 0
    latency_p50_us: float = NAN  # glove frame's arrival -> Sync Write handed to the OS
    latency_p99_us: float = NAN
    glove: GloveLink = field(default_factory=GloveLink)
    bus: BusHealth = field(default_factory=BusHealth)
    servos: tuple[ServoLine, ...] = ()
    outputs: tuple[PanelCell, ...] = ()  # each output's own cell (outputs/base.py)
    events: tuple[str, ...] = ()  # the newest last
    keys: bool = True  # whether the show keys are read (a KeyReader on a terminal)
    show: str = ""  # the show running (handrig run --show), "" when none
    hands: tuple[str, ...] = ()  # a two-hand run: one line per hand (mode, glove, latency)
    cues: tuple[str, ...] = ()  # the last few cues taken (OSC, MIDI, r), newest last
    layers: tuple[str, ...] = ()  # takes layered under the glove: "GROUP <- TAKE (loop, on)"


# -- formatting -----------------------------------------------------------------------


def _num(value: float, spec: str = ".0f", missing: str = "-") -> str:
    return missing if value is None or not math.isfinite(value) else format(value, spec)


def _age(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "never"
    if seconds < 1.0:
        return f"{seconds * 1e3:.0f} ms"
    if seconds < 120:
        return f"{seconds:.1f} s"
    return _clock(seconds)


def _clock(seconds: float) -> str:
    s = int(max(seconds, 0.0))
    h, rem = divmod(s, 3600)
    return f"{h}:{rem // 60:02d}:{rem % 60:02d}" if h else f"{rem // 60:d}:{rem % 60:02d}"


def _size(n_bytes: int) -> str:
    value, unit = float(n_bytes), "B"
    for bigger in ("kB", "MB", "GB"):
        if value < 1024:
            break
        value, unit = value / 1024, bigger
    return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"


def _fit(text: str, width: int) -> str:
    """``text`` cut to ``width`` characters, the cut marked with an ellipsis."""
    return text if len(text) <= width else text[: max(width - 1, 0)] + "…"


def _fit_left(text: str, width: int) -> str:
    """Like :func:`_fit`, keeping the end (a path's file name)."""
    return text if len(text) <= width else "…" + text[len(text) - width + 1:]


def short_joint(name: str) -> str:
    """A joint name for a 10-character column: no hand prefix, long words shortened."""
    stem = name[2:] if name[:2] in ("ri", "le") else name
    stem = stem.replace("Flexion", "Flex").replace("Deviation", "Dev")
    return _fit(stem, 10)


def _deg(value: float) -> str:
    if not math.isfinite(value):
        return "-"
    return f"{value:+.0f}" if abs(value) >= 99.95 else f"{value:+.1f}"


def mode_line(s: PanelSnapshot) -> Text:
    mode = s.mode.upper()
    text = Text.assemble(("handrig ", "bold"))
    if s.show:
        text.append(f"show {_fit(s.show, 20)} ", "bold cyan")
    text.append(f" {mode} ", MODE_STYLES.get(s.mode, "bold"))
    right = f"  {_clock(s.elapsed_s)}"
    room = WIDTH - len(text.plain) - len(right) - 2
    if s.reason and room > 3:
        text.append("  " + _fit(s.reason, room), style="yellow" if s.mode != "running" else "")
    text.append(" " * max(0, WIDTH - len(text.plain) - len(right)) + right)
    return text


def glove_line(g: GloveLink) -> Text:
    age_style = "" if g.last_frame_age_s < 0.1 else "bold yellow"
    text = Text.assemble(
        ("glove  ", "bold"), _fit_left(g.source or "-", 22),
        f"  {_num(g.rate_hz, '.1f')} Hz  errors ",
        (str(g.errors), "bold red" if g.errors else ""),
        "  last ", (_age(g.last_frame_age_s), age_style),
        f"  reconnects {g.reconnects}",
    )
    if g.failure:
        text.append("  " + _fit(g.failure, max(0, WIDTH - len(text.plain) - 2)), "bold red")
    return text


def loop_line(s: PanelSnapshot) -> Text:
    return Text.assemble(
        ("loop   ", "bold"), f"{_num(s.loop_rate_hz, '.1f')} Hz  latency p50 ",
        (f"{_num(s.latency_p50_us)} us", "bold"), f"  p99 {_num(s.latency_p99_us)} us"
        "  overruns ", (str(s.overruns), "bold red" if s.overruns else ""),
    )


def _count(n: int, compact: bool) -> str:
    """A count; ``compact``: 10,000 and up in thousands ("12k"), at most 4 characters
    below a million."""
    return str(n) if not compact or n < 10_000 else f"{n // 1000}k"


BUS_LINE_TIGHTER = 7  # ways to make the bus line tighter, tried in turn until it fits


def bus_line(b: BusHealth) -> Text:
    """The bus's line, within WIDTH columns: as roomy as fits, tightened step by step (one
    space between fields and no "worst"; the port's name cut to its last 7 characters;
    counts of 10,000 and up in thousands; no age of the stale readings; no port; the
    servos left out and admitted first, after a shorter label), then cut at the end: the
    servos left out and admitted are the last to go."""
    for tight in range(BUS_LINE_TIGHTER):
        line = _bus_line(b, tight)
        if len(line.plain) <= WIDTH:
            return line
    line.truncate(WIDTH, overflow="ellipsis")
    return line


def _bus_line(b: BusHealth, tight: int) -> Text:
    sep, worst = ("  ", "worst ") if tight == 0 else (" ", "")
    compact = tight >= 3
    age = f" ({worst}{_age(b.stale_worst_age_s)})" if tight < 4 else ""
    stale = (Text(f"{b.stale_servos}{age}", "bold yellow") if b.stale_servos
             else Text("none"))
    port = [] if tight >= 5 else [_fit_left(b.port or "-", 14 if tight < 2 else 7), sep]
    servos: list[str | tuple[str, str]] = []
    if b.left_out:
        servos += [("out ", ""), (str(b.left_out), "bold yellow"), sep]
    if b.admitted:
        servos += [("admitted ", ""), (str(b.admitted), "green"), sep]
    first = tight >= 6  # at the tightest, ahead of the counts (the cut takes the end)
    return Text.assemble(
        ("bus " if first else "bus    ", "bold"), *port, *(servos if first else []),
        f"reads {_num(b.read_rate_hz)}/s{sep}timeouts ",
        (_count(b.timeouts, compact), "yellow" if b.timeouts else ""),
        *([(f" (host {_count(b.host_timeouts, compact)})", "")] if b.host_timeouts else []),
        f"{sep}errors ", (_count(b.errors, compact), "bold red" if b.errors else ""),
        f"{sep}stale ", stale, *([sep, *servos[:-1]] if servos and not first else []),
    )


OUTPUTS_WIDTH = 73  # the outputs line after "out    ", in 80 columns
OUTPUTS_GAP = "  |  "
ALERT_WIDTH = 34  # why an output stopped: at most this much of the line
TARGET_MIN = 7  # a target shortened below this says nothing: left out


def _figures(c: PanelCell) -> str:
    bits = [*([f"{_num(c.rate_hz)} Hz"] if c.rate else []),
            *([_size(c.size_bytes)] if c.size_bytes is not None else []),
            *([_clock(c.duration_s)] if c.duration_s is not None else []),
            *([str(c.frames) if c.frames < 10000 else f"{c.frames // 1000}k"]
              if c.frames is not None else [])]
    return " ".join(bits)


def _widths(cells: Sequence[PanelCell], room: int) -> list[tuple[int, int]]:
    """Each cell's (target, alert) width within ``room``: alerts first (up to
    ALERT_WIDTH), then targets in order, a target left out rather than cut below
    TARGET_MIN."""
    fixed = sum(len(c.label) + len(f" {_figures(c)}" if _figures(c) else "")
                + (len(f" {c.errors} err") if c.errors else 0) for c in cells)
    left = room - fixed - len(OUTPUTS_GAP) * (len(cells) - 1)
    alerts = []
    for c in cells:
        want = min(len(c.alert) + 1, ALERT_WIDTH + 1) if c.alert else 0
        alerts.append(max(0, min(want, left)))
        left -= alerts[-1]
    targets = []
    for c in cells:
        want = len(c.target) + 1 if c.target else 0
        got = min(want, left)
        targets.append(got if got > TARGET_MIN else 0)
        left -= targets[-1]
    return [(max(t - 1, 0), max(a - 1, 0)) for t, a in zip(targets, alerts, strict=True)]


def outputs_line(cells: Sequence[PanelCell]) -> Text:
    """Each output's cell (its own :class:`~handrig.outputs.base.PanelCell`), in order,
    fitted into 80 columns; "none" when there is none."""
    text = Text.assemble(("out    ", "bold"))
    shown = [c for c in cells if c.label]
    if not shown:
        text.append("none", "dim")
        return text
    for i, (c, (target_w, alert_w)) in enumerate(zip(shown, _widths(shown, OUTPUTS_WIDTH),
                                                      strict=True)):
        if i:
            text.append(OUTPUTS_GAP)
        head = " ".join(x for x in (c.label, _fit_left(c.target, target_w) if target_w
                                    else "", _figures(c)) if x)
        text.append(head, "" if c.ok else "yellow")
        if c.errors:
            text.append(f" {c.errors} err", "bold red")
        if alert_w:
            text.append(f" {_fit(c.alert, alert_w)}", "bold red")
    return text


def output_words(c: PanelCell) -> str:
    """One output's cell in full, for the plain line."""
    return " ".join(x for x in (c.label, c.target, _figures(c),
                                f"{c.errors} errors" if c.errors else "", c.alert) if x)


def _servo_cell(sv: ServoLine | None) -> Text:
    if sv is None:
        return Text(" " * 37)
    hot = ""
    t = sv.temperature_c
    if math.isfinite(t):
        red = min(sv.act_c, sv.temperature_limit_c) if math.isfinite(sv.act_c) \
            else sv.temperature_limit_c
        yellow = sv.warn_c if math.isfinite(sv.warn_c) else sv.temperature_limit_c - 10
        hot = "bold red" if t >= red else "yellow" if t >= yellow else ""
    err = fault_letters(sv.hardware_error)
    current = abs(sv.current_ma) if math.isfinite(sv.current_ma) else NAN
    return Text.assemble(
        f"{sv.id:>2} {short_joint(sv.joint):<10} {_deg(sv.goal_deg):>5} ",
        (f"{_deg(sv.present_deg):>5}", "dim" if sv.stale else ""), " ",
        (f"{_num(sv.temperature_c):>3}", hot), f" {_num(current):>4} ",
        (f"{err or '-':<2}", "bold red" if err else "dim"),
    )


SERVO_HEADER = " id joint       goal   now  °C   mA er"


def servo_rows(servos: Sequence[ServoLine]) -> list[Text]:
    """The servo table: a header, then two servos per line (first half left)."""
    half = -(-len(servos) // SERVO_COLUMNS)
    gap = " │ "
    rows = [Text(_fit(SERVO_HEADER[1:] + " " + gap + SERVO_HEADER[1:], WIDTH), "bold dim")]
    for r in range(half):
        left = servos[r]
        right = servos[r + half] if r + half < len(servos) else None
        rows.append(Text.assemble(_servo_cell(left), gap, _servo_cell(right)))
    return rows


LEGEND = "er: V voltage H overheating E encoder S shock L overload; now dimmed: stale"


def cues_line(s: PanelSnapshot) -> Text:
    """The last cues taken, newest first, as many as fit."""
    return Text(_fit("cues   " + " < ".join(reversed(s.cues)), WIDTH), "cyan")


def keys_line(s: PanelSnapshot) -> Text:
    if not s.keys:
        return Text("keys off: Ctrl-C stops (ease, then torque off)", "dim")
    text = Text()
    for key, what in SHOW_KEYS.items():
        text.append(" space " if key == " " else f" {key} ", "reverse")
        text.append(f" {what} ")
    return text


def layers_line(layers: tuple[str, ...]) -> Text:
    """The takes layered under the glove: each its group, take and fade state."""
    return Text(_fit("layers " + "; ".join(layers), WIDTH), "magenta")


def render(s: PanelSnapshot, height: int = HEIGHT) -> Group:
    """One frame of the panel: at most 80 columns and ``height`` lines."""
    hands = [Text(_fit(line, WIDTH)) for line in s.hands]
    head = [mode_line(s), *(hands or [glove_line(s.glove), loop_line(s)]), bus_line(s.bus),
            outputs_line(s.outputs), *([cues_line(s)] if s.cues else []),
            *([layers_line(s.layers)] if s.layers else [])]
    rows = servo_rows(s.servos)
    fits = height - len(head) - 2  # the legend and the keys are always shown
    if len(rows) > fits:  # 40 servos in a short terminal: the keys stay, rows are cut
        hidden = len(rows) - max(1, fits - 1)
        rows = [*rows[:max(1, fits - 1)],
                Text(_fit(f"... {hidden} more rows of servos: a taller terminal shows them",
                          WIDTH), "dim")]
    lines = [*head, *rows, Text(_fit(LEGEND, WIDTH), "dim")]
    room = height - len(lines) - 1
    for event in s.events[-max(0, min(room, 3)):] if room > 0 else ():
        lines.append(Text(_fit(event, WIDTH), "yellow"))
    lines.append(keys_line(s))
    for line in lines:
        line.truncate(WIDTH)
    return Group(*lines[:height])


def plain_line(s: PanelSnapshot) -> str:
    """The snapshot as one line of text (no terminal: a log, a pipe)."""
    g, b, o = s.glove, s.bus, s.outputs
    hot = max((sv.temperature_c for sv in s.servos if math.isfinite(sv.temperature_c)),
              default=NAN)
    faults = sum(1 for sv in s.servos if sv.hardware_error)
    warm = [str(sv.id) for sv in s.servos if math.isfinite(sv.temperature_c)
            and math.isfinite(sv.warn_c) and sv.temperature_c >= sv.warn_c]
    parts = [
        *([f"show {s.show}"] if s.show else []),
        f"{_clock(s.elapsed_s)} {s.mode}" + (f" ({s.reason})" if s.reason else ""),
        *s.hands,
        f"glove {_num(g.rate_hz, '.0f')} Hz err {g.errors} last {_age(g.last_frame_age_s)}"
        f" reconnects {g.reconnects}",
        f"latency p50 {_num(s.latency_p50_us)} p99 {_num(s.latency_p99_us)} us",
        f"bus {_num(b.read_rate_hz)} reads/s timeouts {b.timeouts}"
        + (f" (host {b.host_timeouts})" if b.host_timeouts else "")
        + f" errors {b.errors} stale "
        + (f"{b.stale_servos} (worst {_age(b.stale_worst_age_s)})" if b.stale_servos
           else "none")
        + (f" left out {b.left_out}" if b.left_out else "")
        + (f" admitted {b.admitted}" if b.admitted else ""),
        f"servos max {_num(hot)} C" + (f" (past [heat] warn_c: {', '.join(warm)})"
                                       if warm else "") + f", {faults} with errors",
        " | ".join(output_words(c) for c in o if c.label) or "outputs none",
        *([f"cues {' < '.join(reversed(s.cues[-3:]))}"] if s.cues else []),
        *([f"layers {'; '.join(s.layers)}"] if s.layers else []),
    ]
    return " | ".join(parts)


# -- the live panel --------------------------------------------------------------------


def show_console() -> Console:
    """The console a show's panel draws on: stdout when it is a terminal; else plain
    lines on stderr, so that stdout carries only the summary."""
    out = Console()
    return out if out.is_terminal else Console(stderr=True, force_terminal=False)



class LivePanel:
    """Redraws a :class:`PanelSnapshot` from ``source`` while the show runs.

    ``source``: a callable returning the current snapshot (called from the
    panel's thread), e.g. a :class:`~handrig.app.rig_snapshot.RigSnapshot`.
    ``header``: lines printed once, above the panel (the commissioning report).
    On a terminal the panel redraws at ``refresh_hz`` below what was printed
    before it; :meth:`log` prints above it. Without a terminal it prints
    :func:`plain_line` every ``plain_every_s`` seconds and once at the end.
    """

    def __init__(
        self,
        source: Callable[[], PanelSnapshot],
        refresh_hz: float = 4.0,
        console: Console | None = None,
        *,
        header: Sequence[str] = (),
        plain_every_s: float = 5.0,
    ) -> None:
        self.source: Callable[[], PanelSnapshot] = source
        self.refresh_s = 1.0 / refresh_hz
        self.plain_every_s = plain_every_s
        self.console = console or Console()
        self.header = tuple(header)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._live: Live | None = None
        self.failure = ""  # the source's error, if it raised (the panel then stops)

    def _snapshot(self) -> PanelSnapshot | None:
        try:
            return self.source()
        except Exception as exc:  # the panel must never take the show down with it
            self.failure = f"panel stopped: the snapshot failed: {exc!r}"
            return None

    def log(self, text: str) -> None:
        """Print a line above the panel (or as a line without a terminal)."""
        self.console.print(text, markup=False, highlight=False, soft_wrap=True)

    def _loop_live(self) -> None:
        first = self._snapshot()
        if first is None:
            return
        height = max(8, self.console.size.height)  # all of a taller terminal (40 servos)
        with Live(render(first, height), console=self.console, auto_refresh=False,
                  transient=False, vertical_overflow="crop") as live:
            self._live = live
            while not self._stop.wait(self.refresh_s):
                snap = self._snapshot()
                if snap is None:
                    break
                live.update(render(snap, max(8, self.console.size.height)), refresh=True)
            snap = self._snapshot()
            if snap is not None:
                live.update(render(snap, height), refresh=True)
            self._live = None
        if self.failure:
            self.log(self.failure)

    def _loop_plain(self) -> None:
        while not self._stop.wait(self.plain_every_s):
            snap = self._snapshot()
            if snap is None:
                break
            self.log(plain_line(snap))
        snap = self._snapshot()
        if snap is not None:
            self.log(plain_line(snap))
        if self.failure:
            self.log(self.failure)

    def __enter__(self) -> LivePanel:
        for line in self.header:
            self.log(line)
        target = self._loop_live if self.console.is_terminal else self._loop_plain
        self._thread = threading.Thread(target=target, name="handrig-panel", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)


def heat_colours(rig_cfg: Any) -> dict[str, Any]:
    """The panel's temperature colours for a rig (RigSnapshot's keywords): each servo's
    Temperature Limit by its model, and the rig's [heat] warn and act tiers."""
    return {"temperature_limit_c": {s.id: temperature_limit_c(s) for s in rig_cfg.servos},
            "heat_c": (rig_cfg.heat.warn_c, rig_cfg.heat.act_c)}


@contextlib.contextmanager
def show_panel(snapshot: Any, header: list[str], keys: Any, log: Callable[[str], None],
               on_panel: Callable[[Any], None]) -> Iterator[None]:
    """The live panel over ``snapshot`` for the block: drawn on a terminal (``header``
    above it), else plain status lines after ``header`` is logged; the show ``keys``
    (a KeyReader, or None) read meanwhile. ``on_panel`` gets the panel while it draws
    on a terminal (log lines then go above it), and None when it ends."""
    console = show_console()
    if not console.is_terminal:  # plain status lines there; the log stays where it was
        for line in header:
            log(line)
        header = []
    panel = LivePanel(snapshot, console=console, header=header)
    with panel:
        if console.is_terminal:
            on_panel(panel)
        try:
            if keys is not None:
                with keys.start():
                    yield
            else:
                yield
        finally:
            on_panel(None)
