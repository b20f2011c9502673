"""The viser front end's drawing: scene layers -> viser scene nodes (the same layers rerun draws).

Layers under the scan plane (``scene.SCANS``) become nodes at heights that follow their draw
order (the camera looks straight down); the plot-space layers (histogram, polar cost and ranges)
and the scalars and texts are the panels' business. Any other layer is an error: nothing is
dropped without a word.
"""

from __future__ import annotations

import math

import numpy as np

from . import scene

# Layers whose data the debugger shows in its plot panels rather than in the scan plane.
PLOT_SPACES = (f"{scene.TEACH}/histogram/", f"{scene.POLAR}/cost/", f"{scene.POLAR}/ranges/")
Z_PER_ORDER = 0.002  # [m] height per unit of draw order: higher draws on top


def in_scan_plane(layer: scene.Layer) -> bool:
    """True for a layer the scan plane draws, False for one a panel shows; an error for anything
    else."""
    if isinstance(layer, (scene.Scalar, scene.Text)) or layer.path.startswith(PLOT_SPACES):
        return False
    if layer.path.startswith((f"{scene.SCANS}/", f"{scene.RUN}/")) and isinstance(
        layer, scene.DRAWN
    ):
        return True
    raise TypeError(
        f"the debugger has no place for the {type(layer).__name__} layer {layer.path!r}"
    )


def _xyz(xy: np.ndarray, z: float = 0.0) -> np.ndarray:
    xy = np.asarray(xy, dtype=np.float32).reshape(-1, 2)
    return np.column_stack((xy, np.full(len(xy), z, dtype=np.float32)))


def _segments(starts: np.ndarray, ends: np.ndarray, z: float) -> np.ndarray:
    return np.stack((_xyz(starts, z), _xyz(ends, z)), axis=1)


def _strip_segments(strips: list[np.ndarray], z: float) -> np.ndarray:
    segs = [_segments(s[:-1], s[1:], z) for s in strips if len(s) > 1]
    return np.concatenate(segs) if segs else np.zeros((0, 2, 3), np.float32)


def _box_segments(centers: np.ndarray, h: float, z: float) -> np.ndarray:
    corners = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    c = centers[:, None, :] + corners[None]  # (N, 4, 2)
    return np.concatenate([_segments(c[:, k], c[:, (k + 1) % 4], z) for k in range(4)])


def _line_geometry(layer, z: float):
    """(segments (N, 2, 3), colours (N, 2, 3), width) of a line-like layer."""
    color = np.asarray(layer.style.color, np.uint8)
    if isinstance(layer, scene.Segments):
        segs = _segments(layer.starts, layer.ends, z)
    elif isinstance(layer, scene.Strips):
        segs = _strip_segments(layer.strips, z)
    else:  # Boxes: each box's own colour on its four sides
        segs = (
            _box_segments(layer.centers, layer.half_size, z)
            if len(layer.centers)
            else np.zeros((0, 2, 3))
        )
        per_box = np.tile(layer.colors[:, :3], (4, 1))
        return segs, np.repeat(per_box[:, None, :], 2, axis=1).astype(np.uint8), 0.004
    width = layer.width
    return segs, np.broadcast_to(color, (len(segs), 2, 3)), width


def draw(scene_api, name: str, layer: scene.Layer, visible: bool = True):
    """Add (or replace) the node ``name`` for one scan-plane layer."""
    z = layer.style.order * Z_PER_ORDER
    if isinstance(layer, scene.Points):
        pts, colors = _cloud(layer, z)
        # viser 1.1's point shader draws point_size / tan(fov/2) * height / z pixels: twice the
        # projection of a world length, so a dot of diameter 2r takes point_size = r.
        return scene_api.add_point_cloud(
            name,
            pts,
            colors,
            point_size=layer.radius,
            point_shape="circle",
            precision="float32",
            visible=visible,
        )
    if isinstance(layer, LINES):
        segs, colors, thickness = _lines(layer, z)
        return scene_api.add_line_segments(name, segs, colors, thickness=thickness, visible=visible)
    if isinstance(layer, scene.Frame):
        return scene_api.add_frame(name, **_frame(layer, z), visible=visible)
    raise TypeError(f"the debugger cannot draw a {type(layer).__name__} layer ({layer.path})")


