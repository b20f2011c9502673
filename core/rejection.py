"""Which candidate pairs the minimisation uses."""

from __future__ import annotations

import numpy as np

from .events import PairStatus
from .metric import mad_threshold


def reject(dist: np.ndarray, max_dist: float, keep_fraction: float,
           mad_k: float | None = None, mad_floor: float = 0.0) -> tuple[np.ndarray, float | None]:
    """Status of each pair and the distance threshold applied after the hard cut (or None).

    First the hard cut ``max_dist`` (MbICP's radial window Br; ICP's maximum pair distance).
    Then either the trimmed estimator — keep the best ``keep_fraction`` of the remaining pairs
    (MbICP's ``filter``) — or, when ``mad_k`` is given, paper 000 eq. 5: reject pairs above
    median + mad_k * MAD of the remaining distances (§2.4.2), but never below ``mad_floor``.
    """
    outside = dist > max_dist
    status = np.where(outside, np.int8(PairStatus.OUTSIDE_BR), np.int8(PairStatus.KEPT))
    inside = np.flatnonzero(~outside)
    if len(inside) == 0:
        return status, None
    d_in = dist[inside]
    if mad_k is not None:
        thr = max(mad_threshold(d_in, mad_k), mad_floor)
        status[inside[d_in > thr]] = PairStatus.MAD
        return status, thr
    n_keep = int(len(d_in) * keep_fraction)
    if n_keep >= len(d_in):
        return status, None
    order = np.argsort(d_in, kind="stable")  # ties at the cut: the earlier pair stays
    status[inside[order[n_keep:]]] = PairStatus.TRIMMED
    return status, float(d_in[order[n_keep]])
