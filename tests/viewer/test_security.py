"""The viewer against a hostile file or web page: strings shown as text, foreign origins and bad messages refused."""

import html
import json
import re
import time
from pathlib import Path

import numpy as np
import pytest

from latentrl.render import save_motion_npz
from latentrl.viewer.markup import plain
from tests.viewer.conftest import walk_controller, walking, write_eval

ROOT = Path(__file__).resolve().parents[2]
IMG = "<img src=x onerror=alert(1)>"
SCRIPT = "<script>alert(2)</script>"
HOSTILE = f"{IMG} {SCRIPT} ![p](/etc/hostname) [l](javascript:alert(3)) `c` **b** {{x}} a|b & &amp;"


def rendered(markdown: str) -> str:
    """HTML that a CommonMark renderer with raw HTML and tables on (as Viser's) makes of ``markdown``."""
    markdown_it = pytest.importorskip("markdown_it")
    return markdown_it.MarkdownIt("commonmark", {"html": True}).enable("table").render(markdown)


def test_plain_renders_as_exactly_its_characters():
    out = rendered(plain(HOSTILE))
    assert re.fullmatch(r"<p>[^<>]*</p>\n", out), out  # one paragraph of text: no tag, link, image, code
    assert html.unescape(out[3:-5]) == HOSTILE
    assert "![" not in plain(HOSTILE)  # Viser reads ![..](path) images from the server's disk before sending


def test_plain_keeps_line_breaks_from_making_blocks():
    out = rendered(plain("walk\n# heading\n| a | b |\n|---|---|\n- item\n\n<div>"))
    assert re.fullmatch(r"<p>[^<>]*</p>\n", out), out
    assert html.unescape(out[3:-5]) == "walk # heading | a | b | |---|---| - item <div>"
    for start in ("# heading", "- item", "+ item", "1. item", "2) item", "> quote", "---", "===", "    code"):
        out = rendered(plain(start))
        assert out == f"<p>{html.escape(start.strip(), quote=False)}</p>\n", (start, out)
    assert plain("success 0.50 ± 0.10") == "success 0.50 ± 0.10"  # numbers stay readable in the source


def markdown_shown(player) -> list[str]:
    return [player.header.content, player.metrics.content, player.status.content]


def assert_text_only(contents: list[str], needle: str) -> None:
    """No markdown panel holds a tag, an image or a link, and ``needle`` shows as its characters in one of them."""
    for content in contents:
        out = rendered(content)
        assert not re.search(r"<(?!/?(p|strong|em|br|table|thead|tbody|tr|th|td)\b)", out), out
        assert "![" not in content, content
    assert any(needle in html.unescape(rendered(c)) for c in contents), contents


def test_motion_texts_are_shown_as_text(server, tmp_path):
    from latentrl.viewer.playback import Player
    from latentrl.viewer.sources import open_source

    path = save_motion_npz(tmp_path / "walk.npz", walking(), texts=[IMG] * 25 + [SCRIPT] * 25, end=HOSTILE)
    player = Player(server, open_source(path))
    assert_text_only(markdown_shown(player), IMG)  # status line (frame 0) and the summary
    assert_text_only(markdown_shown(player), HOSTILE)  # the stored `end` in the metrics table
    player.frame = 30
    player._draw()
    assert_text_only(markdown_shown(player), SCRIPT)


def test_report_strings_are_shown_as_text(server, tmp_path):
    from latentrl.viewer.playback import Player
    from latentrl.viewer.sources import open_source

    folder = write_eval(tmp_path / "eval")
    report = json.loads((folder / "report.json").read_text())
    report["policy"]["path"] = f"runs/{IMG}{SCRIPT}/final.pt"
    report["suites"]["demo"]["paths"][0]["episodes"][1]["end"] = IMG
    (folder / "report.json").write_text(json.dumps(report))
    player = Player(server, open_source(folder))
    assert_text_only(markdown_shown(player), f"runs/{IMG}{SCRIPT}/final.pt")
    player.select(player.source.entries[1].label)
    assert_text_only(markdown_shown(player), IMG)
    assert np.isfinite(player.frame)


