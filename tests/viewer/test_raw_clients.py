"""``latentrl view`` and ``latentrl play`` driven by raw clients (a TCP socket, a WebSocket), not a browser.

Each server is started as its command starts it, with its playback or live-control loop running. Raw HTTP
requests try path traversal in every spelling and malformed or oversized requests; raw WebSocket clients send
what Viser cannot decode, messages of unknown or incomplete types and frames over the message limit. The server
must answer nothing outside its folder, never crash, and keep serving (a new client connects, the page loads,
the loop lives). Origins, connection floods and bad GUI values are in ``test_security.py``.
"""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest

from tests.viewer.conftest import walk_controller
from tests.viewer.test_security import RawClient, wait_for

SECRET = "latentrl-secret-4d1f"


@pytest.fixture(params=["view", "play"])
def served(request, tmp_path, eval_folder, monkeypatch):
    """(server, its loop) of ``view`` (a Player on an eval folder) or ``play`` (the live controller), running."""
    pytest.importorskip("viser")
    from latentrl.viewer import guard
    from latentrl.viewer.playback import Player
    from latentrl.viewer.server import start_server
    from latentrl.viewer.sources import open_source

    monkeypatch.setattr(guard, "_window", {"start": -float("inf"), "lines": 0})
    (tmp_path / "secret.txt").write_text(SECRET)  # a file beside the served data, never to be read through HTTP
    server = start_server("127.0.0.1", 0, "test", request.param)
    loop = Player(server, open_source(eval_folder)) if request.param == "view" else walk_controller(server)
    loop.start()
    yield server, loop
    loop.stop.set()
    loop.thread.join(5)
    server.stop()


def http(port: int, raw: bytes, timeout: float = 10.0) -> bytes:
    """Send ``raw`` bytes on a fresh TCP connection; return all that comes back before the server closes or idles."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as sock:
        try:
            sock.sendall(raw)
        except OSError:  # the server closed while we were still sending (an oversized request): a refusal
            return b""
        out = b""
        try:
            while chunk := sock.recv(65536):
                out += chunk
        except (TimeoutError, ConnectionResetError):
            pass
    return out


def get(port: int, target: str | bytes) -> bytes:
    target = target.encode("latin-1") if isinstance(target, str) else target
    return http(port, b"GET " + target + b" HTTP/1.1\r\nHost: 127.0.0.1:%d\r\nConnection: close\r\n\r\n" % port)


def status(response: bytes) -> int | None:
    head = response.split(b"\r\n", 1)[0].split()
    return int(head[1]) if len(head) >= 2 and head[1].isdigit() else None


def still_serving(server, loop) -> None:
    """The page loads, a new WebSocket client is accepted, and the loop's thread lives."""
    port = server.get_port()
    page = get(port, "/")
    assert status(page) == 200 and b"<html" in page.lower(), page[:200]
    RawClient(port).close()
    assert loop.thread.is_alive()


TRAVERSALS = [
    "/../../../../../../etc/passwd", "/..%2f..%2f..%2f..%2f..%2fetc%2fpasswd",
    "/%2e%2e/%2e%2e/%2e%2e/%2e%2e/etc/passwd",
    "/%2E%2E/%2E%2E/%2E%2E/etc/passwd", "/..\\..\\..\\..\\etc\\passwd", "/..%5c..%5c..%5c..%5cetc%5cpasswd",
    "//etc/passwd", "/%2fetc%2fpasswd", "/assets/../../../../../etc/passwd", "/%252e%252e/%252e%252e/etc/passwd",
    "/etc/passwd%00.html", "/..;/..;/..;/etc/passwd", "/%c0%ae%c0%ae/%c0%ae%c0%ae/etc/passwd",
    "/index.html/../../../../../etc/passwd", "/./.././../../../../etc/passwd", "/....//....//....//etc/passwd",
    "/?../../../../etc/passwd", "/#/../../../../etc/passwd", "http://127.0.0.1/../../../../etc/passwd",
    "/proc/self/environ", "/../../../../../proc/self/environ", "/../../../../../proc/self/cmdline",
]


def test_nothing_outside_the_served_folder_is_answered(served, tmp_path):
    server, loop = served
    port = server.get_port()
    secret = str(tmp_path / "secret.txt")
    for target in [*TRAVERSALS, f"/../../../../../..{secret}", "/" + "../" * 30 + secret.lstrip("/"),
                   "/../../../../../.." + secret.replace("/", "%2f")]:
        response = get(port, target)
        assert status(response) in (None, 400, 404) or (status(response) == 200 and b'<div id="root">' in response), \
            (target, response[:300])  # a refusal, or the viewer's own page (a query or fragment names nothing)
        assert b"root:" not in response and SECRET.encode() not in response, target
    still_serving(server, loop)


