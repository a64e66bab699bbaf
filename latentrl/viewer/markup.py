"""Strings from files and reports, made safe to show in Viser's markdown panels.

Viser renders ``gui.add_markdown`` content as GitHub markdown with raw HTML allowed, and reads
``![...](path)`` images from the server's disk. A motion's ``texts`` or a report's policy path are
data, not markup: :func:`plain` turns any string into markdown that displays exactly that string,
so an ``<img onerror=...>`` or ``<script>`` in a file shows as those characters and never runs.
"""

from __future__ import annotations

import re

MARKDOWN_PUNCTUATION = frozenset("\\`*_[]!|~:")
"""Escaped with a backslash anywhere: emphasis, code, links, images, table cells, strikethrough, URL autolinks."""
BLOCK_START = re.compile(r"^([#+\-=])")
ORDERED_START = re.compile(r"^(\d{1,9})([.)])(?=\s|$)")
"""What opens a block at the start of a line (heading, list, rule; ``1.`` / ``1)`` lists): escaped there."""
HTML_ENTITIES = {"&": "&amp;", "<": "&lt;", ">": "&gt;"}
"""Characters that would open an HTML tag or entity: written as entities, which markdown shows as text."""
_WHITESPACE = re.compile(r"[\s\x00-\x1f\x7f]+")


def plain(value: object) -> str:
    """``str(value)`` as markdown that shows exactly its characters on one line: no tag, link, image or block.

    Line breaks and control characters become single spaces (a prompt never needs them, and they
    would start headings, lists or tables); markdown punctuation is backslash-escaped (block markers
    only at the start, where they act) and ``&``, ``<``, ``>`` become HTML entities.
    """
    text = _WHITESPACE.sub(" ", str(value)).strip()
    text = "".join(HTML_ENTITIES.get(c) or (f"\\{c}" if c in MARKDOWN_PUNCTUATION else c) for c in text)
    return BLOCK_START.sub(r"\\\1", ORDERED_START.sub(r"\1\\\2", text))