LINES = (scene.Segments, scene.Strips, scene.Boxes)


def _cloud(layer: scene.Points, z: float) -> tuple[np.ndarray, np.ndarray]:
    """A point layer's points (N, 3) and colours: one colour for the whole cloud is sent once,
    not per point (a fifth of a map's bytes)."""
    c = layer.colors[:, :3] if layer.colors is not None else layer.style.color[:3]
    return _xyz(layer.xy, z), np.asarray(c, np.uint8)


def _lines(layer, z: float) -> tuple[np.ndarray, np.ndarray, float]:
    """A line layer's segments (N, 2, 3), colours and thickness; an empty layer one segment of
    nothing, so that its node keeps its name (and its visibility)."""
    segs, colors, width = _line_geometry(layer, z)
    if len(segs) == 0:
        segs, colors = np.zeros((1, 2, 3), np.float32), np.zeros((1, 2, 3), np.uint8)
    return segs, colors, max(width, 0.004) * 1.5


def _frame(layer: scene.Frame, z: float) -> dict:
    """A frame layer's node properties: its pose, and axes in proportion to its length."""
    p, radius = layer.pose, 0.04 * layer.length
    return dict(
        position=(p.x, p.y, z),
        wxyz=yaw_to_wxyz(p.theta),
        axes_length=layer.length,
        axes_radius=radius,
        origin_radius=2.0 * radius,
    )


def draw_nodes(scene_api, nodes: dict, layers) -> dict:
    """The nodes of ``layers`` (name, layer, visible), given the ``nodes`` drawn before (name ->
    handle): a node of the same name and kind takes its layer's new geometry in place, any other
    is drawn anew, and the nodes not drawn again are removed. In place, the page updates the
    node's buffers instead of building it again: a run view's slider step on the full Intel log
    took 0.59 s in software WebGL when its pair's four nodes were built anew each step."""
    drawn = {}
    for name, layer, visible in layers:
        handle = nodes.get(name)
        if handle is None or not _update(handle, layer, visible):
            handle = draw(scene_api, name, layer, visible)
        drawn[name] = handle
    for name in nodes.keys() - drawn.keys():
        nodes[name].remove()
    return drawn


def _update(handle, layer: scene.Layer, visible: bool) -> bool:
    """``layer`` drawn into the node ``handle`` already holds, when it is of the layer's kind
    (viser sends only the properties that changed); False when it is not."""
    import viser

    z = layer.style.order * Z_PER_ORDER
    if isinstance(layer, scene.Points) and isinstance(handle, viser.PointCloudHandle):
        handle.points, handle.colors = _cloud(layer, z)
        handle.point_size = layer.radius
    elif isinstance(layer, LINES) and isinstance(handle, viser.LineSegmentsHandle):
        handle.points, handle.colors, handle.thickness = _lines(layer, z)
    elif isinstance(layer, scene.Frame) and isinstance(handle, viser.FrameHandle):
        for prop, value in _frame(layer, z).items():
            setattr(handle, prop, value)
    else:
        return False
    handle.visible = visible
    return True


def yaw_to_wxyz(theta: float) -> tuple[float, float, float, float]:
    return (math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2))


def wxyz_to_yaw(wxyz) -> float:
    w, x, y, z = (float(v) for v in wxyz)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def grid_cell(extent_m: float) -> float:
    """A round grid cell for a scene ``extent_m`` across: 10 to 40 cells over it."""
    return next(
        (c for c in (0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0) if extent_m / c <= 40), 100.0
    )


def metric_grid(scene_api, pts: np.ndarray) -> float:
    """A metric grid in the scan plane under ``pts`` (x right, y up), thicker every five cells,
    just below the layers; its cell [m], for the legend."""
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    cell = grid_cell(float((hi - lo).max()))
    size = (np.ceil((hi - lo) / cell) + 4) * cell
    centre = np.round((lo + hi) / 2 / cell) * cell
    scene_api.add_grid(
        "/grid",
        float(size[0]),
        float(size[1]),
        plane="xy",
        cell_size=cell,
        section_size=cell * 5,
        position=(float(centre[0]), float(centre[1]), -0.01),
        shadow_opacity=0.0,
    )
    return cell
