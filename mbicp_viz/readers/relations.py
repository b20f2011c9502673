"""Kümmerle et al. 2009 relations files: ``t1 t2 x y z roll pitch yaw`` per line (``#`` comments).

Each relation is the pose at t2 seen from the pose at t1, in the frame of the first (metres,
radians; the planar part is read: x, y, yaw).
"""

from __future__ import annotations

from dataclasses import dataclass

from mbicp_viz.core import Pose2
from mbicp_viz.errors import InputError

from .text import token_lines

LAYOUT = "t1 t2 x y z roll pitch yaw"


@dataclass(frozen=True)
class Relation:
    t1: float  # [s]
    t2: float  # [s]
    pose: Pose2  # pose at t2 in the frame of the pose at t1


def read_relations(path: str) -> list[Relation]:
    out = []
    for fields in token_lines(path):
        t1, t2, x, y = (fields.take(name) for name in ("t1", "t2", "x", "y"))
        fields.take("z"), fields.take("roll"), fields.take("pitch")
        yaw = fields.take("yaw")
        fields.end(LAYOUT)
        out.append(Relation(t1, t2, Pose2(x, y, yaw)))
    if not out:
        raise InputError("no relations", path)
    return out
