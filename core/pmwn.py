"""PMWN — Polar Metric-Weighted Norm scan matching (Huo et al. 2016, paper 003).

The paper's equations were lost in our copy; what its prose fixes is implemented as follows
(docs/algorithms.md, "PMWN"):

- Preprocessing and scan projection as PSM (paper 003 §3, steps 1-3).
- Correspondence by shifting (§3.1-3.2): for each shift k of the projected ranges against the
  reference, N(k) = (1/n_k) sum_i |r_ref(phi_i) - r_cur(phi_{i+k})| + lambda |k dphi| — the range
  term averaged over the n_k bearings that have both ranges (the count varies with k), plus the
  metric-weighted angle term that prices rotation against translation, as MbICP's L does.
- Adaptive metric weight (§3.2, eq. 17): lambda_{t+1} = D_t / max(|theta_t|, dphi), the weight
  that balances both terms at the rotation the range term points to (D_t: mean |range
  difference| of the used pairs, theta_t: the shift where the range cost alone is least); the
  first iteration uses ``lambda0``; capped at ``lambda_max``. Shown per iteration in the events
  (``PolarStep.metric_weight``).
- Rotation (§4.1): k* = argmin N(k), refined with the linear absolute-value (V) function through
  the minimum and its neighbours: offset = (a - c) / (2 (max(a, c) - b)).
- Translation (§3.3, §4.2): under a pure translation T the range change along a ray u_i is
  dr_i ~ u_i . T, so the points dr_i u_i lie on the "projected circle" through the origin with
  centre T/2 (Thales). Its centre comes from the weighted least squares u_i . T = dr_i
  (w_i = C / (C + dr_i^2), the weight of the paper's ref. [22] — PSM's, with its schedule: C drops
  from ``C`` to ``C_late`` after ``C_switch`` iterations), which a 180-270 degree field of view does
  not bias as the mean of the points would. Events carry the circle points and the fitted centre.
- Stops after ``stop_after`` small corrections in a row, or at MaxIter (paper 003 Table 1).
"""

from __future__ import annotations

from .events import Observer
from .params import PmwnParams
from .polar import Strategy, refine_v, run_polar
from .result import MatchResult
from .scan import Scan
from .se2 import Pose2


def match(
    ref: Scan,
    obj: Scan,
    initial_guess: Pose2 = Pose2(),
    params: PmwnParams | None = None,
    observer: Observer | None = None,
) -> MatchResult:
    """Pose of the object frame in the reference frame, starting from ``initial_guess``."""
    p = params if params is not None else PmwnParams()
    strategy = Strategy(
        "pmwn", orientation_due=lambda it: True, refine=refine_v, fit="V", metric=True
    )
    return run_polar(strategy, ref, obj, initial_guess, p, observer)
