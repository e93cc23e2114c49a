"""The view's HTTP and WebSocket server, in its own thread with its own event loop.

The page and its JavaScript are files of this package (``static/``), served as they
are; the page opens ``/ws`` and gets the scene once, then frames. One producer reads
``latest()`` at ``rate_hz`` (30 by default) and encodes a new snapshot once; each
browser has a sender that always sends the newest frame, so a slow browser skips
frames instead of queueing them, and the loop's thread never waits for the view.

``websockets`` does the HTTP and WebSocket work: a small library without
dependencies, maintained for years, whose asyncio server answers plain HTTP
requests too (``process_request``), so one port serves the page and its socket.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import hmac
import json
import mimetypes
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from http import HTTPStatus
from pathlib import Path
from typing import TYPE_CHECKING, Protocol
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from handrig.app.view.encode import FrameEncoder, HandsSnapshot
from handrig.errors import ConfigError

if TYPE_CHECKING:
    from handrig.loop.telemetry import LoopSnapshot

STATIC_DIR = Path(__file__).with_name("static")
MAX_MESSAGE_BYTES = 1024  # a button press is a few dozen bytes; more closes the socket
# How far behind a browser may fall before it skips frames: what waits in the server's
# buffer (WRITE_LIMIT_BYTES) and in the kernel's send buffer (SEND_BUFFER_BYTES, which
# Linux doubles). A frame of the human rig is about 5 kB, so at most about 17 frames
# (0.55 s at 30 a second) are on their way to a slow browser; left to itself the kernel
# grows its buffer to 4 MB, 20 s of stale frames for a browser on a weak link.
WRITE_LIMIT_BYTES = 16 * 1024
SEND_BUFFER_BYTES = 32 * 1024
# At close, how long browsers have to answer the close; then their sockets are cut (a
# browser that stopped reading, or whose network is gone, must not hold the run's exit).
CLOSE_GRACE_S = 1.0
# The Host names a view without a token answers to, besides the address it is bound to.
_LOOPBACK_NAMES = frozenset({"127.0.0.1", "localhost", "::1"})


class RigControls(Protocol):
    """What the page's buttons call: the rig's key actions (safe from another thread)."""

    def toggle_relax(self) -> None: ...
    def request_stop(self, reason: str = ...) -> None: ...
    def estop(self, reason: str = ...) -> None: ...


class HandsControls(RigControls, Protocol):
    """A session's controls of every hand (:class:`handrig.app.hands.AllHands`): the
    buttons' actions, and the last few cues taken, for the page to list."""

    def recent_cues(self) -> tuple[str, ...]: ...


@dataclass
class ViewStats:
    """Counters of the view, for the benchmark and the tests."""

    frames_encoded: int = 0
    frames_sent: int = 0
    frames_skipped: int = 0  # frames a slow browser never got (a newer one was sent)
    browsers: int = 0  # connected now
    browsers_total: int = 0
    bad_messages: int = 0
    actions: list[str] = field(default_factory=list)
    encode_s: float = 0.0  # thread time spent encoding frames


class _Browser:
    def __init__(self) -> None:
        self.wake = asyncio.Event()
        self.last_frame = -1  # the producer's count of the last frame sent


def _files() -> dict[str, tuple[Path, str]]:
    """URL path -> (file, content type) for every file the page may load."""
    out: dict[str, tuple[Path, str]] = {}
    for path in sorted(STATIC_DIR.rglob("*")):
        if path.is_file():
            kind = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
            if path.suffix == ".js":
                kind = "text/javascript"
            out["/static/" + path.relative_to(STATIC_DIR).as_posix()] = (path, kind)
    return out


