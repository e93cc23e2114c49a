"""``handrig glove monitor``: what the glove sends, live.

Each raw channel as a bar with the lowest and highest reading seen (``|``), the
calibrated degrees of the glove config, the forearm's inclination and rotation
(from the IMU, or the config's ``[forearm]`` when there is none), the frame rate,
errors and the firmware's flags (firmware_protocol/SPEC.md, "Flags"). Works with a
real glove, ``handrig sim-glove`` or the emulated chip (``make sim-avr-glove``).

On a terminal the screen is redrawn every ``--interval`` seconds until Ctrl-C;
otherwise (a pipe, a log, a test) a plain block of text is printed every
``--interval`` seconds, or once with ``--once``. ``--seconds`` stops after that long.
"""

from __future__ import annotations

import argparse
import select
import sys
from typing import Any

from handrig.cli._numbers import positive_float


def glove_subparsers(sub: Any) -> Any:
    """The ``handrig glove`` parser's subcommand set, created on first use."""
    parser = sub.choices.get("glove")
    if parser is None:
        parser = sub.add_parser("glove", help="look at the glove: `handrig glove monitor`",
                                description="Glove tools.")
        parser.set_defaults(func=lambda _args: (parser.print_help(), 2)[1])
        return parser.add_subparsers(dest="glove_what", metavar="WHAT")
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action
    return parser.add_subparsers(dest="glove_what", metavar="WHAT")


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = glove_subparsers(sub).add_parser(
        "monitor", help="live view of each sensor, the IMU, the frame rate and the "
                        "firmware's flags", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--glove", default=None, metavar="PORT",
                   help="glove port, or opengloves:PORT (default: [glove] port of the config)")
    p.add_argument("--glove-config", default=None, metavar="FILE",
                   help="glove config (default: the one `handrig run` uses)")
    p.add_argument("--seconds", type=positive_float, default=None, metavar="S",
                   help="stop after S s (default: until Ctrl-C)")
    p.add_argument("--once", action="store_true",
                   help="print one report after --seconds (default 1 s) and stop")
    p.add_argument("--interval", type=positive_float, default=None, metavar="S",
                   help="seconds between redraws (default 0.1 on a terminal, 1 otherwise)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from handrig.app.glove_monitor import GloveMonitor
    from handrig.clock import MonotonicClock
    from handrig.config.paths import config_file
    from handrig.devices.glove import SerialGlove
    from handrig.devices.glove_calibration import load_glove_config
    from handrig.errors import DeviceError

    cfg = load_glove_config(args.glove_config or config_file("glove.toml"))
    spec = args.glove or cfg.glove.port
    if not spec:
        raise DeviceError("no glove port: pass --glove PORT (or opengloves:PORT), or set "
                          "[glove] port in the glove config")
    clock = MonotonicClock()
    monitor = GloveMonitor(cfg)
    names = [monitor.names.get(k, "") for k in range(max(monitor.names) + 1)]
    if spec.startswith("opengloves:"):
        glove = SerialGlove(spec.removeprefix("opengloves:"), "opengloves", clock=clock,
                            baud=cfg.glove.baud, analog_max=cfg.glove.analog_max,
                            estop_letter=cfg.glove.estop_letter, reader="poll")
    else:
        glove = SerialGlove(spec, "frames", clock=clock, baud=cfg.glove.baud, reader="poll",
                            channel_names=names)
    live = sys.stdout.isatty() and not args.once
    interval = args.interval or (0.1 if live else 1.0)
    seconds = args.seconds if args.seconds is not None else (1.0 if args.once else None)
    start = clock.now()
    next_draw = start + interval
    glove.start()
    try:
        while seconds is None or clock.now() - start < seconds:
            fd = glove.fileno()
            if fd is not None:
                select.select([fd], [], [], 0.02)
            else:
                clock.sleep(0.02)
            glove.pump()
            while (s := glove.take_behind()) is not None:
                monitor.add(s)
            s = glove.take()
            if s is not None:
                monitor.add(s)
            for event in glove.drain_events():
                monitor.note(event)
            now = clock.now()
            if not args.once and now >= next_draw:
                next_draw = now + interval
                _draw(monitor.render(glove.stats(), now), live)
    except KeyboardInterrupt:
        pass
    finally:
        glove.close()
    if args.once or not live:
        _draw(monitor.render(glove.stats(), clock.now()), False)
    return 0 if monitor.samples else 1


def _draw(lines: list[str], live: bool) -> None:
    if live:
        sys.stdout.write("\x1b[H\x1b[J" + "\n".join(lines) + "\n")
    else:
        sys.stdout.write("\n".join(lines) + "\n\n")
    sys.stdout.flush()
