"""``--view [HOST:]PORT``: the address the view listens on, and its token."""

from __future__ import annotations

import ipaddress
import secrets
from pathlib import Path

from handrig.errors import ConfigError

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765


def parse_view_address(text: str) -> tuple[str, int]:
    """``"PORT"``, ``"HOST:PORT"`` or ``"[IPv6]:PORT"`` -> (host, port); ConfigError
    otherwise."""
    host, sep, port_text = text.rpartition(":")
    if not sep:
        host, port_text = DEFAULT_HOST, text
    host = host.strip("[]") or DEFAULT_HOST
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not 0 <= port < 65536:
        raise ConfigError("not a view address", key="--view", value=text,
                          allowed=f"[HOST:]PORT with PORT 0..65535, e.g. {DEFAULT_PORT} or "
                          f"0.0.0.0:{DEFAULT_PORT}")
    return host, port


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def secrets_token() -> str:
    """The random token a view on another interface needs in its URL."""
    return secrets.token_urlsafe(16)


def has_gpu(dri: Path = Path("/dev/dri")) -> bool:
    """Whether this machine has a GPU a browser could draw with (a DRM render node)."""
    try:
        return any(p.name.startswith("renderD") for p in dri.iterdir())
    except OSError:
        return False


def browser_advice(url: str, *, gpu: bool | None = None) -> str | None:
    """A line for the run's start when a browser on this machine would draw the page in
    software (no GPU): where to open it so it does not take the loop's CPU. None when
    there is a GPU, or one CPU (nothing to keep apart)."""
    from handrig.realtime import cpu_split

    if gpu if gpu is not None else has_gpu():
        return None
    loop_cpu, others = cpu_split()
    if loop_cpu is None or not others:
        return None
    cpus = ",".join(str(c) for c in sorted(others))
    return ("view: this machine has no GPU, so a browser here draws the page in software "
            "and competes with the rig for the CPU (docs/view.md); open it from another "
            "machine (--view 0.0.0.0:PORT), or start the browser off the loop's CPU "
            f"{loop_cpu} at idle priority: taskset -c {cpus} chrt --idle 0 chromium '{url}'")
