"""The user-facing text holds together: every relative link resolves, and no internal milestone word is left.

Links are checked in README.md, CHANGELOG.md, docs/, zoo/ and the policy cards: markdown links and images and
HTML ``src``/``href``, outside code; a ``#fragment`` into a markdown file must name one of its headings (as
GitHub derives anchors). Milestone words (the word "stop" joined to a number) are checked in every tracked
text file.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path
from urllib.parse import unquote

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)"  # [text](target), ![alt](target)
                  r"|<(?:img|a)\b[^>]*?\b(?:src|href)=\"([^\"]+)\"")  # <img src=...>, <a href=...>
FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)
CODE_SPAN = re.compile(r"(`+)(?!`).*?(?<!`)\1(?!`)", re.S)
MILESTONE = re.compile(r"\bstop[- ]?\d+\b", re.I)


def doc_files() -> list[Path]:
    files = [ROOT / "README.md", ROOT / "CHANGELOG.md"]
    for folder, pattern in (("docs", "**/*.md"), ("zoo", "**/*.md"), ("latentrl/policies", "*.md")):
        files += sorted((ROOT / folder).glob(pattern))
    return [f for f in files if f.is_file()]


def anchors(md: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens, repeats numbered."""
    seen: dict[str, int] = {}
    out = set()
    for line in FENCE.sub("", md.read_text(encoding="utf-8")).splitlines():
        m = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(1).lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def links(md: Path) -> list[str]:
    text = CODE_SPAN.sub("", FENCE.sub("", md.read_text(encoding="utf-8")))
    return [a or b for a, b in LINK.findall(text)]


def broken_links(md: Path) -> list[str]:
    bad = []
    for target in links(md):
        if re.match(r"[a-z][a-z0-9+.-]*:", target, re.I):  # http:, https:, mailto:
            continue
        path, _, fragment = unquote(target).partition("#")
        dest = (md.parent / path).resolve() if path else md
        if not dest.exists():
            bad.append(f"{md.relative_to(ROOT)}: {target} (no such file)")
        elif fragment and dest.suffix == ".md" and fragment.lower() not in anchors(dest):
            bad.append(f"{md.relative_to(ROOT)}: {target} (no heading '{fragment}')")
    return bad


def test_the_checked_files_have_links():
    assert sum(len(links(md)) for md in doc_files()) > 50


def test_every_relative_link_resolves():
    bad = [b for md in doc_files() for b in broken_links(md)]
    assert not bad, "\n".join(bad)


def tracked_text_files() -> list[Path]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    names = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z"], capture_output=True, check=True).stdout
    files = []
    for name in names.decode().split("\0"):
        path = ROOT / name
        if name and path.is_file() and not path.is_symlink():
            head = path.read_bytes()[:8192]
            if b"\0" not in head:
                files.append(path)
    return files


def test_no_internal_milestone_words():
    hits = []
    for path in tracked_text_files():
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if MILESTONE.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:100]}")
    assert not hits, "\n".join(hits)
