"""The timecode flags of ``run`` (``--ltc``, ``--ltc-fps``) and ``play``
(``--chase-ltc``, ``--chase-at``, ``--ltc-fps``)."""

from __future__ import annotations

import argparse

FPS_CHOICES = ("auto", "24", "25", "29.97", "30")  # handrig.devices.timecode.ltc.RATES


def add_ltc_fps(p: argparse.ArgumentParser) -> None:
    p.add_argument("--ltc-fps", default=None, choices=FPS_CHOICES,
                   help="the rate of the incoming LTC (default auto: from the signal;"
                   " 29.97 is drop-frame)")


def add_ltc(p: argparse.ArgumentParser) -> None:
    p.add_argument("--ltc", default=None, metavar="SOURCE",
                   help="read SMPTE LTC from SOURCE (a .wav file, or alsa:DEVICE such as"
                   " alsa:default): the panel shows the timecode, and with --record each"
                   " frame of the take is stamped with it in TAKE.timecode.csv beside it")
    add_ltc_fps(p)


def add_chase(p: argparse.ArgumentParser) -> None:
    p.add_argument("--chase-ltc", default=None, metavar="SOURCE",
                   help="with --bus: play the take locked to the SMPTE LTC from SOURCE (a"
                   " .wav file or alsa:DEVICE): it starts when the timecode enters the"
                   " take, stops when it stops, jumps when it jumps")
    p.add_argument("--chase-at", default=None, metavar="HH:MM:SS:FF",
                   help="with --chase-ltc: the timecode the take starts at (default: the"
                   " take's own stamps, TAKE.timecode.csv, from `run --ltc --record`)")
    add_ltc_fps(p)
