"""``mbicp-viz record``: regenerate the curated ``.rrd`` recordings from ``recordings/scenarios``."""

from __future__ import annotations

import math
from pathlib import Path

from core import pose_error

from .rrd import Run, record
from .scenarios import RECORDINGS, Scenario, load_scenario, scenario_paths


def scenario_runs(s: Scenario) -> list[Run]:
    return [Run(name, s.ref, s.obj, s.guess, p, s.truth) for name, p in s.params.items()]


def about(s: Scenario) -> str:
    return f"# {s.title}\n\n{s.note.strip()}\n"


def record_scenario(s: Scenario, out: Path) -> list[str]:
    """Write ``out`` for one scenario; one summary line per matcher."""
    results = record(scenario_runs(s), str(out), teaching=s.teaching, recording_id=f"mbicp-viz/{s.name}",
                     about=about(s))
    lines = []
    for name, r in zip(s.params, results):
        line = f"{name}: {r.pose}, {'converged' if r.converged else r.reason.value}, {r.iterations} iterations"
        if s.truth is not None:
            et, er = pose_error(r.pose, s.truth)
            line += f"; error {et * 1000:.1f} mm, {math.degrees(er):.2f} deg"
        lines.append(line)
    return lines


def record_all(names: list[str] | None = None, directory: Path = RECORDINGS, out_dir: Path | None = None):
    """Yield (scenario, output path, summary lines) for every (or every named) scenario."""
    paths = scenario_paths(directory)
    if names:
        known = {p.stem: p for p in paths}
        from .errors import InputError

        for n in names:
            if n not in known:
                raise InputError(f"unknown scenario {n!r}; known: {', '.join(known)}", field="NAME")
        paths = [known[n] for n in names]
    for p in paths:
        s = load_scenario(p)
        out = (out_dir or directory) / f"{s.name}.rrd"
        yield s, out, record_scenario(s, out)