# --------------------------------------------------------------------------- origin, connection bound, messages
class RawClient:
    """A WebSocket client speaking Viser's protocol by hand, as a hostile page's script could."""

    def __init__(self, port: int, origin: str | None = "own", host: str = "127.0.0.1"):
        import viser
        from websockets.sync.client import connect

        origin = f"http://{host}:{port}" if origin == "own" else origin
        self.ws = connect(f"ws://{host}:{port}", subprotocols=[f"viser-v{viser.__version__}"], origin=origin,
                          open_timeout=30, max_size=None, max_queue=None)  # reads all it is sent, as a page does
        # Viser counts a client as connected (and runs its GUI callbacks) from its first camera message
        self.send(type="ViewerCameraMessage", wxyz=[1.0, 0.0, 0.0, 0.0], position=[0.0, -3.0, 2.0], fov=1.0,
                  near=0.01, far=100.0, image_height=480, image_width=640, look_at=[0.0, 0.0, 0.0],
                  up_direction=[0.0, 0.0, 1.0])

    def send(self, **message) -> None:
        import msgspec

        self.ws.send(msgspec.msgpack.encode(message))

    def gui(self, handle, value) -> None:
        """What a GUI element sends when the user changes it (any value: the page decides)."""
        self.send(type="GuiUpdateMessage", uuid=handle._impl.uuid, updates={"value": value})

    def close(self) -> None:
        self.ws.close()


def refused_status(port: int, **kwargs) -> int | None:
    """The HTTP status a raw client's handshake was refused with, or None when it was accepted."""
    from websockets.exceptions import InvalidStatus

    try:
        RawClient(port, **kwargs).close()
    except InvalidStatus as exc:
        return exc.response.status_code
    return None


def wait_for(check, what: str, timeout: float = 10.0) -> None:
    end = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < end, f"not within {timeout} s: {what}"
        time.sleep(0.05)


@pytest.fixture
def guarded(monkeypatch):
    """A Viser server started as ``latentrl view`` starts it (origin check, connection bound)."""
    pytest.importorskip("viser")
    from latentrl.viewer import guard
    from latentrl.viewer.server import start_server

    monkeypatch.setattr(guard, "_window", {"start": -float("inf"), "lines": 0})  # this test's stderr lines all print
    srv = start_server("127.0.0.1", 0, "test", "view")
    yield srv
    srv.stop()


def test_pages_of_other_sites_are_refused(guarded, capsys):
    port = guarded.get_port()
    assert refused_status(port, origin="http://evil.example") == 403
    assert refused_status(port, origin=f"http://evil.example:{port}") == 403
    assert refused_status(port, origin="null") == 403  # a sandboxed frame or a file:// page
    assert refused_status(port, origin=f"http://127.0.0.1:{port + 1}") == 403  # another local server's page
    assert "refused a browser connection: origin 'http://evil.example'" in capsys.readouterr().err
    assert refused_status(port) is None  # the viewer's own page
    assert refused_status(port, origin=f"http://localhost:{port}", host="localhost") is None
    assert refused_status(port, origin=None) is None  # no web page: a script can forge any header anyway


def test_origin_rules():
    from latentrl.viewer.guard import ConnectionGuard

    guard = ConnectionGuard("view", "127.0.0.1")
    assert guard.refusal(["http://127.0.0.1:9000"], "127.0.0.1:9000", "127.0.0.1", 0) is None  # ssh -L 9000:...
    assert guard.refusal(["http://[::1]:8080"], "[::1]:8080", "::1", 0) is None
    assert guard.refusal(["http://rebind.example:8080"], "rebind.example:8080", "127.0.0.1", 0)[0] == 403
    assert guard.refusal(["http://evil.example", "http://127.0.0.1:8080"], "127.0.0.1:8080", "127.0.0.1", 0)[0] == 403
    assert guard.refusal(["http://10.1.2.3:8080"], "10.1.2.3:8080", "10.1.2.3", 0) is None  # --host 0.0.0.0
    assert guard.refusal([], "127.0.0.1:8080", "127.0.0.1", 16)[0] == 503


def test_connections_are_bounded(guarded, capsys):
    from latentrl.viewer.guard import MAX_CLIENTS

    port = guarded.get_port()
    clients = [RawClient(port) for _ in range(MAX_CLIENTS)]
    try:
        assert refused_status(port) == 503
        assert f"at most {MAX_CLIENTS}" in capsys.readouterr().err
        clients.pop().close()
        wait_for(lambda: refused_status(port) is None, "a slot frees when a client leaves")
    finally:
        for client in clients:
            client.close()


