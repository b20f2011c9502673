"""The viser front end's drawing: scene layers -> viser scene nodes (the same layers rerun draws)."""

from __future__ import annotations

import math

import numpy as np

from . import scene

# Layer groups a user can toggle, by the last part of the layer path.
GROUPS = {
    "reference": ("reference",),
    "object scan": ("object", "object_initial", "object_after"),
    "point pairs": ("pairs/point",),
    "interpolated pairs": ("pairs/interpolated", "interpolated_targets"),
    "rejected pairs": ("pairs/rejected",),
    "hidden points": ("hidden",),
    "resampling grid": ("resampling_grid",),
    "iso-distance curves": ("teaching/metric_isocurves", "teaching/euclidean_circles"),
    "known answer": ("truth",),
    "estimate": ("estimate",),
}
DEFAULT_OFF = {"iso-distance curves", "hidden points"}


def group_of(path: str) -> str | None:
    rel = path.split(f"{scene.SCANS}/", 1)[-1]
    return next((g for g, names in GROUPS.items() if rel in names), None)


def _xyz(xy: np.ndarray, z: float = 0.0) -> np.ndarray:
    xy = np.asarray(xy, dtype=np.float32).reshape(-1, 2)
    return np.column_stack((xy, np.full(len(xy), z, dtype=np.float32)))


def _colors(c, n: int) -> np.ndarray:
    c = np.asarray(c, dtype=np.uint8)
    return np.broadcast_to(c[..., :3], (n, 3)) if c.ndim == 1 else c[:, :3]


def _segments(starts: np.ndarray, ends: np.ndarray, z: float) -> np.ndarray:
    return np.stack((_xyz(starts, z), _xyz(ends, z)), axis=1)


def _strip_segments(strips: list[np.ndarray], z: float) -> np.ndarray:
    segs = [_segments(s[:-1], s[1:], z) for s in strips if len(s) > 1]
    return np.concatenate(segs) if segs else np.zeros((0, 2, 3), np.float32)


def _box_segments(centers: np.ndarray, h: float, z: float) -> np.ndarray:
    corners = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    c = centers[:, None, :] + corners[None]  # (N, 4, 2)
    return np.concatenate([_segments(c[:, k], c[:, (k + 1) % 4], z) for k in range(4)])


# Draw order by height above the plane: pairs over scans, grid below.
_Z = {"resampling_grid": -0.02, "pairs": 0.01, "teaching": 0.015}


def _z(path: str) -> float:
    return next((z for key, z in _Z.items() if key in path), 0.0)


def draw(scene_api, name: str, layer, visible: bool = True, point_size: float = 0.04):
    """Add (or replace) the node ``name`` for one layer; Scalar and Text layers are not scene nodes."""
    z = _z(layer.path)
    if isinstance(layer, scene.Points):
        pts = _xyz(layer.xy, z)
        return scene_api.add_point_cloud(name, pts, _colors(layer.color, len(pts)),
                                         point_size=point_size * max(layer.radius / 0.02, 0.5),
                                         point_shape="circle", precision="float32", visible=visible)
    if isinstance(layer, (scene.Segments, scene.Strips, scene.Boxes)):
        if isinstance(layer, scene.Segments):
            segs, color, width = _segments(layer.starts, layer.ends, z), layer.color, layer.width
        elif isinstance(layer, scene.Strips):
            segs, color, width = _strip_segments(layer.strips, z), layer.color, layer.width
        else:
            segs = _box_segments(layer.centers, layer.half_size, z)
            color, width = np.repeat(layer.colors[:, :3], 4, axis=0)[:, None, :].repeat(2, axis=1), 0.004
        if len(segs) == 0:
            segs = np.zeros((1, 2, 3), np.float32)  # an empty node keeps the name (and its visibility)
            color = (0, 0, 0)
        colors = np.asarray(color, np.uint8)
        if colors.ndim == 1:
            colors = np.broadcast_to(colors, (len(segs), 2, 3))
        return scene_api.add_line_segments(name, segs, colors, thickness=max(width, 0.004) * 1.5,
                                           visible=visible)
    if isinstance(layer, scene.Frame):
        p = layer.pose
        return scene_api.add_frame(name, axes_length=0.4, axes_radius=0.015, position=(p.x, p.y, 0.02),
                                   wxyz=yaw_to_wxyz(p.theta), visible=visible)
    return None


def yaw_to_wxyz(theta: float) -> tuple[float, float, float, float]:
    return (math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2))


def wxyz_to_yaw(wxyz) -> float:
    w, x, y, z = (float(v) for v in wxyz)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
