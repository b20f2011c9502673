"""PSM — Polar Scan Matching (Diosi & Kleeman, IJRR 2007), as summarised in docs/algorithms.md.

Median filter and segmentation, scan projection with occlusion, a weighted translation step
(w = C / (C + e^2), C lowered after C_switch iterations) and, every ``orientation_every``-th
iteration, an orientation step that shifts the projected ranges and refines the best shift with
a parabola; alternated until ``stop_after`` small corrections in a row.
"""

from __future__ import annotations

from .events import Observer
from .params import PsmParams
from .polar import Strategy, refine_parabola, run_polar
from .result import MatchResult
from .scan import Scan
from .se2 import Pose2


def match(ref: Scan, obj: Scan, initial_guess: Pose2 = Pose2(), params: PsmParams | None = None,
          observer: Observer | None = None) -> MatchResult:
    """Pose of the object frame in the reference frame, starting from ``initial_guess``."""
    p = params if params is not None else PsmParams()
    strategy = Strategy("psm", orientation_due=lambda it: (it - 1) % p.orientation_every == 0,
                        refine=refine_parabola, fit="parabola",
                        weight_C=lambda it: p.C if it <= p.C_switch else p.C_late, metric=False)
    return run_polar(strategy, ref, obj, initial_guess, p, observer)