def test_a_flood_of_connections_is_bounded_and_playback_goes_on(guarded, eval_folder):
    from concurrent.futures import ThreadPoolExecutor

    from websockets.exceptions import InvalidStatus

    from latentrl.viewer.guard import MAX_CLIENTS
    from latentrl.viewer.playback import Player
    from latentrl.viewer.sources import open_source

    player = Player(guarded, open_source(eval_folder))
    player.start()

    def attempt(_):
        try:
            return RawClient(guarded.get_port())
        except InvalidStatus as exc:
            return exc.response.status_code

    with ThreadPoolExecutor(20) as pool:  # 20 handshakes at a time, 200 in all
        results = list(pool.map(attempt, range(200)))
    clients = [r for r in results if isinstance(r, RawClient)]
    try:
        assert len(clients) == MAX_CLIENTS and results.count(503) == 200 - MAX_CLIENTS, results
        before = player.frame
        wait_for(lambda: player.frame != before, "playback still moving")
        assert player.thread.is_alive()
    finally:
        for client in clients:
            client.close()
        player.stop.set()
        player.thread.join(2)


def test_bad_gui_values_are_ignored_and_playback_goes_on(guarded, eval_folder, capsys):
    from latentrl.viewer.playback import Player
    from latentrl.viewer.sources import open_source

    player = Player(guarded, open_source(eval_folder))
    player.start()
    client = RawClient(guarded.get_port())
    try:
        for bad in ("abc", "nan", "inf", "-1", "1e308", ""):
            client.gui(player.speed, bad)
            wait_for(lambda line=f"ignored speed {bad!r}": line in capsys.readouterr().err, f"speed {bad!r} ignored")
            wait_for(lambda: player.speed.value == "1", "the speed dropdown put back")
            assert player.rate == 1.0
        client.gui(player.speed, "2")  # the same channel with a good value
        wait_for(lambda: player.rate == 2.0, "speed 2 taken")
        with player.lock:  # paused: while playing, the next frame may replace a bad slider value before the
            player.playing = False  # handler reads it (dropped then, but without the message waited for here)
        for bad in (-5, 10**9):
            client.gui(player.slider, bad)
            wait_for(lambda: "ignored frame" in capsys.readouterr().err, f"frame {bad} ignored")
        client.gui(player.slider, float("nan"))  # Viser's int() cast refuses it before our handler
        client.gui(player.picker, "<no such episode>")
        wait_for(lambda: "ignored episode" in capsys.readouterr().err, "unknown episode ignored")
        assert player.label == player.source.entries[0].label
        client.gui(player.picker, player.source.entries[1].label)
        wait_for(lambda: player.label == player.source.entries[1].label, "a real episode picked")
        with player.lock:
            player.playing = True
        before = player.frame
        wait_for(lambda: player.frame != before and np.isfinite(player.frame), "playback still moving")
        assert player.thread.is_alive()
    finally:
        client.close()
        player.stop.set()
        player.thread.join(2)


@pytest.fixture
def live(guarded):
    """``latentrl play``'s controller with the shipped walk policy, its loop running."""
    controller = walk_controller(guarded)
    controller.start()
    yield controller
    controller.stop.set()
    controller.thread.join(5)


def test_bad_clicks_and_texts_are_ignored_and_live_control_goes_on(guarded, live, capsys):
    env = live.env
    client = RawClient(guarded.get_port())

    def click(origin, direction):
        client.send(type="ScenePointerMessage", event_type="click", ray_origin=origin, ray_direction=direction,
                    screen_pos=[[0.5, 0.5]], modifier=None)

    try:
        nan, inf = float("nan"), float("inf")
        for origin, direction in (((nan, 0.0, 1.0), (0.0, 0.0, -1.0)), ((0.0, -4.0, 3.0), (nan, nan, nan)),
                                  ((inf, 0.0, 1.0), (0.0, 0.0, -1.0)), ((0.0, 0.0, 1.0), (0.0, -1.0))):
            click(origin, direction)
            wait_for(lambda: "ignored a click" in capsys.readouterr().err, f"click {origin} {direction} ignored")
            assert live.goal is None and live.thread.is_alive()
        client.gui(live.text, "<no such text>")
        wait_for(lambda: "ignored text" in capsys.readouterr().err, "unknown text ignored")
        wait_for(lambda: live.text.value == "walk", "the text dropdown put back")
        assert env.text == "walk"
        click(("a", 0.0, 1.0), (0.0, 0.0, -1.0))  # Viser cannot decode it and drops that connection
        time.sleep(0.5)
        assert live.thread.is_alive() and live.goal is None
        client.close()
        client = RawClient(guarded.get_port())
        click((0.0, -4.0, 3.0), (0.3, 0.8, -0.5))  # a good click, as a page sends it
        wait_for(lambda: live.goal is not None, "a good click sets the goal")
        assert np.isfinite(live.goal).all()
        before = live.pelvis().copy()
        wait_for(lambda: np.linalg.norm(live.pelvis() - before) > 0.05, "the body moves", timeout=60)
        assert live.thread.is_alive()
    finally:
        client.close()


