"""Text for viser's markdown panels: what a file, a robot or an error wrote, shown as written.

viser renders a markdown's HTML unsanitised (its client parses raw HTML into the page), so a file
named ``<img src=x onerror=...>``, a bag's topic or a robot's tf frame name would run on the page
if it went in raw, and ``*c*`` in a name would turn italic."""

from __future__ import annotations

import re

_PUNCTUATION = re.compile(r"([!-/:-@\[-`{-~])")


def literal(text: str) -> str:
    """``text`` as markdown that shows it as written: every ASCII punctuation mark escaped, so
    that neither markdown nor HTML in it is read as such."""
    return _PUNCTUATION.sub(r"\\\1", text)


def wrapping(markdown: str) -> str:
    """``markdown`` in a block whose long words (a path, a cache folder) break at the panel's edge
    instead of running past it."""
    return f'<div style="overflow-wrap:anywhere">\n\n{markdown}\n\n</div>'
