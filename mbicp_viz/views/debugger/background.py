"""A run matched in the background while its log is already open in the debugger (``eval sequence
LOG --serve``): every tab can open any pair of the log at once, shows how far the run is (a
progress bar, the pairs done, the rate and the time left), and opens the run view once the run is
matched. The matching side updates a ``Background``; each tab follows it.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

FOLLOW_S = 0.5  # a tab looks at the run's progress this often (not at every pair: 700 a second)


@dataclass
class Background:
    """How far a run is: ``done`` of ``total`` pairs, its pace in words; once matched, the source
    its run view opens (``state.Source`` with the run's rows)."""

    total: int
    done: int = 0
    pace: str = ""
    source: object | None = None
    at_most: bool = False  # ``total`` bounds the pairs: the run finds them as it reads its log

    def update(self, done: int, total: int, at_most: bool, pace: str) -> None:
        self.done, self.total, self.at_most, self.pace = done, total, at_most, pace

    def finish(self, source) -> None:
        self.done, self.source = self.total, source

    def text(self) -> str:
        pace = f" ({self.pace})" if self.pace else ""
        total = f"up to {self.total}" if self.at_most else f"{self.total}"
        return (
            f"matching the run in the background: {self.done} of {total} pairs{pace}; its "
            "run view opens here when it is done, and meanwhile any pair of the log can be opened"
        )


class BackgroundPanel:
    """A tab's view of the run being matched: its progress, until the run view replaces it."""

    def __init__(self, session, gui, order: float, background: Background):
        self.s, self.bg = session, background
        with gui.add_folder("Run", order=order) as self.folder:
            self.bar = gui.add_progress_bar(0.0, animated=True)
            self.text = gui.add_markdown(background.text())
        threading.Thread(target=self._follow, daemon=True).start()

    def _follow(self) -> None:
        """Show the progress as it moves; open the run view when the run is matched."""
        while not self.s.closed.wait(FOLLOW_S):
            if self.bg.source is not None:
                self.folder.remove()
                self.s.guarded(lambda: self.s.open_run(self.bg.source))
                return
            self.bar.value = 100.0 * self.bg.done / max(self.bg.total, 1)
            self.text.content = self.bg.text()
