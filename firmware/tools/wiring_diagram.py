"""Draws firmware/wiring.svg, the glove's wiring diagram, from the table below.

    python firmware/tools/wiring_diagram.py            # rewrites firmware/wiring.svg
    python firmware/tools/wiring_diagram.py --check    # fails if the SVG is stale

Plain SVG written by hand (no dependencies): the board in the middle, the five
sensors on the left as voltage dividers, the IMU, the button and the LED on the
right. The pins here must match firmware/glove/glove_config.h (the test in
tests/firmware/ checks the SVG is what this script draws).
"""

from __future__ import annotations

import sys
from pathlib import Path
from xml.sax.saxutils import escape

OUT = Path(__file__).resolve().parents[1] / "wiring.svg"

DIVIDER = "5V - sensor - {pin} - resistor - GND"
# (label, sensor, pin, its wiring): the order of SPEC.md's channels
SENSORS = (
    ("ch0 thumb CMC twist", "hall sensor + magnet, or 10k pot", "A0",
     "hall: VCC 5V, GND, OUT to A0, no resistor"),
    ("ch1 thumb CMC abduction", "flex sensor 2.2in + 47k to GND", "A1", DIVIDER),
    ("ch2 thumb CMC flexion", "flex sensor 2.2in + 47k to GND", "A2", DIVIDER),
    ("ch3 index MCP flexion", "flex sensor 2.2in + 47k to GND", "A3", DIVIDER),
    ("ch4 little finger MCP flexion", "flex sensor 2.2in + 47k to GND", "A6", DIVIDER),
)
# (pin, what, wire colour): the right-hand side
RIGHT = (
    ("A4 (SDA)", "BNO055 SDA", "#1f77b4"),
    ("A5 (SCL)", "BNO055 SCL", "#17becf"),
    ("5V", "BNO055 VIN (the breakout regulates to 3.3 V)", "#d62728"),
    ("GND", "BNO055 GND", "#000000"),
    ("D2", "relax button to GND (internal pull-up)", "#2ca02c"),
    ("D13", "LED (on board): state", "#ff7f0e"),
    ("D8", "test point (leave open)", "#7f7f7f"),
)

W, H = 1100, 560
BOARD = (420, 70, 220, 420)  # x, y, w, h


def _text(x: float, y: float, s: str, size: int = 13, anchor: str = "start",
          weight: str = "normal") -> str:
    return (f'<text x="{x:.0f}" y="{y:.0f}" font-family="sans-serif" font-size="{size}" '
            f'text-anchor="{anchor}" font-weight="{weight}">{escape(s)}</text>')


def _line(x1: float, y1: float, x2: float, y2: float, colour: str, width: float = 2) -> str:
    return (f'<line x1="{x1:.0f}" y1="{y1:.0f}" x2="{x2:.0f}" y2="{y2:.0f}" '
            f'stroke="{colour}" stroke-width="{width}"/>')


def _divider(x: float, y: float, label: str, sensor: str, pin: str,
             wiring: str) -> list[str]:
    """A sensor's box: what it is and how it is wired to its pin, drawn small."""
    out = [f'<rect x="{x:.0f}" y="{y - 22:.0f}" width="300" height="56" rx="6" '
           'fill="#f7f7f7" stroke="#999"/>',
           _text(x + 8, y - 6, label, 13, weight="bold"),
           _text(x + 8, y + 12, sensor, 12),
           _text(x + 8, y + 28, wiring.format(pin=pin), 11)]
    bx, by = BOARD[0], _pin_y(pin)
    out.append(_line(x + 300, y, bx, by, "#444"))
    return out


LEFT_PINS = ("A0", "A1", "A2", "A3", "A6")


def _pin_y(pin: str) -> float:
    if pin in LEFT_PINS:
        return BOARD[1] + 60 + 70 * LEFT_PINS.index(pin)
    names = [p for p, _, _ in RIGHT]
    return BOARD[1] + 40 + 55 * names.index(pin)


def draw() -> str:
    x, y, w, h = BOARD
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
             f'viewBox="0 0 {W} {H}">',
             '<rect width="100%" height="100%" fill="white"/>',
             _text(W / 2, 30, "handrig glove: Arduino Nano (ATmega328P), five sensors, BNO055, "
                   "relax button", 16, "middle", "bold"),
             _text(W / 2, 50, "drawn by firmware/tools/wiring_diagram.py; pins as in "
                   "firmware/glove/glove_config.h", 11, "middle"),
             f'<rect x="{x}" y="{y}" width="{w}" height="{h}" rx="10" fill="#2b5d8a" '
             'stroke="#123"/>',
             f'<text x="{x + w / 2:.0f}" y="{y + h - 20:.0f}" font-family="sans-serif" '
             'font-size="16" text-anchor="middle" fill="white" font-weight="bold">'
             'Arduino Nano</text>',
             f'<text x="{x + w / 2:.0f}" y="{y + h - 4:.0f}" font-family="sans-serif" '
             'font-size="11" text-anchor="middle" fill="white">USB to the host: '
             '1 Mbps frames</text>']
    for pin in LEFT_PINS:
        py = _pin_y(pin)
        parts.append(f'<text x="{x + 8}" y="{py + 4:.0f}" font-family="monospace" '
                     f'font-size="13" fill="white">{pin}</text>')
    for pin, _, _ in RIGHT:
        py = _pin_y(pin)
        parts.append(f'<text x="{x + w - 8}" y="{py + 4:.0f}" font-family="monospace" '
                     f'font-size="13" fill="white" text-anchor="end">{escape(pin)}</text>')
    for i, (label, sensor, pin, wiring) in enumerate(SENSORS):
        parts += _divider(40, BOARD[1] + 60 + 70 * i, label, sensor, pin, wiring)
    # the title sits above the first wire (SDA): the box starts at the board's top
    bno = (760, BOARD[1], 325, 225)
    parts.append(f'<rect x="{bno[0]}" y="{bno[1]}" width="{bno[2]}" height="{bno[3]}" rx="6" '
                 'fill="#f2f7ee" stroke="#6a6"/>')
    parts.append(_text(bno[0] + 8, bno[1] + 18, "BNO055 breakout (I2C 0x28), on the forearm",
                       12, weight="bold"))
    for pin, what, colour in RIGHT:
        py = _pin_y(pin)
        parts.append(_line(x + w, py, 780, py, colour))
        parts.append(_text(786, py + 4, what, 12))
    parts.append(_text(40, H - 40, "Flex sensor dividers: the resistor near the geometric mean "
                       "of the sensor's flat and bent resistance (2.2in: 25k flat, about 70k bent "
                       "-> 47k; other sensors: measure both).", 11))
    parts.append(_text(40, H - 22, "Hall sensor (SS49E/DRV5053 class): VCC 5V, GND, OUT to the "
                       "pin directly, no resistor; a 3x2 mm magnet on the moving segment.", 11))
    parts.append("</svg>")
    return "\n".join(parts) + "\n"


def main(argv: list[str]) -> int:
    svg = draw()
    if "--check" in argv:
        if not OUT.is_file() or OUT.read_text(encoding="utf-8") != svg:
            print(f"{OUT} is stale: run python {Path(__file__).name}", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(svg, encoding="utf-8")
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
