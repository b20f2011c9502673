"""What a tab shows of its runs: at the current iteration each run's event, scene layers and text;
in Markdown each result with its agreement, the known answer and the odometry, and for a reopened
evaluation row whether this run reproduces it; the session as an .rrd."""

from __future__ import annotations

import math

import numpy as np

from mbicp_viz.core import IterationEvent, Termination, pose_error
from mbicp_viz.core.agreement import INLIER_RADIUS_M
from mbicp_viz.evaluation.failures import failed, failure_kind, failure_reason
from mbicp_viz.evaluation.health import flags_text
from mbicp_viz.evaluation.single import reported
from mbicp_viz.readers.pair_match import PairMatch

from .. import scene, text
from .markdown import literal
from .state import WHY_LAYERS, DebugState


def budget_text(budget_s: float) -> str:
    return f"budget {budget_s:g} s a match" if budget_s else "no time budget"


def result_markdown(state: DebugState) -> str:
    """Every run's result (the robot base's motion when the laser's mount is known), the
    agreement of its pose with the data, and the known answer's."""
    frames, parts = state.source.log.frames, []
    for run in state.runs:
        r = run.result
        lines = [
            f"**{label}** {value}" for label, value in text.result_fields(r, frames.frame_text())
        ]
        if r.reason is Termination.HALTED:
            lines.append(
                f"**halted** {state.halt.why or 'stopped'}: the pose is its last finished "
                "iteration's"
            )
        lines.append(f"**on ref** {text.agreement_line(run.on_ref, INLIER_RADIUS_M)}")
        if run.truth is not None:
            lines.append(
                f"**known answer** {text.truth_line(r.pose, frames.reported(run.truth, True))}"
            )
        if run.odometry is not None:
            lines.append(
                "**odometry** "
                f"{text.pose_distance(r.pose, frames.reported(run.odometry, True))} "
                "from "
                f"the odometry ({state.source.log.odometry_source or 'the log'})"
            )
        parts.append("  \n".join(lines))
    parts.append(
        f"initial guess {state.guess} (laser frame; {state.guess_source}); match time "
        f"{state.match_ms:.1f} ms ({budget_text(state.source.budget_s)})"
    )
    if (row := state.opened) is not None and state.pair == (row.ref, row.obj):
        parts.append(row_markdown(state, row))
    return "\n\n".join(parts)


def row_markdown(state: DebugState, row: PairMatch) -> str:
    """What the evaluation found for this pair, and whether this run reproduces it."""
    loops = state.source.loops
    loop = next((c for c in loops.closures if c.match is row), None) if loops else None
    head = (
        f"**loop candidate** ({loop.verdict.value}; matched from the correlative search's best "
        "peak around the chain's prediction)"
        if loop is not None
        else f"**evaluation** ({literal(state.source.rows_label)}, line {row.line})"
    )
    lines = [
        f"{head}: {row.matcher} gave {row.result.pose} (motion of the {literal(row.frame)} frame)"
    ]
    if (sc := row.score) is not None:
        lines.append(
            f"{sc.error_xy * 1000:.1f} mm, {math.degrees(sc.error_theta):.3f} deg from the "
            "scan poses"
        )
    if row.flags:
        lines.append(f"flagged: {flags_text(row)}")
    if failed(row):
        lines.append(f"failed: {failure_reason(row)}")
        if (why := WHY_LAYERS.get(failure_kind(row))) is not None:
            lines.append(
                "shown: " + ", ".join(s.label for s in why) + " (the Layers panel has the others)"
            )
    run = next((r for r in state.runs if r.matcher == row.matcher), None)
    frames = state.source.log.frames
    if run is None or row.frame not in (frames.frame_name(True), frames.frame_name(False)):
        lines.append(
            f"not comparable with this run (its matcher or its frame differ: this log reads as "
            f"{frames.frame_name(True)})"
        )
    else:
        laser = run.events.finish.result  # the laser's motion, reported as the row was
        et, er = pose_error(
            reported(laser, frames, row.frame == frames.frame_name(True)).pose,
            row.result.pose,
        )
        lines.append(
            "this run reproduces it (the poses agree within 1 nm and 1 nrad)"
            if et < 1e-9 and er < 1e-9
            else f"this run differs from it by {et * 1000:.1f} mm, {math.degrees(er):.3f} deg "
            "(its "
            "parameters, guess or scans changed)"
        )
    return "  \n".join(lines)


def event(state: DebugState, run: PairMatch) -> IterationEvent | None:
    """The run's event at the current iteration (None at the initial guess)."""
    if state.iteration == 0 or not run.iterations:
        return None
    return run.iterations[min(state.iteration, len(run.iterations)) - 1]


def layers(state: DebugState, run: PairMatch) -> list[scene.Layer]:
    """The scene layers of ``run`` at the current iteration; in compare mode each run's object
    scan takes its matcher's colour."""
    return scene.pair_layers(
        state.ref,
        state.obj,
        run.matcher,
        run.start,
        run.iterations,
        state.iteration,
        run.truth,
        run.odometry,
        len(state.runs) > 1,
        state.iso_point,
    )


def iteration_text(state: DebugState, run: PairMatch) -> str:
    ev = event(state, run)
    if ev is None:
        return f"iteration 0: the initial guess ({state.guess_source})"
    return text.iteration_text(ev)


def nearest_object_point(state: DebugState, xy) -> int:
    """The object point (index into the start event's points) nearest to ``xy`` where the first
    run shows it at the current iteration."""
    run = state.runs[0]
    ev = event(state, run)
    moved = (
        ev.moved_points
        if ev is not None
        else run.start.initial_guess.apply(run.start.obj_points[run.start.used])
    )
    return int(run.start.used[int(np.argmin(np.hypot(*(moved - np.asarray(xy)).T)))])


def session_rrd(state: DebugState) -> bytes:
    """The session (data, parameters, all iterations of every shown matcher) as an .rrd."""
    from ..rrd import recorded_bytes  # rerun loads when a session is first exported

    return recorded_bytes(
        state.runs,
        teaching=True,
        recording_id="mbicp-viz/session",
        about="# mbicp-viz "
        f"session\n\n{', '.join(filter(None, (state.source.label, state.pair_label())))}"
        f"; initial guess "
        f"{state.guess} ({state.guess_source})\n",
    )