MALFORMED_HTTP = {
    "binary junk": bytes(range(256)) * 4 + b"\r\n\r\n",
    "no request line": b"\r\n\r\n",
    "unknown version": b"GET / HTTP/9.9\r\n\r\n",
    "HTTP/0.9": b"GET /\r\n\r\n",
    "64 KiB header line": b"GET / HTTP/1.1\r\nHost: x\r\nX-Long: " + b"a" * 65536 + b"\r\n\r\n",
    "1000 headers": b"GET / HTTP/1.1\r\nHost: x\r\n" + b"".join(b"X-%d: y\r\n" % i for i in range(1000)) + b"\r\n",
    "1 MiB path": b"GET /" + b"a" * (1 << 20) + b" HTTP/1.1\r\nHost: x\r\n\r\n",
    "huge body announced": b"POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 99999999999\r\n\r\nabc",
    "chunked junk": b"POST / HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n",
    "websocket without key": b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                             b"Sec-WebSocket-Version: 13\r\n\r\n",
    "websocket bad version": b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                             b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 99\r\n\r\n",
    "NUL in path": b"GET /index\x00.html HTTP/1.1\r\nHost: x\r\n\r\n",
    "half a request": b"GET / HTT",
}


@pytest.mark.parametrize("name", list(MALFORMED_HTTP))
def test_malformed_http_requests_get_an_error_or_a_closed_connection(served, name):
    server, loop = served
    response = http(server.get_port(), MALFORMED_HTTP[name], timeout=5.0)
    assert status(response) in (None, 400, 404, 405, 413, 426, 431, 500, 501, 505), response[:300]
    assert status(response) != 200 or name == "HTTP/0.9", response[:300]
    still_serving(server, loop)


def _msgpack(obj) -> bytes:
    import msgspec

    return msgspec.msgpack.encode(obj)


def _nested(depth: int) -> bytes:
    return b"\x91" * depth + b"\xc0"  # msgpack: an array holding an array ... holding nil


WEBSOCKET_MESSAGES = {
    "not msgpack": b"\xc1\xff\x00garbage",
    "text frame": "hello viser",
    "empty frame": b"",
    "msgpack list": _msgpack([1, 2, 3]),
    "msgpack string": _msgpack("GuiUpdateMessage"),
    "unknown type": _msgpack({"type": "DeleteEverythingMessage"}),
    "no type": _msgpack({"uuid": "x", "updates": {"value": 1}}),
    "known type, fields missing": _msgpack({"type": "GuiUpdateMessage"}),
    "known type, wrong field types": _msgpack({"type": "GuiUpdateMessage", "uuid": 5, "updates": "x"}),
    "unknown GUI element": _msgpack({"type": "GuiUpdateMessage", "uuid": "no-such-uuid", "updates": {"value": 1}}),
    "camera with NaN": _msgpack({"type": "ViewerCameraMessage", "wxyz": [float("nan")] * 4, "position": [0.0] * 3,
                                 "fov": float("inf"), "near": -1.0, "far": 0.0, "image_height": -5,
                                 "image_width": 10**9, "look_at": [0.0] * 3, "up_direction": [0.0] * 3}),
    "nested 100000 deep": _nested(100_000),
    "map of 100000 keys": _msgpack({str(i): i for i in range(100_000)}),
    "over the size limit": b"\x00" * ((1 << 20) + 1),
}


@pytest.mark.parametrize("name", list(WEBSOCKET_MESSAGES))
def test_malformed_websocket_messages_never_crash_the_server_or_its_loop(served, name, capsys):
    from websockets.exceptions import ConnectionClosed

    server, loop = served
    client = RawClient(server.get_port())
    try:
        client.ws.send(WEBSOCKET_MESSAGES[name])
        time.sleep(0.3)
        try:  # the connection may be closed for it (Viser cannot decode it, or it is too big) or live on
            client.ws.send(_msgpack({"type": "ViewerCameraMessage"}))
        except ConnectionClosed:
            pass
    finally:
        try:
            client.close()
        except Exception:  # noqa: BLE001 - already closed by the server
            pass
    still_serving(server, loop)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    if name == "not msgpack":  # Viser's decode error: one line on the server's stderr, the connection closed
        assert "closed a browser connection after an error (DecodeError: MessagePack data is malformed" in err, err


def test_after_every_bad_message_the_loop_still_takes_a_good_one(served):
    """All the bad messages above, each on its own connection; then a good client still drives the loop."""
    server, loop = served
    port = server.get_port()
    for message in WEBSOCKET_MESSAGES.values():
        client = RawClient(port)
        try:
            client.ws.send(message)
        finally:
            try:
                client.close()
            except Exception:  # noqa: BLE001 - closed by the server
                pass
    client = RawClient(port)
    try:
        if hasattr(loop, "speed"):  # view: a speed change is taken
            client.gui(loop.speed, "2")
            wait_for(lambda: loop.rate == 2.0, "speed 2 taken")
            before = loop.frame
            wait_for(lambda: loop.frame != before, "playback still moving")
        else:  # play: a click sets a finite goal
            client.send(type="ScenePointerMessage", event_type="click", ray_origin=(0.0, -4.0, 3.0),
                        ray_direction=(0.3, 0.8, -0.5), screen_pos=[[0.5, 0.5]], modifier=None)
            wait_for(lambda: loop.goal is not None, "a good click sets the goal")
            assert np.isfinite(loop.goal).all()
        assert loop.thread.is_alive()
    finally:
        client.close()
