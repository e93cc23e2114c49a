"""Serial port names that last: ``/dev/serial/by-id/`` links, and ports never saved.

A USB adapter's ``/dev/ttyUSB0`` or ``/dev/ttyACM0`` can change with the order
devices are plugged in; udev also names it under ``/dev/serial/by-id/`` after its
vendor, product and serial number, which stays the same. A pseudo-terminal
(``/dev/pts/N``, an emulator's) is gone when its program exits: never saved.
"""

from __future__ import annotations

import os
from pathlib import Path

BY_ID = Path("/dev/serial/by-id")
TRANSIENT_PREFIXES = ("/dev/pts/",)


def is_transient(port: str) -> bool:
    """A port that will not be there next time (a pseudo-terminal)."""
    return port.startswith(TRANSIENT_PREFIXES)


def by_id_for(port: str, folder: Path = BY_ID) -> Path | None:
    """The stable ``/dev/serial/by-id/...`` name of ``port``, if there is one."""
    if not folder.is_dir() or port.startswith(str(folder)):
        return None
    try:
        target = os.path.realpath(port)
        for link in sorted(folder.iterdir()):
            if os.path.realpath(link) == target:
                return link
    except OSError:
        return None
    return None


SIMULATED_FIRST_LINE = ("SIMULATED rig (--port sim): emulated servos, nothing real is "
                        "driven; give --port PORT for the hardware")
"""The first line of every command that runs on the simulated bus."""


def say_if_simulated(port: str | None, *, out: bool = True) -> bool:
    """Print :data:`SIMULATED_FIRST_LINE` when ``port`` is the simulated rig's (``out``
    False: only tell); returns whether it is."""
    simulated = port == "sim"
    if simulated and out:
        print(SIMULATED_FIRST_LINE, flush=True)
    return simulated