def test_an_error_in_the_control_loop_stops_the_walk_and_the_thread_lives(live, capsys):
    class BrokenPolicy:
        def act(self, obs, deterministic=False):
            raise RuntimeError("policy failed")

    policy, live.policy = live.policy, BrokenPolicy()
    live.set_goal((1.0, 2.0))
    wait_for(lambda: not live.active, "the walk stopped")
    assert "live control paused: RuntimeError: policy failed" in capsys.readouterr().err
    assert live.thread.is_alive() and "press Reset" in live.message
    live.policy = policy
    live.reset()
    live.set_goal((1.0, 2.0))
    before = live.pelvis().copy()
    wait_for(lambda: np.linalg.norm(live.pelvis() - before) > 0.05, "the body moves again", timeout=60)


def test_an_error_in_the_playback_loop_pauses_it_and_the_thread_lives(guarded, eval_folder, capsys, monkeypatch):
    from latentrl.viewer.playback import Player
    from latentrl.viewer.sources import open_source

    player = Player(guarded, open_source(eval_folder))
    draw = player.scene.show_pose

    def broken(joints):
        raise RuntimeError("drawing failed")

    monkeypatch.setattr(player.scene, "show_pose", broken)
    player.start()
    try:
        wait_for(lambda: not player.playing, "playback paused")
        assert "playback paused: RuntimeError: drawing failed" in capsys.readouterr().err
        assert player.thread.is_alive() and player.play.label == "Play"
        monkeypatch.setattr(player.scene, "show_pose", draw)
        player.toggle()  # the Play button
        before = player.frame
        wait_for(lambda: player.frame != before, "playback moves again")
    finally:
        player.stop.set()
        player.thread.join(2)


# --------------------------------------------------------------------------- --host
def serve_view(motion_file, *host):
    """``latentrl view MOTION [--host H] --port 0`` in a subprocess; returns it and its URL line."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "latentrl.app.cli", "view", str(motion_file), *host, "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    return proc, proc.stdout.readline()


def stop(proc) -> str:
    """Ctrl-C the server; its stderr."""
    import signal

    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    return err


def test_a_network_host_prints_its_reachable_address_and_a_warning(motion_file):
    import urllib.request

    pytest.importorskip("viser")
    from latentrl.viewer.server import is_local_only

    proc, line = serve_view(motion_file, "--host", "0.0.0.0")
    try:
        url = re.search(r"open (http://\S+) in a browser", line).group(1)
        assert "0.0.0.0" not in url, line
        warning = proc.stderr.readline()
        assert warning.startswith("latentrl view: warning: --host 0.0.0.0 makes the viewer reachable from the "
                                  f"network: anyone who can reach {url} can watch it"), warning
        with urllib.request.urlopen(url, timeout=10) as page:  # the printed address serves the viewer
            assert page.status == 200
        host = re.match(r"http://\[?([^\]]+?)\]?:\d+$", url).group(1)
        assert is_local_only(host) == (host == "127.0.0.1")  # loopback only where the machine has no network
    finally:
        stop(proc)


def test_a_loopback_host_prints_no_warning(motion_file):
    pytest.importorskip("viser")
    from latentrl.viewer.server import is_local_only

    proc, line = serve_view(motion_file, "--host", "localhost")
    assert line.startswith("latentrl view: open http://localhost:"), line
    assert "warning" not in stop(proc)
    assert all(is_local_only(h) for h in ("127.0.0.1", "127.0.0.2", "::1", "localhost"))
    assert not any(is_local_only(h) for h in ("0.0.0.0", "::", ""))


def test_a_viser_that_starts_its_server_another_way_is_warned_about(capsys, monkeypatch):
    import contextlib

    pytest.importorskip("viser")
    import latentrl.viewer.server as server

    monkeypatch.setattr(server, "guarded_websockets", lambda guard: contextlib.nullcontext())
    srv = server.start_server("127.0.0.1", 0, "test", "view")
    srv.stop()
    assert "other web pages could connect to it" in capsys.readouterr().err
