"""The cockpit page's web server: aiohttp HTTP + WebSocket on its own asyncio thread.

It serves the three page files in ``web/`` (nothing else is reachable) with strict security headers and
one rate-limited, latest-value-only sender per connected page; it knows nothing of ROS (the node hands
it a ``frame`` function).

**Host check** (DNS rebinding: a web site whose name resolves to 127.0.0.1 would otherwise read the page): every
request's ``Host`` header must be one of ``127.0.0.1``, ``localhost``, ``[::1]``, the bound address, or an
``allowed_hosts`` entry, each with the server's port (a bare name only when the port is 80; an entry that
carries its own port must match exactly). Anything else gets ``421 Misdirected Request`` with a short text.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable, Sequence
from importlib import resources as importlib_resources
from pathlib import Path

from aiohttp import WSCloseCode, WSMsgType, web

__all__ = ["DisplayServerError", "PageServer", "allowed_host_headers", "web_directory"]

# Which page file each URL serves: nothing else in the package (or on disk) is reachable.
_WEB_FILES: dict[str, tuple[str, str]] = {
    "/": ("index.html", "text/html"),
    "/index.html": ("index.html", "text/html"),
    "/app.js": ("app.js", "text/javascript"),
    "/style.css": ("style.css", "text/css"),
}
_SECURITY_HEADERS = {
    # Everything comes from this server; the WebSocket too ('self' covers ws: to the same host in CSP 3).
    "Content-Security-Policy": (
        "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "
        "base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}
_MAX_INCOMING_MESSAGE_BYTES = 4096  # the page sends nothing; a client that does is ignored (or cut off)
_SEND_TIMEOUT_S = 10.0  # a page that cannot take one frame in this long is disconnected


_LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "[::1]")


def _host_literal(host: str) -> str:
    """A host as it appears in a Host header (IPv6 addresses in brackets)."""
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


def allowed_host_headers(bind: str, port: int, extra_hosts: Sequence[str] = ()) -> frozenset[str]:
    """The ``Host`` header values the server answers (lower case; see the module docstring)."""
    allowed: set[str] = set()
    for host in (*_LOOPBACK_HOSTS, bind, *extra_hosts):
        host = host.strip().lower()
        if not host:
            continue
        if (host.startswith("[") and "]:" in host) or (host.count(":") == 1 and not host.startswith("[")):
            allowed.add(host)  # an entry with its own port
            continue
        literal = _host_literal(host)
        allowed.add(f"{literal}:{port}")
        if port == 80:
            allowed.add(literal)
    return frozenset(allowed)


class DisplayServerError(RuntimeError):
    """The web server could not start (address in use, bad bind address, missing page files)."""


def web_directory() -> Path:
    """The folder holding the page (``index.html``, ``app.js``, ``style.css``) inside the package."""
    return Path(str(importlib_resources.files("helireach_ros.display") / "web"))


class PageServer:
    """aiohttp server on its own asyncio thread; one rate-limited, latest-value-only sender per page.

    Args:
        bind: address to listen on.
        port: TCP port (0 = any free port).
        frame: ``frame(sent_versions) -> (json_text, versions)``: the message for a page that has seen
            ``sent_versions`` of the versioned sections (called on the server thread).
        min_interval_s: shortest time between two frames to one page.
        heartbeat_s: longest time between two frames to one page.
        log_warning: where to report page errors.
        allowed_hosts: more host names (or ``name:port``) the ``Host`` header may carry, e.g. for a
            non-loopback bind; loopback and the bound address are always allowed.
    """

    def __init__(
        self,
        bind: str,
        port: int,
        frame: Callable[[dict[str, int]], tuple[str, dict[str, int]]],
        min_interval_s: float,
        heartbeat_s: float,
        log_warning: Callable[[str], None],
        allowed_hosts: Sequence[str] = (),
    ) -> None:
        self._frame = frame
        self._extra_hosts = tuple(allowed_hosts)
        self._allowed_hosts: frozenset[str] = frozenset()  # set once the port is known
        self.min_interval_s = min_interval_s
        self.heartbeat_s = heartbeat_s
        self._log_warning = log_warning
        self._loop = asyncio.new_event_loop()
        self._wakeups: set[asyncio.Event] = set()
        self._sockets: set[web.WebSocketResponse] = set()
        self._wake_pending = False
        self._runner: web.AppRunner | None = None
        self.address: tuple[str, int] | None = None
        started = threading.Event()
        failure: list[BaseException] = []
        self._thread = threading.Thread(
            target=self._run, args=(bind, port, started, failure), name="helireach_display_http", daemon=True
        )
        self._thread.start()
        started.wait()
        if failure:
            self._thread.join(timeout=5.0)
            raise DisplayServerError(f"cannot serve the display on {bind}:{port}: {failure[0]}") from failure[0]

    # -- server thread ---------------------------------------------------------------------------------
    def _run(self, bind: str, port: int, started: threading.Event, failure: list[BaseException]) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._start(bind, port))
        except Exception as error:  # address in use, bad address: reported to the constructor
            failure.append(error)
            started.set()
            self._loop.run_until_complete(self._cleanup())
            self._loop.close()
            return
        started.set()
        self._loop.run_forever()
        self._loop.run_until_complete(self._cleanup())
        self._loop.close()

    async def _start(self, bind: str, port: int) -> None:
        app = web.Application(middlewares=[self._check_host])
        for route in _WEB_FILES:
            app.router.add_get(route, self._serve_file)
        app.router.add_get("/ws", self._serve_websocket)
        self._runner = web.AppRunner(app, handle_signals=False, access_log=None, shutdown_timeout=1.0)
        await self._runner.setup()
        await web.TCPSite(self._runner, bind, port, reuse_address=True).start()
        host, bound_port = self._runner.addresses[0][:2]
        self.address = (str(host), int(bound_port))
        self._allowed_hosts = allowed_host_headers(bind, int(bound_port), self._extra_hosts)

    @web.middleware
    async def _check_host(self, request: web.Request, handler: Callable) -> web.StreamResponse:
        host = (request.headers.get("Host") or "").strip().lower()
        if host not in self._allowed_hosts:
            return web.Response(status=421, text=f"host {host[:80]!r} is not served here", headers=_SECURITY_HEADERS)
        return await handler(request)

    async def _cleanup(self) -> None:
        for socket in list(self._sockets):
            await socket.close(code=WSCloseCode.GOING_AWAY, message=b"display stopped")
        if self._runner is not None:
            await self._runner.cleanup()

    async def _serve_file(self, request: web.Request) -> web.StreamResponse:
        name, content_type = _WEB_FILES[request.path]
        try:
            body = (web_directory() / name).read_bytes()
        except OSError as error:
            self._log_warning(f"display page file {name} unreadable: {error}")
            raise web.HTTPInternalServerError(text=f"display page file {name} is missing from the package") from None
        return web.Response(body=body, content_type=content_type, charset="utf-8", headers=_SECURITY_HEADERS)

    async def _serve_websocket(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if origin is not None and origin.split("://", 1)[-1] != request.host:
            # another web site in the same browser must not read the feed (cross-site WebSocket hijacking)
            raise web.HTTPForbidden(text="cross-origin WebSocket refused")
        socket = web.WebSocketResponse(
            heartbeat=max(self.heartbeat_s * 4.0, 5.0), max_msg_size=_MAX_INCOMING_MESSAGE_BYTES
        )
        await socket.prepare(request)
        wakeup = asyncio.Event()
        self._wakeups.add(wakeup)
        self._sockets.add(socket)
        sender = asyncio.ensure_future(self._send_frames(socket, wakeup))
        try:
            async for message in socket:  # read only to see pings and closes; whatever the page says is ignored
                if message.type == WSMsgType.ERROR:
                    break
        finally:
            sender.cancel()
            self._wakeups.discard(wakeup)
            self._sockets.discard(socket)
            await asyncio.gather(sender, return_exceptions=True)
            await socket.close()
        return socket

    async def _send_frames(self, socket: web.WebSocketResponse, wakeup: asyncio.Event) -> None:
        sent_versions: dict[str, int] = {}
        try:
            while not socket.closed:
                text, sent_versions = self._frame(sent_versions)
                await asyncio.wait_for(socket.send_str(text), timeout=_SEND_TIMEOUT_S)
                # rate limit: whatever arrives meanwhile only re-sets the event; the next frame is the latest value
                await asyncio.sleep(self.min_interval_s)
                try:
                    await asyncio.wait_for(wakeup.wait(), timeout=max(self.heartbeat_s - self.min_interval_s, 0.0))
                except TimeoutError:
                    pass
                wakeup.clear()
        except (ConnectionError, TimeoutError, RuntimeError) as error:  # gone, or too slow to take a frame
            self._log_warning(f"display page dropped: {error!r}")
            await socket.close(code=WSCloseCode.TRY_AGAIN_LATER, message=b"dropped")
        except Exception as error:  # a frame that cannot be built: the page sees silence and shows NO DATA
            self._log_warning(f"display frame failed: {type(error).__name__}: {error}")
            await socket.close(code=WSCloseCode.INTERNAL_ERROR, message=b"frame error")

    def _wake_all(self) -> None:
        self._wake_pending = False
        for wakeup in self._wakeups:
            wakeup.set()

    # -- any thread ------------------------------------------------------------------------------------
    def notify(self) -> None:
        """Tells every page sender that something changed (coalesced; cheap at kHz rates)."""
        if self._wake_pending or self._loop.is_closed():
            return
        self._wake_pending = True
        try:
            self._loop.call_soon_threadsafe(self._wake_all)
        except RuntimeError:  # loop closed during shutdown
            pass

    @property
    def page_count(self) -> int:
        """Pages connected right now."""
        return len(self._sockets)

    def stop(self, timeout_s: float = 5.0) -> None:
        """Closes every page (WebSocket code 1001) and the listening socket; joins the server thread."""
        if self._thread.is_alive():
            try:
                self._loop.call_soon_threadsafe(self._loop.stop)
            except RuntimeError:
                pass
            self._thread.join(timeout=timeout_s)


# ----------------------------------------------------------------------------------------------------------
# The node
# ----------------------------------------------------------------------------------------------------------
