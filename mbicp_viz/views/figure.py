"""The still front end (matplotlib, Agg): scene layers -> a PNG, for the lesson's handout and the
debugger's lesson panel. It draws the layers rerun and the debugger draw, with their colours and
legend labels, y up, equal axes in metres, in the reference laser frame.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np

from mbicp_viz.pyplot import pyplot

from . import scene


def _rgb(style: scene.Style):
    return _unit(style.color)


def _unit(rgb) -> tuple[float, ...]:
    """A 0-255 colour as matplotlib's 0-1."""
    return tuple(c / 255 for c in rgb)


def draw_layers(ax, layers: list[scene.Layer], shown: dict[str, scene.Style]) -> None:
    """Every drawable layer on ``ax`` (points in metres, or a plot space's own units); the styles
    that drew something are added to ``shown`` (the legend). Dots keep the sizes the layers give
    them relative to each other (the known answer's larger dots ring the scans drawn over them)."""
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Rectangle

    radii = [ly.radius for ly in layers if isinstance(ly, scene.Points) and scene.has_content(ly)]
    unit = min(radii) if radii else 1.0

    for ly in layers:
        if not isinstance(ly, scene.DRAWN) or not scene.has_content(ly):
            continue
        z = ly.style.order
        if isinstance(ly, scene.Points):
            colors = ly.colors[:, :3] / 255 if ly.colors is not None else [_rgb(ly.style)]
            # s is the marker's area in points^2: the smallest dots 3 points^2, the others by their
            # radius
            size = float(np.clip(3.0 * (ly.radius / unit) ** 2, 3.0, 40.0))
            ax.scatter(ly.xy[:, 0], ly.xy[:, 1], s=size, c=colors, linewidths=0, zorder=z)
        elif isinstance(ly, scene.Segments):
            ax.add_collection(
                LineCollection(
                    np.stack((ly.starts, ly.ends), axis=1),
                    colors=[_rgb(ly.style)],
                    linewidths=0.6,
                    zorder=z,
                )
            )
        elif isinstance(ly, scene.Strips):
            ax.add_collection(
                LineCollection(ly.strips, colors=[_rgb(ly.style)], linewidths=0.8, zorder=z)
            )
        elif isinstance(ly, scene.Boxes):
            for c, rgba in zip(ly.centers, ly.colors):
                ax.add_patch(
                    Rectangle(
                        c - ly.half_size,
                        2 * ly.half_size,
                        2 * ly.half_size,
                        facecolor=rgba / 255,
                        edgecolor=rgba[:3] / 255,
                        linewidth=0.3,
                        zorder=z,
                    )
                )
        elif isinstance(ly, scene.Frame):
            p, n = ly.pose, ly.length
            for angle, rgb in ((p.theta, scene.AXIS_X), (p.theta + np.pi / 2, scene.AXIS_Y)):
                ax.annotate(
                    "",
                    xy=(p.x + n * np.cos(angle), p.y + n * np.sin(angle)),
                    xytext=(p.x, p.y),
                    arrowprops=dict(arrowstyle="->", color=_unit(rgb), lw=1.2),
                    zorder=z,
                )
        shown.setdefault(ly.style.label, ly.style)


def _same_window(axes, window: tuple[float, float, float, float] | None) -> None:
    """The same window on every scan panel (axes of one size: equal aspect keeps them equal): the
    given one (x_min, y_min, x_max, y_max) [m], else everything drawn."""
    if not len(axes):
        return
    if window is not None:
        lo, hi = np.array(window[:2]), np.array(window[2:])
    else:
        lo = np.min([ax.dataLim.min for ax in axes], axis=0)
        hi = np.max([ax.dataLim.max for ax in axes], axis=0)
        pad = 0.03 * (hi - lo).max()
        lo, hi = lo - pad, hi + pad
    for ax in axes:
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])


def _legend(fig, shown: dict[str, scene.Style], columns: int) -> float:
    """The legend under the panels; returns the height it takes [inches]."""
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], marker="o", linestyle="", markersize=6, color=_rgb(s), label=s.label)
        for s in shown.values()
    ]
    if handles:
        fig.legend(handles=handles, loc="lower center", ncol=columns, fontsize=7, frameon=False)
    return 0.2 + 0.16 * -(-len(handles) // columns)


@dataclass(frozen=True)
class Plot:
    """A plot beside the scans: layers of a plot space (histogram, cost, dot plot) and its axes."""

    title: str
    x_label: str
    y_label: str
    layers: list[scene.Layer]
    y_values: bool = True  # False: the heights are relative (no tick values)


def scene_png(
    panels: list[tuple[str, list[scene.Layer]]],
    side: Plot | None,
    title: str,
    window: tuple[float, float, float, float] | None = None,
) -> bytes:
    """PNG bytes: one scan-plane panel per (title, layers), side by side with the same window
    (``window``, else all they draw), and optionally a plot beside them; one legend for
    everything."""
    plt = pyplot()
    n = len(panels) + (side is not None)
    fig, axes = plt.subplots(1, n, figsize=(4.6 * n, 4.8), squeeze=False)
    shown: dict[str, scene.Style] = {}
    scan_axes = axes[0][: len(panels)]
    for ax, (name, layers) in zip(scan_axes, panels):
        draw_layers(ax, [ly for ly in layers if ly.path.startswith(f"{scene.SCANS}/")], shown)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("x [m] (reference laser frame)", fontsize=8)
        ax.set_ylabel("y [m]", fontsize=8)
        ax.set_aspect("equal", adjustable="box")
        ax.grid(True, linewidth=0.3, alpha=0.5)
        ax.tick_params(labelsize=7)
    _same_window(scan_axes, window)
    if side is not None:
        ax = axes[0][-1]
        draw_layers(ax, side.layers, shown)
        ax.autoscale_view()
        ax.set_title(side.title, fontsize=9)
        ax.set_xlabel(side.x_label, fontsize=8)
        ax.set_ylabel(side.y_label, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, linewidth=0.3, alpha=0.5)
        if not side.y_values:
            ax.set_yticks([])
    fig.suptitle(title, fontsize=11)
    legend_in = _legend(fig, shown, min(n, 3))
    width, height = fig.get_size_inches()
    fig.set_size_inches(width, height + legend_in)
    fig.tight_layout(rect=(0, legend_in / (height + legend_in), 1, 0.95))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()
