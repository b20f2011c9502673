"""A run's loop closures in the debugger (``serve LOG --rows R --close-loops``, issue 36).

Every candidate is listed with what became of it. The one picked opens in the pair debugger as it
was matched (from the correlative search's best peak), beside the search's response over rotation
(the peak the match started from, the highest one 10 degrees or more away, the line above which the
surface is ambiguous) and what the closure does to the run: how far taking it out (or forcing it
in) moves the scans, and the relation score with and without it where the log has relations.
"accept / reject this closure" solves the pose graph again with the hand's decisions
(``LoopRun.decided``) and the run view redraws. Each tab keeps its own decisions.
"""

from __future__ import annotations

import math

import numpy as np
import viser.uplot as uplot

from mbicp_viz.evaluation.loops import Closure, LoopRun

from .. import scene
from . import panels

NONE = "(pick a candidate)"


def response_series(c: Closure, ambiguous_from: float, apart: float) -> tuple[np.ndarray, ...]:
    """A candidate's correlative response: each rotation of the motion [deg] and its best score
    over the best, vertical lines at the best peak and at the second (the highest ``apart`` or
    more from it; none when the window holds no such rotation), the ambiguity line."""
    s = c.search
    x = np.degrees(c.guess.theta + s.angles)
    y = s.best_per_angle / max(float(s.best_per_angle.max()), 1e-12)
    best = int(np.argmax(y))
    far = np.flatnonzero(np.abs(s.angles - s.angles[best]) >= apart)
    second = float(x[far[np.argmax(y[far])]]) if len(far) else None
    xs, curve, *marks = panels.with_marks(x, y, [float(x[best]), second])
    return (xs, curve, *marks, np.full(len(xs), ambiguous_from))


