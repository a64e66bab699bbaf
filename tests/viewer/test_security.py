"""The viewer against a hostile file or web page: strings shown as text, foreign origins and bad messages refused."""

import html
import json
import re

import numpy as np
import pytest

from latentrl.render import save_motion_npz
from latentrl.viewer.markup import plain
from tests.viewer.conftest import walking, write_eval

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


@pytest.fixture
def server():
    viser = pytest.importorskip("viser")
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield srv
    srv.stop()


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
