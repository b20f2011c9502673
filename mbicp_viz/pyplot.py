"""matplotlib for the PNG files the tool writes: the Agg backend (files only, never a window),
imported when a command first draws (matplotlib takes a moment to load)."""

from __future__ import annotations


def pyplot():
    """``matplotlib.pyplot`` on the Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_png(fig, path, dpi: float | None = None) -> None:
    """Write ``fig`` to ``path`` whole (``outputs.written``) and free it."""
    from mbicp_viz.outputs import written

    with written(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
    pyplot().close(fig)
