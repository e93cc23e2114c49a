"""``--view [HOST:]PORT``: the address the view listens on, and its token."""

from __future__ import annotations

import ipaddress
import secrets

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
