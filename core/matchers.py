"""The matchers by name: one interface ``match(ref, obj, initial_guess, params, observer)``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from . import icp, mbicp, pmwn, psm
from .events import Observer
from .params import IcpParams, ImprovedParams, MbicpParams, Params, PmwnParams, PsmParams
from .result import MatchResult
from .scan import Scan
from .se2 import Pose2


@dataclass(frozen=True)
class Matcher:
    name: str
    title: str
    params_type: type
    run: Callable[..., MatchResult]


MATCHERS: dict[str, Matcher] = {
    m.name: m
    for m in (
        Matcher("icp", "ICP (point-to-point, Euclidean)", IcpParams, icp.match),
        Matcher("mbicp", "MbICP (Minguez et al. 2006)", MbicpParams, mbicp.match),
        Matcher("improved", "Improved MbICP (Li et al. 2018)", ImprovedParams, mbicp.match),
        Matcher("psm", "PSM (Diosi & Kleeman 2007)", PsmParams, psm.match),
        Matcher("pmwn", "PMWN (Huo et al. 2016)", PmwnParams, pmwn.match),
    )
}


def matcher_for(params: Params) -> Matcher:
    # exact type: ImprovedParams derives from MbicpParams
    return next(m for m in MATCHERS.values() if type(params) is m.params_type)


def match(ref: Scan, obj: Scan, initial_guess: Pose2 = Pose2(), params: Params | None = None,
          observer: Observer | None = None, algorithm: str = "improved") -> MatchResult:
    """Run the matcher that ``params`` belongs to (or ``algorithm``'s, with its defaults)."""
    m = matcher_for(params) if params is not None else MATCHERS[algorithm]
    return m.run(ref, obj, initial_guess, params if params is not None else m.params_type(), observer)
