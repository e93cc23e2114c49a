"""The view answers only to the names it serves (issue 41): a page of another site whose
name was pointed at 127.0.0.1 (DNS rebinding) names its own site in Host and Origin,
and is refused; so is a foreign Origin with a loopback Host. With a token any name does
for whoever holds the token."""

from __future__ import annotations

import base64
import http.client
import json
import os
import socket
import time

from handrig.app.view import build_server
from tests.helpers.view import Controls


def _get(port: int, path: str, host: str) -> tuple[int, bytes]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
    try:
        conn.putrequest("GET", path, skip_host=True)
        conn.putheader("Host", host)
        conn.endheaders()
        reply = conn.getresponse()
        return reply.status, reply.read()
    finally:
        conn.close()


def _upgrade(port: int, path: str, host: str, origin: str | None,
             message: bytes | None = None) -> bytes:
    """A raw WebSocket handshake to 127.0.0.1 naming ``host`` (and ``origin``); returns
    the status line. When upgraded and ``message`` given, sends it as a masked text frame."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    try:
        key = base64.b64encode(os.urandom(16)).decode()
        head = (f"GET {path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\n")
        if origin is not None:
            head += f"Origin: {origin}\r\n"
        sock.sendall((head + "\r\n").encode())
        buf = b""
        while b"\r\n\r\n" not in buf:
            data = sock.recv(65536)
            if not data:
                break
            buf += data
        status = buf.split(b"\r\n", 1)[0]
        if status.startswith(b"HTTP/1.1 101") and message is not None:
            mask = os.urandom(4)
            body = bytes(b ^ mask[i % 4] for i, b in enumerate(message))
            sock.sendall(bytes([0x81, 0x80 | len(body)]) + mask + body)
            time.sleep(0.2)
        return status
    finally:
        sock.close()


def test_rebinding_page_is_refused_page_and_socket(human_rig) -> None:  # type: ignore[no-untyped-def]
    controls = Controls()
    with build_server("127.0.0.1:0", human_rig) as server:
        server.attach(lambda: None, controls)
        port = server.port
        evil = f"evil.example:{port}"
        status, body = _get(port, "/", evil)
        assert status == 403 and b"127.0.0.1, localhost and [::1]" in body
        assert _get(port, "/static/view.js", evil)[0] == 403
        relax = json.dumps({"action": "relax"}).encode()
        assert _upgrade(port, "/ws", evil, f"http://{evil}", relax).startswith(b"HTTP/1.1 403")
        assert _upgrade(port, "/ws", evil, None, relax).startswith(b"HTTP/1.1 403")
        # a foreign Origin with a loopback Host: another site's page in the same browser
        assert _upgrade(port, "/ws", f"127.0.0.1:{port}", "http://evil.example",
                        relax).startswith(b"HTTP/1.1 403")
        assert controls.calls == []
        # the names the view serves, each with its own page as Origin
        for name in (f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}", "localhost",
                     f"LOCALHOST:{port}"):
            assert _get(port, "/", name)[0] == 200, name
            assert _upgrade(port, "/ws", name, f"http://{name}").startswith(b"HTTP/1.1 101")
        assert _upgrade(port, "/ws", f"localhost:{port}", f"http://localhost:{port}",
                        relax).startswith(b"HTTP/1.1 101")
        deadline = time.monotonic() + 5
        while not controls.calls and time.monotonic() < deadline:
            time.sleep(0.01)
        assert controls.calls == ["relax"]


def test_with_a_token_any_name_needs_the_token(human_rig) -> None:  # type: ignore[no-untyped-def]
    with build_server("0.0.0.0:0", human_rig) as server:
        port, token = server.port, server.token
        name = f"handrig-box.lan:{port}"  # this machine's name on the network
        assert _get(port, "/", name)[0] == 403
        assert _get(port, f"/?token={token}", name)[0] == 200
        assert _upgrade(port, "/ws", name, f"http://{name}").startswith(b"HTTP/1.1 403")
        assert _upgrade(port, f"/ws?token={token}", name,
                        f"http://{name}").startswith(b"HTTP/1.1 101")
        assert _upgrade(port, f"/ws?token={token}", name,
                        "http://evil.example").startswith(b"HTTP/1.1 403")
