"""What a browser may do to the viewer: which pages may connect, how many at once, which values it may send.

Any web page the user opens can make the browser open a WebSocket to ``127.0.0.1``; only the
server can refuse it. :class:`ConnectionGuard` runs at the WebSocket handshake (before Viser sees
the connection) and refuses pages of other sites and connections beyond :data:`MAX_CLIENTS`.
Every value a client sends through a GUI element or a click is checked by the functions below
before use; a bad one is ignored with one line on stderr (:func:`complain`), never raised in a
playback or control thread.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import math
import socket
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from typing import Any
from urllib.parse import urlsplit

MAX_CLIENTS = 16
"""WebSockets served at once (browser tabs); more are refused with HTTP 503 so a flood cannot starve playback."""
MAX_MESSAGE_BYTES = 1 << 20
"""Largest WebSocket message a client may send (Viser allows 50 MiB): the viewer's camera, GUI and click messages
are under 1 KiB, so a bigger frame only costs memory (times :data:`MAX_CLIENTS`); it closes that connection (1009)."""
MAX_COMPLAINTS, COMPLAINT_WINDOW_S = 50, 10.0
"""At most 50 stderr lines about refused connections and ignored messages per 10 s (a hostile page may loop)."""
_window = {"start": -math.inf, "lines": 0}
_window_lock = threading.Lock()


def complain(command: str, text: str) -> None:
    """One stderr line ``latentrl COMMAND: TEXT``, unless :data:`MAX_COMPLAINTS` were printed in this window."""
    now = time.monotonic()
    with _window_lock:
        if now - _window["start"] > COMPLAINT_WINDOW_S:
            _window.update(start=now, lines=0)
        _window["lines"] += 1
        n = _window["lines"]
    if n <= MAX_COMPLAINTS:
        print(f"latentrl {command}: {text}", file=sys.stderr, flush=True)
    elif n == MAX_COMPLAINTS + 1:
        print(f"latentrl {command}: more refused connections or ignored messages in the next "
              f"{COMPLAINT_WINDOW_S:.0f} s are not printed", file=sys.stderr, flush=True)


def is_loopback(host: str) -> bool:
    """``localhost`` (and ``*.localhost``) or a loopback address (127.0.0.0/8, ::1)."""
    name = host.strip("[]").lower()
    if name == "localhost" or name.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


class ConnectionGuard:
    """Decides at each WebSocket handshake whether the page asking may drive the viewer.

    The page must be one the viewer served: its ``Origin`` (scheme://host:port) matches the
    request's ``Host`` header (a forwarded port, as ``ssh -L`` gives, keeps the two equal), and that
    host is a loopback name, the address the connection arrived on, the ``--host`` given, or this
    machine's name (``socket.gethostname()``; to use another name, give it as ``--host``). A page of
    another site fails the first test; a DNS-rebinding page (a foreign name resolving to 127.0.0.1)
    fails the second. A handshake without ``Origin`` comes from no web page (a script can send any
    header anyway) and is let through.

    Args:
        command: ``"view"`` or ``"play"``, for the stderr lines.
        host: the ``--host`` the server binds.
        max_clients: WebSockets open at once beyond which new ones are refused.
    """

    def __init__(self, command: str, host: str, max_clients: int = MAX_CLIENTS):
        self.command, self.max_clients = command, max_clients
        names = {host, socket.gethostname()}
        self.names = {n.strip("[]").lower() for n in names} - {"", "0.0.0.0", "::"}
        self.installed = False
        """Set once the websockets server was built with :meth:`wrap` (see :func:`guarded_websockets`)."""

    def refusal(self, origins: Sequence[str], host_header: str | None, local_address: str,
                open_clients: int) -> tuple[int, str] | None:
        """``(HTTP status, reason)`` to refuse a WebSocket handshake, or None to accept it."""
        if open_clients >= self.max_clients:
            return 503, f"{open_clients} browser connections are open already (at most {self.max_clients})"
        if not origins:
            return None
        if len(origins) > 1:
            return 403, f"{len(origins)} Origin headers"
        origin = origins[0]
        try:
            parts = urlsplit(origin)
            hostname = parts.hostname or ""
        except ValueError:
            return 403, f"origin {origin[:80]!r} is malformed"
        if parts.scheme not in ("http", "https") or parts.netloc.lower() != (host_header or "").lower():
            return 403, f"origin {origin[:80]!r} is not a page of this viewer ({str(host_header)[:80]})"
        if not (is_loopback(hostname) or hostname in self.names or hostname == local_address.lower()):
            return 403, f"origin {origin[:80]!r} names a host that is not this machine"
        return None

    def wrap(self, process_request: Any) -> Any:
        """Viser's HTTP handler for its websockets server, with :meth:`refusal` asked first on each WebSocket."""
        from websockets.protocol import State

        def guarded(connection: Any, request: Any) -> Any:
            if request.headers.get("Upgrade", "").lower() == "websocket":
                open_clients = sum(1 for c in connection.server.handlers if c.protocol.state is State.OPEN)
                local = (connection.transport.get_extra_info("sockname") or ("",))[0]
                refused = self.refusal(request.headers.get_all("Origin"), request.headers.get("Host"), str(local),
                                       open_clients)
                if refused is not None:
                    status, reason = refused
                    complain(self.command, f"refused a browser connection: {reason}")
                    return connection.respond(status, f"{reason}\n")
            return process_request(connection, request) if process_request is not None else None

        self.installed = True
        return guarded


class _OneLine(logging.Handler):
    """The websockets server's warnings and errors (a message Viser could not decode) as one :func:`complain` line."""

    def __init__(self, command: str):
        super().__init__(logging.WARNING)
        self.command = command

    def emit(self, record: logging.LogRecord) -> None:
        exc = record.exc_info[1] if record.exc_info else None
        text = f"{type(exc).__name__}: {(str(exc).splitlines() or [''])[0]}" if exc else record.getMessage()
        complain(self.command, f"closed a browser connection after an error ({text[:160]})")


def server_logger(command: str) -> logging.Logger:
    """The logger given to the viewer's websockets server: one stderr line per problem, never a traceback."""
    logger = logging.getLogger(f"latentrl.viewer.{command}.websockets")
    logger.propagate = False
    logger.setLevel(logging.WARNING)
    if not logger.handlers:
        logger.addHandler(_OneLine(command))
    return logger


_serve_lock = threading.Lock()


@contextlib.contextmanager
def guarded_websockets(guard: ConnectionGuard) -> Iterator[None]:
    """While open, every websockets server started gets ``guard`` in front of its HTTP handler.

    It also gets :data:`MAX_MESSAGE_BYTES` as its message limit and :func:`server_logger` as its logger.

    Viser (1.1) starts its server with ``websockets.asyncio.server.serve`` and offers no hook for the
    handshake, so :func:`~latentrl.viewer.server.start_server` opens this around building the
    ``ViserServer`` only; ``guard.installed`` tells whether Viser still starts its server that way.
    """
    import websockets.asyncio.server as ws_server

    with _serve_lock:  # two servers built at once must not keep each other's wrapper
        original = ws_server.serve

        def serve(*args: Any, process_request: Any = None, **kwargs: Any) -> Any:
            kwargs["max_size"] = MAX_MESSAGE_BYTES
            kwargs["logger"] = server_logger(guard.command)
            return original(*args, process_request=guard.wrap(process_request), **kwargs)

        ws_server.serve = serve
        try:
            yield
        finally:
            ws_server.serve = original


# --------------------------------------------------------------------------- values a client sends
def choice(value: Any, options: Sequence[str]) -> str | None:
    """``value`` if it is one of ``options``, else None."""
    return value if isinstance(value, str) and value in options else None


def number(value: Any, low: float, high: float) -> float | None:
    """``value`` as a float if it is a finite number (not a bool or a string) in [low, high], else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    value = float(value)
    return value if math.isfinite(value) and low <= value <= high else None


def vector(value: Any, size: int, bound: float) -> tuple[float, ...] | None:
    """``value`` as a tuple of ``size`` finite numbers within ±``bound``, else None."""
    if not isinstance(value, (list, tuple)) or len(value) != size:
        return None
    out = tuple(number(v, -bound, bound) for v in value)
    return None if any(v is None for v in out) else out  # type: ignore[return-value]
