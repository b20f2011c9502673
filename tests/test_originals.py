"""The baselines reproduce their originals: poses the original C implementations return on real
pairs, pinned. How they were obtained (reproduce with docs/reference.md, "Faithful baselines"):
the original code built locally from its public sources, never part of this project —

- MbICP: Minguez's C library as Player ships it (playerproject/player at cb1e0b13,
  server/drivers/position/mbicp), ``gcc -O2``, called as Player's ``mbicp`` driver calls it, with
  the driver's defaults (``PLAYER``: ``MbicpParams()`` with its 7.9 m range limit), every beam
  passed (invalid ones beyond max range). FLASER bearings as CARMEN reads them (1 degree steps for
  Intel's and aces' 180 readings).
- ICP and PL-ICP: Censi's CSM (AndreaCensi/csm at dff25579), ``cmake -DCMAKE_BUILD_TYPE=Release``,
  ``sm_icp`` with the options ``sm2`` sets (``IcpParams()``, ``PlIcpParams()``), the guess as
  ``first_guess``, use_point_to_line_distance 0 and 1; every beam passed with its valid flag.
  Poses and iteration counts (restarts included) are pinned.

Guesses: the log's relative pose perturbed uniformly within +/-0.2 m, +/-10 deg (seed 7).
"""

import math

import pytest

from mbicp_viz.core import IcpParams, MbicpParams, PlIcpParams, Pose2, match, pose_error
from mbicp_viz.readers import read_log

from .conftest import DATA, EXAMPLES

FILES = {
    "laserazosSM3-40.log": DATA / "laserazosSM3-40.log",
    "intel-excerpt.log.gz": EXAMPLES / "intel-excerpt.log.gz",
    "aces-10.log.gz": DATA / "aces-10.log.gz",
}

# Player's mbicp driver's parameters (the preset ``player``)
PLAYER = MbicpParams(max_range=7.9)

# (file, reference scan k (object k + 1), guess (x, y, theta), the C code's pose)
MBICP_C = [
    ("laserazosSM3-40.log", 1, (0.068597, 0.158797, 0.087776), (0.0263137, -0.0399866, -0.0583488)),
    (
        "laserazosSM3-40.log",
        4,
        (-0.029549, -0.080956, 0.105472),
        (0.0649131, -0.0195396, -0.0291036),
    ),
    ("laserazosSM3-40.log", 7, (-0.120589, 0.128829, 0.114823), (0.0704202, -0.0052696, -0.003952)),
    (
        "intel-excerpt.log.gz",
        1,
        (-0.008292, -0.063391, -0.584401),
        (-0.0655022, -0.1046552, -0.5092097),
    ),
    (
        "intel-excerpt.log.gz",
        4,
        (-0.142683, -0.092831, -0.535442),
        (-0.0329217, -0.0522643, -0.5460405),
    ),
    (
        "intel-excerpt.log.gz",
        7,
        (0.021266, 0.173959, -0.432642),
        (0.1628547, 0.1790392, -0.5376357),
    ),
    ("aces-10.log.gz", 1, (0.05827, 0.147456, -0.621376), (-0.0052347, -0.029494, -0.5236899)),
    ("aces-10.log.gz", 4, (0.69962, 0.244163, 0.476316), (0.781643, 0.1613474, 0.6397521)),
    ("aces-10.log.gz", 7, (-0.192978, 0.001017, 0.562553), (-0.0147506, 0.0331324, 0.5772082)),
]


