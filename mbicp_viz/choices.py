"""The choices the commands offer (command-line choice options take them as they are): plain
enums, importable without loading numpy, so that ``--help`` lists them at once."""

from __future__ import annotations

import enum

# The ROS distro whose message types decode a ROS 2 bag recorded without them (``--typestore``)
DEFAULT_TYPESTORE = "ROS2_HUMBLE"

# The time budget of one match [s] (``--budget-s``, the debugger's): the bundled pairs take
# milliseconds and real logs' matches under a second; one still running after a minute is not
# converging usefully (a 100,000-beam scan under PSM: about 4 s an iteration).
MATCH_BUDGET_S = 60.0


class Guess(str, enum.Enum):
    """Where an initial guess comes from (``--guess``)."""

    stored = "stored"  # the scan poses the log stores, else its odometry, else the identity
    pose = "pose"
    odometry = "odometry"
    identity = "identity"
    search = "search"  # the correlative search around the identity (core/search.py)


class Thin(str, enum.Enum):
    """The copy of a displaced scan that loses points (``--thin``, a scenario's ``thin``)."""

    reference = "reference"  # the object's points there then lack counterparts (paper 000 §3.1)
    object = "object"


class Removal(str, enum.Enum):
    """How the 1 - eta of the points are removed (``--removal``)."""

    block = "block"  # one contiguous block, as an occlusion leaves
    random = "random"  # paper 000's wording (§3.2)


class Deskew(str, enum.Enum):
    """Where the velocity that corrects a scan for the motion during it comes from (``--deskew``,
    readers/deskew.py)."""

    odometry = "odometry"  # the log's odometry between consecutive scans
    velocity = "velocity"  # the motion matched between consecutive scans as measured
