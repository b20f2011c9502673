"""Which candidate pairs the minimisation uses (compiled: the matchers' loops call it)."""

from __future__ import annotations

import numpy as np

from .events import PairStatus
from .metric import kth_smallest, mad_threshold
from .tiers import kernel

KEPT, OUTSIDE_BR, TRIMMED, MAD = (
    int(s) for s in (PairStatus.KEPT, PairStatus.OUTSIDE_BR, PairStatus.TRIMMED, PairStatus.MAD)
)


@kernel
def reject(
    dist: np.ndarray,
    max_dist: float,
    keep_fraction: float,
    use_mad: bool,
    mad_k: float,
    mad_floor: float,
    shown: bool = True,
):
    """Status of each pair and the distance threshold applied after the hard cut (NaN: none).

    First the hard cut ``max_dist`` (MbICP's radial window Br). Then either the trimmed estimator
    — keep the best ``keep_fraction`` of the remaining pairs (MbICP's ``filter``) — or, with
    ``use_mad``, paper 000 eq. 5: reject pairs above median + mad_k * MAD of the remaining
    distances (§2.4.2), but never below ``mad_floor``. When no pair lies above the floor MAD
    rejects none whatever its value, and unless the threshold is ``shown`` (recorded) its two
    selections are skipped: the threshold is then NaN.
    """
    status = np.empty(len(dist), dtype=np.int8)
    for i in range(len(dist)):
        status[i] = OUTSIDE_BR if dist[i] > max_dist else KEPT
    inside = np.flatnonzero(status == KEPT)
    if len(inside) == 0:
        return status, np.nan
    d_in = dist[inside]
    if use_mad:
        if not shown and d_in.max() <= mad_floor:
            return status, np.nan
        thr = max(mad_threshold(d_in, mad_k), mad_floor)
        for j in range(len(inside)):
            if d_in[j] > thr:
                status[inside[j]] = MAD
        return status, thr
    n_keep = int(len(d_in) * keep_fraction)
    if n_keep >= len(d_in):
        return status, np.nan
    cut = kth_smallest(d_in, n_keep)  # the first distance trimmed
    ties = n_keep - np.count_nonzero(d_in < cut)  # pairs at the cut that stay: the earliest
    for j in range(len(d_in)):
        if d_in[j] > cut or (d_in[j] == cut and ties <= 0):
            status[inside[j]] = TRIMMED
        elif d_in[j] == cut:
            ties -= 1
    return status, cut
