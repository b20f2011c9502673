"""A 2-D view on viser's 3-D camera: straight down on the scan plane, x right and y up, pan and
zoom only.

viser's camera orbits freely (a drag, or the arrow keys while a slider has the focus, tilts it
until the scans are edge-on). Whenever the browser reports a camera that is tilted or turned, it
is put back top-down over the same point at the same distance; panning and zooming keep it
top-down and pass untouched.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import viser

TOLERANCE_RAD = math.radians(0.5)
SETTLE_S = 1.0  # reports this soon after the camera was placed may still show the view before
DEFAULT_ASPECT = 1.1  # a tab's view beside the fixed control panel, until it reports its own
MAX_REPLACEMENTS = 3  # a placement a tab did not take is sent again at most this many times


class TopDownCamera:
    def __init__(self, client: viser.ClientHandle | viser.ViserServer):
        self.client = client
        # when this put the camera somewhere (the tab's reports lag behind)
        self.placed_at = -math.inf
        self.placement: tuple[np.ndarray, float] | None = None  # (centre, height) last placed
        self.replaced = 0  # placements repeated since the last one asked for
        self.pending: np.ndarray | None = (
            None  # points to fit once the tab has reported its first view
        )
        self.recheck: threading.Timer | None = None
        self._pending_lock = threading.Lock()
        if isinstance(client, viser.ClientHandle):
            client.camera.on_update(lambda cam: self.level(cam))

    def stop(self) -> None:
        """No more looks (the tab has gone): a pending recheck is cancelled."""
        if self.recheck is not None:
            self.recheck.cancel()

    @staticmethod
    def is_top_down(position, look_at, up) -> bool:
        d = np.asarray(position, float) - np.asarray(look_at, float)
        dist = float(np.linalg.norm(d))
        up = np.asarray(up, float)
        return (
            dist > 0
            and d[2] >= dist * math.cos(TOLERANCE_RAD)
            and up[1] >= float(np.linalg.norm(up)) * math.cos(TOLERANCE_RAD)
        )

    def level(self, cam) -> None:
        """Fit a view asked for before the tab had one; put a tilted or turned camera back top-down
        (same point, same distance)."""
        with self._pending_lock:
            points, self.pending = self.pending, None
        if points is not None:
            self.fit(points)
            return
        top_down = self.is_top_down(cam.position, cam.look_at, cam.up_direction)
        wait = SETTLE_S - (time.monotonic() - self.placed_at)
        if wait > 0 and not (top_down and self._shows_placement(cam)):
            # maybe a report from before the tab took the last placement (a loaded tab's own
            # opening view can even overwrite it): look again once it has had time to settle
            if self.recheck is None or not self.recheck.is_alive():
                self.recheck = threading.Timer(wait, self._settled, (cam,))
                self.recheck.daemon = True
                self.recheck.start()
            return
        if top_down:
            return
        look = np.asarray(cam.look_at, float)
        self._place(cam, look[:2], float(np.linalg.norm(np.asarray(cam.position, float) - look)))

    def _settled(self, cam) -> None:
        """A placement's settling time is over: a tab whose latest view is still not the placement
        never took it, and gets it again (a few times at most: then its view is its own)."""
        if self._shows_placement(cam) or self.replaced >= MAX_REPLACEMENTS:
            self.level(cam)
            return
        self.replaced += 1
        self._place(cam, *self.placement, framed=True)

    def _shows_placement(self, cam) -> bool:
        if self.placement is None:
            return True
        centre, height = self.placement
        tol = 1e-3 * max(height, 1.0)
        placed = np.array([centre[0], centre[1], height])
        return bool(
            np.allclose(cam.position, placed, atol=tol)
            and np.allclose(cam.look_at, [centre[0], centre[1], 0.0], atol=tol)
        )

    def _place(self, cam, centre, height: float, framed: bool = False) -> None:
        """Top-down over ``centre``; a ``framed`` view (a fit) is checked once it has settled, a
        levelled one is the person's own view and is not."""
        self.placed_at = time.monotonic()
        self.placement = (np.array(centre[:2], float), float(height)) if framed else None
        with cam.client.atomic():
            cam.up_direction = (0.0, 1.0, 0.0)
            cam.position = (float(centre[0]), float(centre[1]), float(height))
            cam.look_at = (float(centre[0]), float(centre[1]), 0.0)

    @staticmethod
    def framing(points: np.ndarray, fov: float, aspect: float) -> tuple[np.ndarray, float]:
        """Centre and height of a top-down camera that shows all of ``points``."""
        lo, hi = points.min(axis=0), points.max(axis=0)
        w, h = np.maximum(hi - lo, 1.0) * 1.15
        tan = math.tan(fov / 2)
        return (lo + hi) / 2, max(h / (2 * tan), w / (2 * tan * aspect))

    def fit(self, points: np.ndarray) -> None:
        """Top-down over ``points`` (the reference scan), the whole scan in view. On the server, the
        view "reset view" returns to; on a tab that has not reported its first view yet, done when
        it does (a view placed while the tab is still opening is overwritten by the tab's own)."""
        pts = points if len(points) else np.zeros((1, 2))
        if isinstance(self.client, viser.ViserServer):
            cam = self.client.initial_camera
            c, height = self.framing(pts, cam.fov, DEFAULT_ASPECT)
            cam.up, cam.position, cam.look_at = (
                (0.0, 1.0, 0.0),
                (c[0], c[1], height),
                (c[0], c[1], 0.0),
            )
            return
        cam = self.client.camera
        if cam.update_timestamp > 0.0:
            c, height = self.framing(pts, cam.fov, cam.aspect or DEFAULT_ASPECT)
            self.replaced = 0
            self._place(cam, c, height, framed=True)
        else:  # the tab has not shown its first view yet: a view placed now would race it
            with self._pending_lock:
                self.pending = pts
            # its first report may have come in between: then nothing else would place it
            if cam.update_timestamp > 0.0:
                self.level(cam)


def on_scan_plane(origin, direction) -> np.ndarray | None:
    """Where a view ray (a click) meets the scan plane z = 0, (x, y) [m]; None if it runs along
    it."""
    o, d = np.asarray(origin, float), np.asarray(direction, float)
    if abs(d[2]) < 1e-9:
        return None
    return (o - o[2] / d[2] * d)[:2]