class LoopPanel:
    """The candidates, the one picked, its response and the buttons that decide it."""

    def __init__(self, session, gui, order: float, loops: LoopRun):
        self.s, self.original, self.current = session, loops, loops
        self.by_hand: dict[int, bool] = {}  # positions in loops.closures -> accepted by hand
        p = loops.params
        with gui.add_folder("Loop closures", order=order):
            self.summary = gui.add_markdown("")
            self.pick = gui.add_dropdown("open candidate", [NONE], initial_value=NONE)
            self.details = gui.add_markdown("")
            self.accept = gui.add_button("accept this closure", visible=False)
            self.reject = gui.add_button("reject this closure", visible=False)
            self.judged = gui.add_button(
                "as its match judged it", visible=False, hint="undo this closure's hand decision"
            )
            ratio = f"{100 * p.peak_ratio:.0f} %"
            apart = f"{math.degrees(p.peak_apart):.0f}°"
            self.plot = gui.add_uplot(
                data=(np.zeros(1),) * 5,
                series=(
                    uplot.Series(label="rotation [deg]"),
                    panels._line(scene.RESPONSE.label, "r", scene.RESPONSE),
                    panels._line(scene.CHOSEN_PEAK.label, "r", scene.CHOSEN_PEAK),
                    panels._line(
                        f"{scene.SECOND_PEAK.label} ({apart} or more away)", "r", scene.SECOND_PEAK
                    ),
                    panels._line(
                        f"{scene.AMBIGUOUS_FROM.label} ({ratio})",
                        "r",
                        scene.AMBIGUOUS_FROM,
                        dash=True,
                    ),
                ),
                aspect=1.6,
                title="correlative search: response over rotation",
                visible=False,
                **panels._numeric("rotation [deg]", ("r", "score / best", 3, 1.05)),
            )
        self.labels: dict[str, int] = {}
        self.picked = NONE
        self.show_list()
        self.pick.on_update(lambda _: session.guarded(self._picked))
        self.accept.on_click(lambda _: session.guarded(lambda: self.decide(True)))
        self.reject.on_click(lambda _: session.guarded(lambda: self.decide(False)))
        self.judged.on_click(lambda _: session.guarded(lambda: self.decide(None)))

    @property
    def k(self) -> int | None:
        """The candidate picked (a position in the run's closures)."""
        return self.labels.get(self.picked)

    def show_list(self) -> None:
        """The summary and the list, each candidate with its verdict as it stands."""
        closures, k = self.current.closures, self.k
        self.summary.content = "  \n".join(self.current.summary()) + (
            f"  \n{len(self.by_hand)} decided by hand" if self.by_hand else ""
        )
        self.labels = {
            f"{k + 1}. scans {c.old} -> {c.key}: {c.says()}": k for k, c in enumerate(closures)
        }
        label = next((lb for lb, j in self.labels.items() if j == k), NONE)
        # a value set here runs the list's callback at once: one it already holds opens nothing.
        # The list goes through NONE (in the old options and the new), or the page, finding its
        # value gone from the new options, would send back its first
        self.picked = self.pick.value = NONE
        self.pick.options = (NONE, *self.labels)
        self.picked = self.pick.value = label

    def _picked(self) -> None:
        # a list opened and closed again sends its value unchanged: that opens nothing
        if self.pick.value == self.picked:
            return
        self.picked = self.pick.value
        if self.k is None:
            self.show_closure()
            return
        self.s.open_row(self.current.closures[self.k].match)
        self.show_closure()

    def decide(self, accepted: bool | None) -> None:
        """The picked closure accepted or rejected by hand (None: as its match judged it), the
        pose graph solved again, the run and the list shown anew."""
        if self.k is None:
            return
        if accepted is None:
            self.by_hand.pop(self.k, None)
        else:
            self.by_hand[self.k] = accepted
        self.current = self.original.decided(self.by_hand)
        self.s.set_loops(self.current)
        self.show_list()
        self.show_closure()

    def show_closure(self) -> None:
        """The picked candidate: how it was judged, its response, what it does to the run."""
        k = self.k
        for handle in (self.accept, self.reject, self.judged):
            handle.visible = k is not None
        self.plot.visible = k is not None and self.current.closures[k].search is not None
        if k is None:
            self.details.content = ""
            return
        c, p = self.current.closures[k], self.current.params
        self.accept.disabled = c.accepted
        self.reject.disabled = not c.accepted
        self.judged.disabled = not c.by_hand
        m = c.match
        lines = [
            f"**candidate {k + 1}**: scan {c.key} seen again from scan {c.old}: **{c.says()}**",
            f"second peak {100 * c.peak_ratio:.0f} % of the best (ambiguous from "
            f"{100 * p.peak_ratio:.0f} %)",
        ]
        if m.overlap is not None:
            lines.append(
                f"{100 * m.overlap:.0f} % of its points on the old scan's surface (at least "
                f"{100 * p.min_overlap:.0f} %)"
            )
        lines.append(f"{m.result.iterations} iterations, {m.result.reason.value}")
        lines.append(self.effect(k))
        self.details.content = "  \n".join(lines)
        if self.plot.visible:
            self.plot.data = response_series(c, p.peak_ratio, p.peak_apart)

    def effect(self, k: int) -> str:
        """What closure k does to the run: the graph solved without it (or with it forced in)."""
        c = self.current.closures[k]
        other = self.original.decided({**self.by_hand, k: not c.accepted})
        moved = other.moved(self.current)
        what = "taking it out" if c.accepted else "forcing it in"
        text = (
            f"**what it does**: {what} moves the scans up to {moved.max():.3f} m (median "
            f"{np.median(moved):.3f} m; the pose graph solved in "
            f"{1000 * other.optimise_s[-1]:.0f} ms)"
        )
        score = self.s.loop_score
        with_it, without = (self.current, other) if c.accepted else (other, self.current)
        a, b = score(with_it), score(without)
        if a is not None:
            text += f"; relation score with it {a:.3f} m, without it {b:.3f} m"
        return text
