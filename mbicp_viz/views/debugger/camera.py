"""A 2-D view on viser's 3-D camera: straight down on the scan plane, x right and y up, pan and
zoom only.

viser's camera orbits freely (a drag, or the arrow keys while a slider has the focus, tilts it
until the scans are edge-on). Whenever the browser reports a camera that is tilted or turned, it
is put back top-down over the same point at the same distance; panning and zooming keep it
top-down and pass untouched.
"""

from __future__ import annotations

import math

import numpy as np
import viser

TOLERANCE_RAD = math.radians(0.5)


class TopDownCamera:
    def __init__(self, client: viser.ClientHandle | viser.ViserServer):
        self.client = client
        if isinstance(client, viser.ClientHandle):
            client.camera.on_update(lambda cam: self.level(cam))

    def _cameras(self):
        if isinstance(self.client, viser.ClientHandle):
            return [self.client.camera]
        return [c.camera for c in self.client.get_clients().values()]

    @staticmethod
    def is_top_down(position, look_at, up) -> bool:
        d = np.asarray(position, float) - np.asarray(look_at, float)
        dist = float(np.linalg.norm(d))
        up = np.asarray(up, float)
        return (dist > 0 and d[2] >= dist * math.cos(TOLERANCE_RAD)
                and up[1] >= float(np.linalg.norm(up)) * math.cos(TOLERANCE_RAD))

    def level(self, cam) -> None:
        """Put a tilted or turned camera back top-down (same point, same distance)."""
        if self.is_top_down(cam.position, cam.look_at, cam.up_direction):
            return
        look = np.asarray(cam.look_at, float)
        dist = float(np.linalg.norm(np.asarray(cam.position, float) - look))
        self._place(cam, look[:2], dist)

    @staticmethod
    def _place(cam, centre, height: float) -> None:
        with cam.client.atomic():
            cam.up_direction = (0.0, 1.0, 0.0)
            cam.position = (float(centre[0]), float(centre[1]), float(height))
            cam.look_at = (float(centre[0]), float(centre[1]), 0.0)

    def fit(self, points: np.ndarray) -> None:
        """Top-down over ``points`` (the reference scan), the whole scan in view."""
        c = points.mean(axis=0) if len(points) else np.zeros(2)
        extent = float(np.ptp(points, axis=0).max()) if len(points) > 1 else 10.0
        height = max(extent * 1.1, 2.0)
        if isinstance(self.client, viser.ViserServer):  # no tab yet: where every tab starts
            cam = self.client.initial_camera
            cam.up, cam.position, cam.look_at = (0.0, 1.0, 0.0), (c[0], c[1], height), (c[0], c[1], 0.0)
        for cam in self._cameras():
            self._place(cam, c, height)
