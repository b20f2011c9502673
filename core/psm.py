"""PSM — Polar Scan Matching (Diosi & Kleeman, IJRR 2007), as summarised in docs/algorithms.md.

Median filter and segmentation, scan projection with occlusion, an orientation step that shifts
the projected ranges and refines the best shift with a parabola, and a weighted translation step
(w = C / (C + e^2), C lowered after C_switch iterations), alternated until ``stop_after`` small
corrections in a row. Diosi's pm_psm alternates one orientation pass and one translation pass,
re-projecting before each; one iteration here holds both (``orientation_every`` = 1; with n > 1
only every n-th iteration turns the scan).
"""

from __future__ import annotations

from .events import Observer
from .params import PsmParams
from .polar import Strategy, refine_parabola, run_polar
from .result import MatchResult
from .scan import Scan
from .se2 import Pose2


def match(
    ref: Scan,
    obj: Scan,
    initial_guess: Pose2 = Pose2(),
    params: PsmParams | None = None,
    observer: Observer | None = None,
) -> MatchResult:
    """Pose of the object frame in the reference frame, starting from ``initial_guess``."""
    p = params if params is not None else PsmParams()
    strategy = Strategy(
        "psm",
        orientation_due=lambda it: (it - 1) % p.orientation_every == 0,
        refine=refine_parabola,
        fit="parabola",
        metric=False,
    )
    return run_polar(strategy, ref, obj, initial_guess, p, observer)
