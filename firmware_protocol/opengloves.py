"""The OpenGloves / LucidGloves "alpha" serial line format: a pure codec.

One ASCII line per sample, at 115200 baud (LucidVR lucidgloves ``AlphaEncoding``;
opengloves-driver ``alpha_encoding_service``)::

    A<thumb>B<index>C<middle>D<ring>E<pinky>F<joyX>G<joyY>P<trigger><buttons>\\n

Values are decimal 0..ANALOG_MAX (1023 on AVR boards, 4095 on ESP32), 0 = open.
Button letters appear, without a value, only while pressed: ``H`` joystick click,
``I`` trigger, ``J`` A, ``K`` B, ``L`` grab, ``M`` pinch, ``N`` menu, ``O``
calibrate. Optional splay ``(AB)n`` .. ``(EB)n`` (neutral at ANALOG_MAX / 2) and
per-joint overrides ``(AAA)n`` .. ``(EAD)n`` (finger A..E, joint A..D).

There is no checksum, so a line can arrive cut short or merged with the next.
The parser therefore rejects a line that lacks any of the five fingers, repeats
a key, holds an unknown character or a value above ANALOG_MAX; the streaming
:class:`LineDecoder` counts each kind and never raises.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass

FINGER_LETTERS = "ABCDE"
BUTTON_LETTERS = "HIJKLMNO"
"""Button letters in order: joystick click, trigger, A, B, grab, pinch, menu, calibrate."""
VALUE_LETTERS = "ABCDEFGP"
ANALOG_MAX_AVR = 1023
ANALOG_MAX_ESP32 = 4095
MAX_LINE = 256
"""Longest line accepted (a full line with splay and all joints is about 130 bytes)."""

CHANNEL_KEYS: tuple[str, ...] = (
    "A", "B", "C", "D", "E", "(AB)", "(BB)", "(CB)", "(DB)", "(EB)", "F", "G", "P",
)
"""The raw channel order handrig gives an OpenGloves sample: five fingers, five
splays, joystick x and y, trigger (see :meth:`OpenGlovesLine.channels`)."""

_TOKEN = re.compile(r"([A-P])(\d*)|\(([A-E])(B|A[A-D])\)(\d+)")


class LineErrorKind(enum.Enum):
    """Why a line was rejected."""

    SYNTAX = "syntax"
    """A character that is not part of the format (or a value on a button letter)."""
    MISSING = "missing"
    """A finger value is missing: the line was cut short."""
    DUPLICATE = "duplicate"
    """A key appears twice: two lines ran together."""
    RANGE = "range"
    """A value above ANALOG_MAX."""
    OVERFLOW = "overflow"
    """More than :data:`MAX_LINE` bytes without a newline."""


class LineError(ValueError):
    """A line that cannot be parsed; ``kind`` says why."""

    def __init__(self, kind: LineErrorKind, message: str) -> None:
        self.kind = kind
        super().__init__(message)


@dataclass(frozen=True, slots=True)
class OpenGlovesLine:
    """One parsed alpha line. Values are raw counts 0..ANALOG_MAX; ``None`` = absent."""

    fingers: tuple[int, int, int, int, int]
    joystick: tuple[int, int] | None = None
    trigger: int | None = None
    buttons: frozenset[str] = frozenset()
    splay: tuple[int | None, int | None, int | None, int | None, int | None] = (
        None, None, None, None, None,
    )
    joints: tuple[tuple[int | None, ...], ...] = ((None,) * 4,) * 5
    """Per-joint overrides: ``joints[finger][joint]``, finger A..E, joint A..D."""

    def channels(self, analog_max: int) -> tuple[float, ...]:
        """The 13 values in :data:`CHANNEL_KEYS` order; an absent splay or joystick
        axis reads as neutral (``analog_max / 2``), an absent trigger as 0."""
        mid = analog_max / 2
        splay = tuple(mid if v is None else float(v) for v in self.splay)
        joy = (mid, mid) if self.joystick is None else self.joystick
        trig = 0 if self.trigger is None else self.trigger
        return (*map(float, self.fingers), *splay, float(joy[0]), float(joy[1]), float(trig))

    def button_bits(self) -> int:
        """Buttons as a bitfield, bit ``i`` = ``BUTTON_LETTERS[i]`` pressed."""
        bits = 0
        for i, letter in enumerate(BUTTON_LETTERS):
            if letter in self.buttons:
                bits |= 1 << i
        return bits


def parse_line(line: str | bytes, analog_max: int = ANALOG_MAX_ESP32) -> OpenGlovesLine:
    """Parse one line (with or without its ``\\n``); raises :class:`LineError` only."""
    if isinstance(line, bytes | bytearray):
        try:
            text = bytes(line).decode("ascii")
        except UnicodeDecodeError:
            raise LineError(LineErrorKind.SYNTAX, "non-ASCII byte in line") from None
    else:
        text = line
    text = text.rstrip("\r\n")
    if text[:1].isdigit():
        raise LineError(LineErrorKind.MISSING, "line starts mid-value: its start was cut")
    values: dict[str, int] = {}
    buttons: set[str] = set()
    pos = 0
    end = len(text)
    while pos < end:
        m = _TOKEN.match(text, pos)
        if m is None:
            raise LineError(LineErrorKind.SYNTAX, f"unexpected {text[pos]!r} at column {pos}")
        letter, digits, finger, sub, pdigits = m.groups()
        if letter is not None:
            key = letter
            if letter in BUTTON_LETTERS:
                if digits:
                    raise LineError(LineErrorKind.SYNTAX, f"button {letter} carries a value")
                if letter in buttons:
                    raise LineError(LineErrorKind.DUPLICATE, f"button {letter} twice")
                buttons.add(letter)
                pos = m.end()
                continue
            if not digits:
                raise LineError(LineErrorKind.MISSING, f"{letter} has no value")
        else:
            key, digits = f"({finger}{sub})", pdigits
        if key in values:
            raise LineError(LineErrorKind.DUPLICATE, f"{key} twice: lines ran together")
        if len(digits) > 6 or int(digits) > analog_max:
            raise LineError(LineErrorKind.RANGE, f"{key}{digits} above {analog_max}")
        values[key] = int(digits)
        pos = m.end()
    missing = [f for f in FINGER_LETTERS if f not in values]
    if missing:
        raise LineError(LineErrorKind.MISSING, f"finger {''.join(missing)} missing: line cut")
    fingers = (values["A"], values["B"], values["C"], values["D"], values["E"])
    jx, jy = values.get("F"), values.get("G")
    joystick = (jx, jy) if jx is not None and jy is not None else None
    splay = tuple(values.get(f"({f}B)") for f in FINGER_LETTERS)
    joints = tuple(
        tuple(values.get(f"({f}A{j})") for j in "ABCD") for f in FINGER_LETTERS
    )
    return OpenGlovesLine(
        fingers, joystick, values.get("P"), frozenset(buttons),
        splay,  # type: ignore[arg-type]
        joints,
    )


def encode_line(line: OpenGlovesLine) -> bytes:
    """``line`` in alpha encoding, newline included (what a LucidGloves board sends)."""
    parts = [f"{letter}{v}" for letter, v in zip(FINGER_LETTERS, line.fingers, strict=True)]
    if line.joystick is not None:
        parts += [f"F{line.joystick[0]}", f"G{line.joystick[1]}"]
    if line.trigger is not None:
        parts.append(f"P{line.trigger}")
    parts += [b for b in BUTTON_LETTERS if b in line.buttons]
    parts += [f"({f}B){v}" for f, v in zip(FINGER_LETTERS, line.splay, strict=True)
              if v is not None]
    for f, row in zip(FINGER_LETTERS, line.joints, strict=True):
        parts += [f"({f}A{j}){v}" for j, v in zip("ABCD", row, strict=True) if v is not None]
    return ("".join(parts) + "\n").encode("ascii")


def encode_force_feedback(values: tuple[int, int, int, int, int]) -> bytes:
    """Host-to-glove force feedback line ``A<t>B<i>C<m>D<r>E<p>\\n``, each 0..1000."""
    for v in values:
        if not 0 <= v <= 1000:
            raise ValueError(f"force feedback value {v} outside 0..1000")
    return ("".join(f"{k}{v}" for k, v in zip(FINGER_LETTERS, values, strict=True))
            + "\n").encode("ascii")


@dataclass
class LineStats:
    """Counters of a :class:`LineDecoder` (all monotonic)."""

    lines_ok: int = 0
    syntax_errors: int = 0
    cut_lines: int = 0
    merged_lines: int = 0
    range_errors: int = 0
    overflows: int = 0
    garbage_bytes: int = 0

    @property
    def errors(self) -> int:
        """Rejected lines of every kind."""
        return (self.syntax_errors + self.cut_lines + self.merged_lines + self.range_errors
                + self.overflows)


_LINE_COUNTER = {
    LineErrorKind.SYNTAX: "syntax_errors",
    LineErrorKind.MISSING: "cut_lines",
    LineErrorKind.DUPLICATE: "merged_lines",
    LineErrorKind.RANGE: "range_errors",
    LineErrorKind.OVERFLOW: "overflows",
}


class LineDecoder:
    """Streaming alpha-line decoder: feed byte chunks, get parsed lines back.

    Rejected lines are dropped and counted in :attr:`stats`; a run longer than
    :data:`MAX_LINE` without a newline is dropped up to the next newline. Blank
    lines are ignored. Never raises on input.
    """

    def __init__(self, analog_max: int = ANALOG_MAX_ESP32) -> None:
        if analog_max < 1:
            raise ValueError(f"analog_max must be positive, got {analog_max}")
        self.analog_max = analog_max
        self.stats = LineStats()
        self.last_error: LineError | None = None
        self._buf = bytearray()
        self._discarding = False

    def reset(self) -> None:
        """Forget a partial line (counters are kept)."""
        self._buf.clear()
        self._discarding = False

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[OpenGlovesLine]:
        """Lines completed by ``chunk`` (possibly none)."""
        out: list[OpenGlovesLine] = []
        data = bytes(chunk)
        start = 0
        while start < len(data):
            nl = data.find(b"\n", start)
            stop = len(data) if nl < 0 else nl
            if self._discarding:
                self.stats.garbage_bytes += stop - start
            else:
                self._buf += data[start:stop]
                if len(self._buf) > MAX_LINE:
                    self._reject(LineError(LineErrorKind.OVERFLOW,
                                           f"{len(self._buf)} bytes without a newline"),
                                 len(self._buf))
                    self._buf.clear()
                    self._discarding = True
            if nl < 0:
                break
            if self._discarding:
                self._discarding = False
            else:
                self._line_done(out)
            start = nl + 1
        return out

    def _line_done(self, out: list[OpenGlovesLine]) -> None:
        raw = bytes(self._buf)
        self._buf.clear()
        if not raw.strip(b"\r"):
            return
        try:
            out.append(parse_line(raw, self.analog_max))
        except LineError as exc:
            self._reject(exc, len(raw) + 1)
            return
        self.stats.lines_ok += 1

    def _reject(self, exc: LineError, nbytes: int) -> None:
        name = _LINE_COUNTER[exc.kind]
        setattr(self.stats, name, getattr(self.stats, name) + 1)
        self.stats.garbage_bytes += nbytes
        self.last_error = exc