class ViewServer:
    """Serves the page on ``host:port`` (port 0: any free port) from :meth:`start` to
    :meth:`close`. ``token``: when set, the page and its socket need ``?token=``.
    Attach a snapshot source and the rig's controls with :meth:`attach`."""

    def __init__(self, host: str, port: int, encoder: FrameEncoder, *, token: str | None = None,
                 rate_hz: float = 30.0, flag: str = "--view") -> None:
        if not 1.0 <= rate_hz <= 60.0:
            raise ConfigError("view rate out of range", key="rate_hz", value=rate_hz,
                              allowed="1 to 60 frames a second")
        self.host, self.port, self.token = host, port, token
        self.encoder = encoder
        self.period_s = 1.0 / rate_hz
        self.flag = flag
        self.stats = ViewStats()
        self._files = _files()
        self._source: Callable[[], LoopSnapshot | HandsSnapshot | None] = lambda: None
        self._controls: RigControls | None = None
        self._scene = ""
        self._latest: tuple[int, str] | None = None
        self._browsers: set[_Browser] = set()
        self._sockets: set[ServerConnection] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    # -- the caller's side -----------------------------------------------------------------
    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/" + (f"?token={self.token}" if self.token else "")

    @property
    def native_thread_id(self) -> int | None:
        """The server thread's OS id while it runs (its CPU time is in /proc)."""
        return self._thread.native_id if self._thread is not None else None

    def attach(self, source: Callable[[], LoopSnapshot | HandsSnapshot | None],
               controls: RigControls | None = None) -> None:
        """Show what ``source`` returns (``rig.telemetry.latest``, or both hands'
        snapshots in a two-hand run); the buttons call ``controls`` (the rig, or what
        acts on both hands), none when None."""
        self._source = source
        self._controls = controls

    def start(self) -> ViewServer:
        """Bind and serve; ConfigError naming the port when it is taken."""
        self._scene = self.encoder.scene()
        self._thread = threading.Thread(target=self._run, name="handrig-view", daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            self._thread.join()
            self._thread = None
            exc = self._error
            if isinstance(exc, OSError) and exc.errno == errno.EADDRINUSE:
                raise ConfigError(f"port {self.port} on {self.host} is in use (another "
                                  "handrig --view, or another server)", key=self.flag,
                                  value=f"{self.host}:{self.port}",
                                  allowed="a free port, e.g. --view 8766, or 0 for any") from None
            raise ConfigError(f"cannot serve the view on {self.host}:{self.port}: {exc}",
                              key=self.flag, value=f"{self.host}:{self.port}",
                              allowed="an address of this machine and a free port") from None
        return self

    def close(self) -> None:
        """Close every socket and stop the server thread (idempotent)."""
        loop, stop, thread = self._loop, self._stop, self._thread
        if loop is not None and stop is not None and thread is not None:
            with contextlib.suppress(RuntimeError):  # the loop is already closed
                loop.call_soon_threadsafe(stop.set)
            thread.join(timeout=5.0)
        self._thread = None

    def __enter__(self) -> ViewServer:
        return self.start() if self._thread is None else self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the server thread -------------------------------------------------------------------
    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:  # reported by start()
            if not self._ready.is_set():
                self._error = exc
                self._ready.set()
            else:
                raise

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        server: Server
        async with serve(self._handle, self.host, self.port, process_request=self._http,
                         max_size=MAX_MESSAGE_BYTES, write_limit=WRITE_LIMIT_BYTES,
                         ping_interval=10, ping_timeout=20, close_timeout=CLOSE_GRACE_S,
                         server_header=None) as server:
            sock = next(iter(server.sockets))
            self.port = int(sock.getsockname()[1])
            self._ready.set()
            producer = asyncio.create_task(self._produce())
            await self._stop.wait()
            producer.cancel()
            server.close(close_connections=True)  # a close frame to every browser
            try:
                await asyncio.wait_for(asyncio.shield(server.wait_closed()), CLOSE_GRACE_S)
            except TimeoutError:
                # a browser that does not read cannot take its close frame (its close
                # waits behind the frames it did not read, with no deadline): cut it
                for ws in list(self._sockets):
                    ws.transport.abort()
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(server.wait_closed(), CLOSE_GRACE_S)

    def _host_served(self, request: Request) -> bool:
        """Whether the request names this view in its Host: a loopback name or the bound
        address. A page of another site whose name was made to point at this machine (DNS
        rebinding) names its own site, and is refused unless it holds the token."""
        host = str(request.headers.get("Host", "")).strip().lower()
        if host.startswith("["):
            name = host[1:host.find("]")] if "]" in host else host
        else:
            name = host.rpartition(":")[0] if ":" in host else host
        return name in _LOOPBACK_NAMES or name == self.host.lower()

    def _authorised(self, path: str) -> bool:
        if self.token is None:
            return True
        given = parse_qs(urlsplit(path).query).get("token", [""])[0]
        return hmac.compare_digest(given.encode(), self.token.encode())

    @staticmethod
    def _same_origin(request: Request) -> bool:
        """A browser names the page that opens a socket (Origin): it must be this server's
        own page (the Host it asked for). Programs that send no Origin are let in (they
        are on this machine, or hold the token)."""
        origin = request.headers.get("Origin")
        if origin is None:
            return True
        return urlsplit(origin).netloc.lower() == str(request.headers.get("Host", "")).lower()

    def _http(self, connection: ServerConnection, request: Request) -> Response | None:
        path = urlsplit(request.path).path
        if self.token is None and not self._host_served(request):
            # with a token in use, any name (this machine's on the network) is fine for
            # whoever holds it: the page and its socket check it below
            return connection.respond(HTTPStatus.FORBIDDEN,
                                      "this view answers to 127.0.0.1, localhost and [::1] "
                                      "only: open the URL exactly as printed\n")
        if path == "/ws":
            if not self._authorised(request.path):
                return connection.respond(HTTPStatus.FORBIDDEN, "token missing or wrong\n")
            if not self._same_origin(request):
                # another site's page in the user's browser must not press the buttons
                return connection.respond(HTTPStatus.FORBIDDEN, "not this view's page\n")
            return None  # the WebSocket handshake goes on
        if path in ("/", "/index.html"):
            if not self._authorised(request.path):
                return connection.respond(
                    HTTPStatus.FORBIDDEN, "this view needs the token printed at the start: "
                    "open the URL exactly as printed\n")
            return self._file(STATIC_DIR / "index.html", "text/html; charset=utf-8")
        found = self._files.get(path)
        if found is None:
            return connection.respond(HTTPStatus.NOT_FOUND, "not found\n")
        return self._file(*found)

    @staticmethod
    def _file(path: Path, kind: str) -> Response:
        body = path.read_bytes()
        headers = Headers([("Content-Type", kind), ("Content-Length", str(len(body))),
                           ("Cache-Control", "no-cache")])
        return Response(200, "OK", headers, body)

    async def _produce(self) -> None:
        last_seq = -1
        while True:
            snap = self._source()
            if snap is not None and snap.seq != last_seq and self._browsers:
                t0 = time.thread_time()
                text = self.encoder.frame(snap)
                self.stats.encode_s += time.thread_time() - t0
                self.stats.frames_encoded += 1
                last_seq = snap.seq
                self._latest = (self.stats.frames_encoded, text)
                for browser in self._browsers:
                    browser.wake.set()
            await asyncio.sleep(self.period_s)

    async def _handle(self, ws: ServerConnection) -> None:
        sock = ws.transport.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER_BYTES)
        self._sockets.add(ws)
        browser = _Browser()
        self._browsers.add(browser)
        self.stats.browsers = len(self._browsers)
        self.stats.browsers_total += 1
        sender = asyncio.create_task(self._send(ws, browser))
        try:
            async for message in ws:
                self._on_message(message)
        except ConnectionClosed:
            pass
        finally:
            self._sockets.discard(ws)
            self._browsers.discard(browser)
            self.stats.browsers = len(self._browsers)
            sender.cancel()

    async def _send(self, ws: ServerConnection, browser: _Browser) -> None:
        with contextlib.suppress(ConnectionClosed):
            await ws.send(self._scene)
            while True:
                await browser.wake.wait()
                browser.wake.clear()
                latest = self._latest
                if latest is None or latest[0] == browser.last_frame:
                    continue
                count, text = latest
                if browser.last_frame >= 0:
                    self.stats.frames_skipped += count - browser.last_frame - 1
                await ws.send(text)  # waits while this browser's buffer is full
                self.stats.frames_sent += 1
                browser.last_frame = count

    def _on_message(self, message: str | bytes) -> None:
        """A button press: ``{"action": "relax" | "stop" | "estop"}``; anything else is
        counted and dropped."""
        try:
            action = json.loads(message).get("action") if isinstance(message, str) else None
        except (ValueError, AttributeError):
            action = None
        controls = self._controls
        if controls is None or action not in self.encoder.actions:
            self.stats.bad_messages += 1
            return
        self.stats.actions.append(action)
        if action == "estop":
            controls.estop("e-stop button (view)")
        elif action == "stop":
            controls.request_stop("stop button (view)")
        elif action == "relax":
            controls.toggle_relax()
