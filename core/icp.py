"""Point-to-point ICP: Euclidean closest points (k-d tree) and the closed-form SVD fit (paper 000 §2.1).

The baseline the MbICP family is compared with: it has no notion of rotation when pairing, so
large rotations pull it into local minima.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .events import Correspondences, FinishEvent, IterationEvent, Observer, PairKind, PairStatus, StartEvent
from .metric import linearised_jacobians, mean_sq_residual, svd_fit
from .params import IcpParams
from .rejection import reject
from .result import MatchResult, Termination
from .scan import Scan
from .se2 import Pose2
from .uncertainty import DEGENERACY_LENGTH_M, FinalSystem, build_result



def match(ref: Scan, obj: Scan, initial_guess: Pose2 = Pose2(), params: IcpParams | None = None,
          observer: Observer | None = None) -> MatchResult:
    """Pose of the object frame in the reference frame, starting from ``initial_guess``."""
    params = params if params is not None else IcpParams()
    ref_pts = ref.points()
    tree = cKDTree(ref_pts)
    P = obj.points()
    used = np.arange(len(P))
    min_pairs = max(3, int(np.ceil(params.AsocError * len(P))))
    no_hidden = np.empty(0, dtype=np.int64)
    if observer is not None:
        observer(StartEvent("icp", params, ref_pts, P, used, initial_guess, None))

    est = initial_guess
    reason = Termination.MAX_ITERATIONS
    last = None
    it = 0
    for it in range(1, params.MaxIter + 1):
        moved = est.apply(P)
        dist, j = tree.query(moved, k=1)
        status, thr = reject(dist, params.max_correspondence_dist, params.filter)
        kept = status == PairStatus.KEPT
        n_kept = int(np.count_nonzero(kept))
        step = svd_fit(moved[kept], ref_pts[j[kept]]) if n_kept >= min_pairs else None
        inc = Pose2(*step) if step is not None else Pose2()
        error = float("nan")
        if step is not None:
            error = mean_sq_residual(inc.apply(moved[kept]), ref_pts[j[kept]])
        new_est = inc @ est
        if observer is not None:
            pairs = Correspondences(used, ref_pts[j], np.full(len(j), PairKind.POINT, dtype=np.int8),
                                    np.column_stack((j, np.full(len(j), -1))), dist, status, moved)
            observer(IterationEvent(it, est, new_est, moved, no_hidden, pairs, thr, error, inc))
        if step is None:
            reason = Termination.TOO_FEW_PAIRS
            break
        est = new_est
        J = linearised_jacobians(moved[kept])
        last = FinalSystem(np.einsum("nij,nik->jk", J, J), error, ref_pts[j[kept]], j[kept], n_kept,
                           len(status) - n_kept)
        if abs(inc.x) < params.errx_out and abs(inc.y) < params.erry_out and abs(inc.theta) < params.errt_out:
            reason = Termination.CONVERGED
            break

    result = build_result("icp", est, reason, it, last, ref_pts, ref.is_full_circle(), DEGENERACY_LENGTH_M)
    if observer is not None:
        observer(FinishEvent(result))
    return result