# (file, k, guess, CSM's pose, CSM's iterations)
ICP_CSM = [
    (
        "laserazosSM3-40.log",
        1,
        (0.068597, 0.158797, 0.087776),
        (0.0263295, -0.0390476, -0.0590846),
        35,
    ),
    (
        "laserazosSM3-40.log",
        4,
        (-0.029549, -0.080956, 0.105472),
        (0.0648673, -0.0189952, -0.0290133),
        22,
    ),
    (
        "laserazosSM3-40.log",
        7,
        (-0.120589, 0.128829, 0.114823),
        (0.0699064, -0.0049979, -0.0039439),
        25,
    ),
    (
        "intel-excerpt.log.gz",
        1,
        (-0.008292, -0.063391, -0.584401),
        (-0.0682067, -0.1096251, -0.5090516),
        4,
    ),
    (
        "intel-excerpt.log.gz",
        4,
        (-0.142683, -0.092831, -0.535442),
        (-0.0334851, -0.0518447, -0.5462267),
        16,
    ),
    (
        "intel-excerpt.log.gz",
        7,
        (0.021266, 0.173959, -0.432642),
        (0.1223155, 0.127349, -0.5381339),
        24,
    ),
    (
        "aces-10.log.gz",
        1,
        (0.05827, 0.147456, -0.621376),
        (-0.0112284, -0.0288916, -0.5234893),
        160,
    ),
    ("aces-10.log.gz", 4, (0.69962, 0.244163, 0.476316), (0.7166672, 0.1148975, 0.6424084), 147),
    ("aces-10.log.gz", 7, (-0.192978, 0.001017, 0.562553), (-0.0146471, 0.0310043, 0.5775417), 113),
]
PLICP_CSM = [
    (
        "laserazosSM3-40.log",
        1,
        (0.068597, 0.158797, 0.087776),
        (0.0258696, -0.0391832, -0.0591721),
        8,
    ),
    (
        "laserazosSM3-40.log",
        4,
        (-0.029549, -0.080956, 0.105472),
        (0.0649222, -0.0191205, -0.0291731),
        7,
    ),
    (
        "laserazosSM3-40.log",
        7,
        (-0.120589, 0.128829, 0.114823),
        (0.0699424, -0.0049047, -0.0042021),
        6,
    ),
    (
        "intel-excerpt.log.gz",
        1,
        (-0.008292, -0.063391, -0.584401),
        (-0.0660852, -0.1063425, -0.509059),
        5,
    ),
    (
        "intel-excerpt.log.gz",
        4,
        (-0.142683, -0.092831, -0.535442),
        (-0.0320313, -0.0525778, -0.5465622),
        6,
    ),
    (
        "intel-excerpt.log.gz",
        7,
        (0.021266, 0.173959, -0.432642),
        (0.0220908, -0.0027823, -0.5380587),
        13,
    ),
    ("aces-10.log.gz", 1, (0.05827, 0.147456, -0.621376), (-0.0112325, -0.0271804, -0.5238875), 43),
    ("aces-10.log.gz", 4, (0.69962, 0.244163, 0.476316), (0.7573722, 0.1465348, 0.6400737), 92),
    ("aces-10.log.gz", 7, (-0.192978, 0.001017, 0.562553), (-0.0139064, 0.0265632, 0.5777766), 42),
]


@pytest.fixture(scope="module")
def logs():
    return {name: read_log(path) for name, path in FILES.items()}


@pytest.mark.parametrize("name, k, guess, original", MBICP_C)
def test_mbicp_returns_the_original_c_codes_pose(logs, name, k, guess, original):
    """Within 1 mm and 0.01 deg (the C code computes in single precision)."""
    scans = logs[name].scans
    result = match(scans[k], scans[k + 1], Pose2(*guess), PLAYER)
    et, er = pose_error(result.pose, Pose2(*original))
    assert et < 1e-3 and er < math.radians(0.01), (et, math.degrees(er))


@pytest.mark.parametrize(
    "params, name, k, guess, original, iterations",
    [(IcpParams(), *case) for case in ICP_CSM] + [(PlIcpParams(), *case) for case in PLICP_CSM],
    ids=[f"icp-{c[0]}-{c[1]}" for c in ICP_CSM] + [f"plicp-{c[0]}-{c[1]}" for c in PLICP_CSM],
)
def test_icp_and_plicp_return_csms_pose(logs, params, name, k, guess, original, iterations):
    """Within 0.01 mm and 0.001 deg, in as many iterations (CSM computes in double precision
    too)."""
    scans = logs[name].scans
    result = match(scans[k], scans[k + 1], Pose2(*guess), params)
    et, er = pose_error(result.pose, Pose2(*original))
    assert et < 1e-5 and er < math.radians(1e-3), (et, math.degrees(er))
    assert result.iterations == iterations and result.converged
