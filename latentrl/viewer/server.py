"""Starting and stopping the Viser web server: the optional extra, host/port checks, the URL line, Ctrl-C."""

from __future__ import annotations

import contextlib
import io
import signal
import socket
import sys
import threading
from typing import Any

from latentrl.errors import ConfigError, LatentRLError
from latentrl.viewer.guard import ConnectionGuard, complain, guarded_websockets, is_loopback

EXTRA_HINT = "pip install 'latentrl[viewer]'"


class ViewerMissingError(LatentRLError):
    """The optional viewer dependency (Viser) is not installed."""


def require_viser() -> Any:
    """Import ``viser`` or raise one line naming the extra that provides it."""
    try:
        import viser
    except ImportError:
        raise ViewerMissingError(f"the viewer needs the optional extra 'viewer' (Viser): {EXTRA_HINT}") from None
    return viser


def check_port(host: str, port: int) -> None:
    """Refuse a port outside 0..65535, a host that does not resolve, or a port something else listens on.

    Viser would silently move to the next free port; a user who asked for one should hear that it is taken.
    """
    if not 0 <= int(port) <= 65535:
        raise ConfigError(f"--port must be in 0..65535, got {port}")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise ConfigError(f"--host {host}: cannot be resolved ({exc})") from None
    family, _, _, _, address = infos[0]
    probe = socket.socket(family, socket.SOCK_STREAM)
    try:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        probe.bind(address)
    except OSError as exc:
        if exc.errno in (98, 48, 10048):  # EADDRINUSE on Linux, macOS, Windows
            raise ConfigError(f"--port {port}: already in use on {host}; choose another with --port") from None
        raise ConfigError(f"--host {host} --port {port}: cannot listen there ({exc.strerror or exc})") from None
    finally:
        probe.close()


WILDCARD_HOSTS = ("", "0.0.0.0", "::")
"""Hosts that bind every network interface."""


def reachable_host(host: str) -> str:
    """The address another machine reaches a server bound to ``host`` at.

    A wildcard host is this machine's outward address: the one the OS would send from (a UDP
    socket "connected" to a documentation address sends nothing), else the address of its name,
    else loopback when it has no network.
    """
    if host not in WILDCARD_HOSTS:
        return host
    family, probe = (socket.AF_INET6, "2001:db8::1") if host == "::" else (socket.AF_INET, "192.0.2.1")
    try:
        with socket.socket(family, socket.SOCK_DGRAM) as s:
            s.connect((probe, 9))
            address = s.getsockname()[0]
    except OSError:
        address = ""
    if address in WILDCARD_HOSTS and family == socket.AF_INET:
        try:
            address = socket.gethostbyname(socket.gethostname())
        except OSError:
            address = ""
    return address if address not in WILDCARD_HOSTS else ("::1" if host == "::" else "127.0.0.1")


def is_local_only(host: str) -> bool:
    """Whether a server bound to ``host`` is reachable from this machine only (every address it names is loopback)."""
    if host in WILDCARD_HOSTS:
        return False
    if is_loopback(host):
        return True
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        return False
    return all(is_loopback(str(info[4][0]).split("%")[0]) for info in infos)


def url_of(host: str, port: int) -> str:
    """The URL to open for a server bound to ``host:port`` (a wildcard host: this machine's outward address)."""
    shown = reachable_host(host)
    return f"http://[{shown}]:{port}" if ":" in shown else f"http://{shown}:{port}"


def start_server(host: str, port: int, label: str, command: str = "view") -> Any:
    """A running ``viser.ViserServer`` on exactly ``host:port`` (port 0: any free port).

    Its WebSocket handshake goes through a :class:`~latentrl.viewer.guard.ConnectionGuard`: pages of
    other sites and connections beyond :data:`~latentrl.viewer.guard.MAX_CLIENTS` are refused.
    """
    viser = require_viser()
    check_port(host, port)
    guard = ConnectionGuard(command, host)
    with contextlib.redirect_stdout(io.StringIO()), guarded_websockets(guard):  # Viser's banner: we print ours
        server = viser.ViserServer(host=host, port=int(port), label=label, verbose=False)
    if not guard.installed:
        complain(command, f"warning: viser {getattr(viser, '__version__', '?')} started its server in a way "
                          "this latentrl does not know: other web pages could connect to it")
    if port and server.get_port() != int(port):  # taken between the check and the bind
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()
        raise ConfigError(f"--port {port}: already in use on {host}; choose another with --port")
    server.gui.configure_theme(show_share_button=False)
    return server


def announce(command: str, host: str, port: int) -> None:
    """The line that tells the user where to look, and a warning line when other machines can reach it too."""
    url = url_of(host, port)
    print(f"latentrl {command}: open {url} in a browser (Ctrl-C stops)", flush=True)
    if not is_local_only(host):
        print(f"latentrl {command}: warning: --host {host} makes the viewer reachable from the network: "
              f"anyone who can reach {url} can watch{' and steer' if command == 'play' else ''} it",
              file=sys.stderr, flush=True)


def serve_until_interrupted(server: Any, command: str, host: str, stop: threading.Event | None = None,
                            on_stop: Any = None) -> int:
    """Print the URL, block until Ctrl-C (or ``stop`` is set), then stop the server; returns exit status 0."""
    stop = stop or threading.Event()
    if threading.current_thread() is threading.main_thread():
        # A command started in the background by a non-interactive shell inherits SIGINT as ignored, and
        # Python then never raises KeyboardInterrupt: take Ctrl-C back so it always stops the server.
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        announce(command, host, server.get_port())  # inside the try: a Ctrl-C right after the line stops cleanly
        while not stop.wait(0.25):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        stop.set()
        if on_stop is not None:
            on_stop()
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()
    print(f"latentrl {command}: stopped", flush=True)
    return 0
