"""The matchers by name: one interface ``match(ref, obj, initial_guess, params, observer)``.

A matcher is declared once, here: its name, its parameters' dataclass (fields with units and
bounds, and what its threshold and hard cut are called: ``Params.threshold_label``,
``Params.hard_cut``), the module that runs it, its colour when matchers are compared, and whether
it has a polar cost curve (PSM, PMWN). The front ends ask the declaration. A matcher's module (and
its compiled kernels) is imported when it first runs, so that naming the matchers — command-line
choices, the debugger's dropdown — costs nothing. Another matcher is one ``register`` call (before
the command line is imported: its choices are made then).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from .params import (
    IcpParams,
    ImprovedParams,
    MbicpParams,
    Params,
    PlIcpParams,
    PmwnParams,
    PsmParams,
)

RGB = tuple[int, int, int]


@dataclass(frozen=True)
class Matcher:
    name: str
    title: str
    params_type: type
    module: str  # the module whose ``match`` runs it: of this package, or a full dotted name
    colour: RGB  # its object scan, lines and legend entries when matchers are compared
    polar: bool = False  # it records a cost per shift (PolarStep): the front ends plot it

    def run(self, ref, obj, initial_guess, params, observer=None):
        check_inputs(ref, obj, initial_guess)
        return self.load().match(ref, obj, initial_guess, params, observer)

    def load(self):
        """The matcher's module (importing it defines its kernels; nothing is compiled yet)."""
        if "." in self.module:
            return importlib.import_module(self.module)
        return importlib.import_module(f".{self.module}", __package__)


# A guess farther than this from the reference frame's origin is a damaged number, not a pose.
MAX_GUESS_M = 1e6


def check_inputs(ref, obj, guess) -> None:
    """Refuse, with a ValueError that says why, what no matcher can answer sensibly: a guess that is
    not a finite pose, or a scan whose valid readings are not finite points."""
    import math

    values = (guess.x, guess.y, guess.theta)
    if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
        raise ValueError(f"the initial guess must be finite numbers, got {guess}")
    if max(abs(guess.x), abs(guess.y)) > MAX_GUESS_M:
        raise ValueError(
            f"the initial guess lies {max(abs(guess.x), abs(guess.y)):.3g} m away: more than "
            f"{MAX_GUESS_M:g} m is no pose between two scans"
        )
    for name, scan in (("reference", ref), ("object", obj)):
        if not scan.has_finite_points():
            raise ValueError(f"the {name} scan ({scan.source}) has no finite valid points")


# Compare-mode colours: one per matcher, none of them a colour of the scene's own layers.
MATCHERS: dict[str, Matcher] = {
    m.name: m
    for m in (
        Matcher("icp", "ICP (CSM's, point to segment)", IcpParams, "icp", (230, 159, 0)),
        Matcher("plicp", "PL-ICP (Censi 2008, CSM's)", PlIcpParams, "icp", (120, 80, 30)),
        Matcher("mbicp", "MbICP (Minguez et al. 2006)", MbicpParams, "mbicp", (0, 114, 178)),
        Matcher(
            "improved", "Improved MbICP (Li et al. 2018)", ImprovedParams, "mbicp", (204, 80, 170)
        ),
        Matcher("psm", "PSM (Diosi & Kleeman 2007)", PsmParams, "psm", (0, 158, 115), True),
        Matcher("pmwn", "PMWN (Huo et al. 2016)", PmwnParams, "pmwn", (86, 180, 233), True),
    )
}


def register(matcher: Matcher) -> None:
    """Add a matcher (a name not taken, a parameters type of its own)."""
    if matcher.name in MATCHERS:
        raise ValueError(f"a matcher named {matcher.name!r} exists already")
    if any(m.params_type is matcher.params_type for m in MATCHERS.values()):
        raise ValueError(f"{matcher.params_type.__name__} is another matcher's parameters")
    MATCHERS[matcher.name] = matcher


def matcher_for(params: Params) -> Matcher:
    # exact type: ImprovedParams derives from MbicpParams
    return next(m for m in MATCHERS.values() if type(params) is m.params_type)


def match(
    ref,
    obj,
    initial_guess=None,
    params: Params | None = None,
    observer=None,
    algorithm: str = "improved",
):
    """Run the matcher that ``params`` belongs to (or ``algorithm``'s, with its defaults): the
    ``MatchResult`` whose pose maps object-frame points into the reference frame."""
    from .se2 import Pose2

    m = matcher_for(params) if params is not None else MATCHERS[algorithm]
    return m.run(
        ref,
        obj,
        initial_guess if initial_guess is not None else Pose2(),
        params if params is not None else m.params_type(),
        observer,
    )
