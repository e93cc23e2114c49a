"""``handrig sim-glove FILE``: stream a glove recording over a pseudo-terminal."""

from __future__ import annotations

import argparse
from typing import Any

from handrig.errors import DataError
from handrig.glove_recording import read_glove_recording


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "sim-glove",
        help="stream a glove recording over a pty, like a USB glove (prints 'port: PATH' first)",
        description="Stream a glove recording (CSV, see handrig/glove_recording.py) over a "
        "pseudo-terminal in real time, as handrig frames or OpenGloves alpha lines. Prints "
        "'port: /dev/pts/N' first; point 'handrig run --glove' at that path.",
    )
    p.add_argument("file", help="glove recording (CSV)")
    p.add_argument("--format", choices=("frames", "opengloves"), default="frames",
                   help="wire format (default: frames, firmware_protocol/SPEC.md)")
    p.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="send at this rate (default: the recording's own timestamps)")
    p.add_argument("--loop", action="store_true", help="start over at the end, until Ctrl-C")
    p.add_argument("--analog-max", type=int, default=4095, choices=(1023, 4095),
                   help="OpenGloves value range (1023 AVR, 4095 ESP32)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from handrig import simulator

    rec = read_glove_recording(args.file)
    if args.rate is not None and not 1.0 <= args.rate <= 5000.0:
        raise DataError(f"--rate {args.rate} out of range: use 1..5000 Hz")
    with simulator.glove_emulator(rec, args.format, rate_hz=args.rate, loop=args.loop,
                                  analog_max=args.analog_max) as emu:
        print(f"port: {emu.port_path}", flush=True)
        rate = args.rate or rec.nominal_rate_hz
        print(f"streaming {len(rec)} samples ({rec.duration_s:.1f} s) as {args.format} at "
              f"{rate:.0f} Hz{' in a loop' if args.loop else ''}; Ctrl-C stops", flush=True)
        try:
            while not emu.done.wait(0.2):
                pass
        except KeyboardInterrupt:
            pass
        sent, dropped = emu.frames_sent, emu.bytes_dropped
    print(f"sent {sent} frames" + (f", {dropped} bytes dropped (nobody reading)"
                                   if dropped else ""), flush=True)
    return 0
