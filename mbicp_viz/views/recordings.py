"""``mbicp-viz record``: regenerate the curated ``.rrd`` recordings from the scenarios."""

from __future__ import annotations

from pathlib import Path

from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.scenarios import (
    Scenario,
    find_scenario,
    is_checkout,
    load_scenario,
    recordings_dir,
    scenario_paths,
)

from .rrd import record
from .text import truth_line


def about(s: Scenario) -> str:
    return f"# {s.title}\n\n{s.note.strip()}\n"


def record_scenario(s: Scenario, out: Path) -> list[str]:
    """Write ``out`` for one scenario; one summary line per matcher."""
    matches = s.matches()
    record(
        matches, str(out), teaching=s.teaching, recording_id=f"mbicp-viz/{s.name}", about=about(s)
    )
    lines = []
    for name, r in zip(s.params, (m.result for m in matches)):
        line = (
            f"{name}: {r.pose}, {'converged' if r.converged else r.reason.value}, "
            f"{r.iterations} iterations"
        )
        if s.truth is not None:
            line += f"; {truth_line(r.pose, s.truth)}"
        lines.append(line)
    return lines


def default_out_dir() -> Path:
    """Where ``record`` writes without ``--out-dir``: beside the scenarios in a checkout; an
    installed package's data is no place to write, so there the user must say where."""
    directory = recordings_dir()
    if not is_checkout(directory):
        raise InputError(
            "the scenarios are installed package data: say where to write with --out-dir DIR",
            field="--out-dir",
        )
    return directory


def record_all(names: list[str] | None = None, out_dir: Path | None = None):
    """Yield (scenario, output path, summary lines) for every (or every named) scenario."""
    out_dir = out_dir or default_out_dir()
    scenarios = (
        [find_scenario(n) for n in names] if names else [load_scenario(p) for p in scenario_paths()]
    )
    if not scenarios:
        raise InputError(f"no scenario files in {recordings_dir() / 'scenarios'}", field="NAME")
    for s in scenarios:
        out = out_dir / f"{s.name}.rrd"
        yield s, out, record_scenario(s, out)
