"""Compile every kernel into numba's cache: ``python -m mbicp_viz.core.warmup``.

The background process of the quick-start tier (core/tiers.py), also usable by hand after an
install. Every matcher runs on a synthetic room, without an observer and with one (the
debugger's replay), which calls every kernel with the argument types that real scans give them
(tests/test_tiers.py: matching real scans afterwards compiles nothing).
"""

from __future__ import annotations

import numpy as np

from .agreement import agreement
from .events import Recorder
from .matchers import MATCHERS, matcher_for
from .metric import mad_threshold
from .scan import Scan, make_scan, uniform_bearings
from .se2 import Pose2
from .tiers import run

# A 6 m x 4 m room with a pillar, seen by a 270-degree, 541-beam scanner
ROOM_HALF_M = np.array([3.0, 2.0])
PILLAR_M, PILLAR_RADIUS_M = np.array([1.0, 0.5]), 0.3


def room_scan(sensor: Pose2) -> Scan:
    """The room seen from ``sensor`` (its pose in the room), ray-cast exactly."""
    bearings = uniform_bearings(541, -0.75 * np.pi, 1.5 * np.pi / 540)
    a = bearings + sensor.theta
    d = np.stack([np.cos(a), np.sin(a)], axis=1)
    o = np.array([sensor.x, sensor.y])
    with np.errstate(divide="ignore"):
        walls = np.min(np.abs((np.sign(d) * ROOM_HALF_M - o) / d), axis=1)
    b = d @ (o - PILLAR_M)
    disc = b * b - (np.sum((o - PILLAR_M) ** 2) - PILLAR_RADIUS_M**2)
    pillar = np.where(disc > 0, -b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    return make_scan(
        np.minimum(walls, np.where(pillar > 0, pillar, np.inf)), bearings, range_max=30.0
    )


def _room_pair() -> tuple[Scan, Scan, Pose2]:
    """Two scans of the room a little apart, and a guess of their motion."""
    ref, obj = room_scan(Pose2(-0.5, -0.3, 0.1)), room_scan(Pose2(-0.35, -0.25, 0.2))
    return ref, obj, Pose2(0.1, 0.0, 0.05)


def load_kernels(params) -> None:
    """The kernels a run of ``params``' matcher calls for every pair (its match and the pair's
    agreement), loaded in this process: from numba's cache, compiled if missing. A run's start-up,
    kept out of its pace; and a pool's workers, forked afterwards, share them instead of each
    loading them again (0.4-0.5 s a worker here)."""
    ref, obj, guess = _room_pair()
    matcher_for(params).run(ref, obj, guess, params)
    agreement(ref, obj, guess)


def compile_all() -> None:
    ref, obj, guess = _room_pair()
    for m in MATCHERS.values():
        m.run(ref, obj, guess, m.params_type())
        m.run(ref, obj, guess, m.params_type(), Recorder())
    run(mad_threshold, np.linspace(0.0, 1.0, 21), 2.0)  # the lesson's distances
    agreement(ref, obj, guess)  # every pair's record


if __name__ == "__main__":
    compile_all()
