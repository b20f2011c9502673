"""What a file, a robot or an error wrote reaches viser's markdown as written (the debugger's
page reads it in a real browser: tests/test_browser.py)."""

import re

from hypothesis import given
from hypothesis import strategies as st

from mbicp_viz.views.debugger.markdown import literal, wrapping


@given(st.text())
def test_literal_escapes_every_punctuation_mark_and_nothing_else(text):
    """Markdown reads a backslash before an ASCII punctuation mark as that mark: undoing the
    escapes gives the text back, and no mark (a tag's angle bracket, an emphasis star) is left
    bare."""
    tokens = re.findall(r"\\[!-/:-@\[-`{-~]|[\s\S]", literal(text))  # escapes, or one character
    assert "".join(t[-1] for t in tokens) == text
    assert not any(len(t) == 1 and re.fullmatch(r"[!-/:-@\[-`{-~]", t) for t in tokens)


def test_wrapping_keeps_the_markdown_and_breaks_long_words():
    md = wrapping(literal("/a/very/long/path"))
    assert "overflow-wrap:anywhere" in md and "\n\n\\/a\\/very\\/long\\/path\n\n" in md
