"""Two configurations on one log (two matchers, or one matcher with two parameter sets): their
runs' rows side by side on the pairs both matched, where they end apart, and which does better —
against the truth where the rows are scored, against the odometry where the log has it, and in any
case how often they disagree.

Where they end apart by more than the consecutive-pair criteria, both rows get the sign "matchers
disagree" (evaluation/health.py), so the run view and the lists show it like any other.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from mbicp_viz.core import pose_error
from mbicp_viz.errors import InputError
from mbicp_viz.readers.pair_match import PairMatch, Suspicion

from .criteria import CONSECUTIVE


@dataclass(frozen=True)
class Versus:
    """Runs A and B on the same pairs, in A's order."""

    a: list[PairMatch]
    b: list[PairMatch]
    name_a: str
    name_b: str

    @property
    def differ(self) -> list[int]:
        """The pairs (indices) where A and B end apart beyond the consecutive-pair criteria."""
        return [k for k, r in enumerate(self.a) if Suspicion.DISAGREE in r.flags]

    def differing(self) -> list[PairMatch]:
        """A's rows where A and B disagree, the farthest apart first."""
        rows = [self.a[k] for k in self.differ]
        return sorted(rows, key=lambda r: -r.flags[Suspicion.DISAGREE][0])

    def verdict(self) -> list[str]:
        """On how many pairs B beats A and A beats B, against what."""
        n, differ = len(self.a), self.differ
        lines = [
            f"{len(differ)} of {n} pairs end more than {CONSECUTIVE.text()} apart "
            f"(A: {self.name_a}; B: {self.name_b})"
        ]
        scored = [(a, b) for a, b in zip(self.a, self.b) if a.score and b.score]
        if scored:
            b_wins = sum(b.score.success and not a.score.success for a, b in scored)
            a_wins = sum(a.score.success and not b.score.success for a, b in scored)
            lines.append(
                f"against the truth: B is right where A is wrong on {b_wins} pairs, A right "
                f"where B is wrong on {a_wins} (of {len(scored)} scored)"
            )
        near = [
            (self.a[k], self.b[k])
            for k in differ
            if self.a[k].odometry_xy is not None and self.b[k].odometry_xy is not None
        ]
        if near:
            b_nearer = sum(b.odometry_xy < a.odometry_xy for a, b in near)
            lines.append(
                f"against the odometry, where they differ: B nearer on {b_nearer} pairs, A on "
                f"{len(near) - b_nearer}"
            )
        return lines


def versus(a: list[PairMatch], b: list[PairMatch], name_a: str, name_b: str) -> Versus:
    """A's and B's rows on the pairs both matched (in A's order), each marked where they
    disagree."""
    if a and b and a[0].frame != b[0].frame:
        raise InputError(
            f"these rows report the {b[0].frame} frame's motion, the first rows the {a[0].frame}'s",
            name_b,
            field="frame",
        )
    by_pair = {(r.ref, r.obj): r for r in b}
    both = [(r, by_pair[(r.ref, r.obj)]) for r in a if (r.ref, r.obj) in by_pair]
    if not both:
        raise InputError("no pair of these rows is in the first rows' run", name_b, field="ref")
    out_a, out_b = [], []
    for ra, rb in both:
        et, er = pose_error(ra.result.pose, rb.result.pose)
        if not CONSECUTIVE.correct(et, er):
            ra = replace(ra, flags=ra.flags | {Suspicion.DISAGREE: (et, er)})
            rb = replace(rb, flags=rb.flags | {Suspicion.DISAGREE: (et, er)})
        out_a.append(ra)
        out_b.append(rb)
    return Versus(out_a, out_b, name_a, name_b)
