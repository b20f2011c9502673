"""A match in words: the one place that writes iterations and results as text, for the terminal,
the debugger's panels and rerun's text log alike."""

from __future__ import annotations

import math

from mbicp_viz.core import IterationEvent, MatchResult, PairKind, PairStatus, Pose2, pose_error
from mbicp_viz.readers.pair_match import PairMatch


def result_fields(r: MatchResult, frame: str = "the laser frame") -> list[tuple[str, str]]:
    """(label, value) of everything a result says, in the order a debugging user asks; ``frame``
    names the frame whose motion the pose is."""
    fields = [
        ("algorithm", r.algorithm),
        (
            "pose",
            f"{r.pose}   (motion of {frame}: its pose at the object scan, in its frame at the "
            "reference scan)",
        ),
        (
            "status",
            f"{'converged' if r.converged else 'NOT converged: ' + r.reason.value} after "
            f"{r.iterations} "
            "iterations",
        ),
        (
            "error",
            f"{r.error:.3e} m^2 mean squared residual; pairs kept {r.pairs_kept}, rejected "
            f"{r.pairs_rejected}",
        ),
    ]
    if r.covariance is not None:
        sx, sy, st = (math.sqrt(max(r.covariance[i, i], 0.0)) for i in range(3))
        fields.append(
            (
                "1-sigma",
                f"x {sx * 1000:.2f} mm, y {sy * 1000:.2f} mm, theta {math.degrees(st):.3f} deg",
            )
        )
    if r.degeneracy is not None:
        d = r.degeneracy
        fields.append(
            (
                "degeneracy",
                f"condition number {d.condition_number:.1f}; weakest direction "
                f"(x, y, L*theta) = ({d.weakest_direction[0]:+.2f}, "
                f"{d.weakest_direction[1]:+.2f}, {d.weakest_direction[2]:+.2f}), heading "
                f"{d.weakest_heading_deg:+.0f} deg",
            )
        )
    return fields


def result_lines(r: MatchResult, frame: str = "the laser frame") -> list[str]:
    """The result as the terminal prints it: one labelled line per field."""
    return [f"{label:<11} {value}" for label, value in result_fields(r, frame)]


def result_sentence(r: MatchResult) -> str:
    """The result as one line (rerun's text log, the debugger's compare summary)."""
    text = (
        f"{r.algorithm}: "
        f"{'converged' if r.converged else 'NOT converged (' + r.reason.value + ')'} after "
        f"{r.iterations} iterations; pose {r.pose}; error {r.error:.3e} m^2; "
        f"pairs kept {r.pairs_kept}, rejected {r.pairs_rejected}"
    )
    if r.degeneracy is not None:
        text += (
            f"; condition number {r.degeneracy.condition_number:.1f}, weakest direction heading "
            f"{r.degeneracy.weakest_heading_deg:+.0f} deg"
        )
    return text


def agreement_line(on_ref: float, radius_m: float) -> str:
    return (
        f"{100 * on_ref:.1f} % of the object points lie within {100 * radius_m:.0f} cm of a "
        "reference point"
    )


def pose_distance(pose: Pose2, other: Pose2) -> str:
    et, er = pose_error(pose, other)
    return f"{et * 1000:.1f} mm, {math.degrees(er):.3f} deg"


def truth_line(pose: Pose2, truth: Pose2) -> str:
    return f"{pose_distance(pose, truth)} from the known answer"


ITERATION_HEADER = (
    f"{'it':>3} {'pairs':>5} {'interp':>6} {'kept':>5} {'rejected':>8} {'threshold_m':>11} "
    f"{'error_m2':>10} {'dx_m':>9} {'dy_m':>9} {'dtheta_deg':>10}"
)


def iteration_line(e: IterationEvent) -> str:
    """One row under ``ITERATION_HEADER``."""
    p = e.pairs
    thr = f"{e.threshold:.4f}" if e.threshold is not None else "-"
    n = len(p.kind)
    kept = p.count(status=PairStatus.KEPT)
    return (
        f"{e.iteration:>3} {n:>5} {p.count(kind=PairKind.INTERPOLATED):>6} {kept:>5} {n - kept:>8} "
        f"{thr:>11} "
        f"{e.error:>10.3e} {e.increment.x:>+9.4f} {e.increment.y:>+9.4f} "
        f"{math.degrees(e.increment.theta):>+10.4f}"
        + (f"  extrapolated x{1.0 + e.extrapolated:.2f}" if e.extrapolated else "")
    )


def iteration_text(ev: IterationEvent) -> str:
    """One iteration as a sentence (rerun's text log, the debugger's playback panel)."""
    p = ev.pairs
    n_kept = p.count(status=PairStatus.KEPT)
    by = {s.name.lower(): p.count(status=s) for s in PairStatus if s != PairStatus.KEPT}
    rej = ", ".join(f"{v} {k}" for k, v in by.items() if v) or "none"
    thr = f"{ev.threshold:.3f} m" if ev.threshold is not None else "-"
    return (
        f"iteration {ev.iteration}: {len(p.kind)} pairs ({p.count(kind=PairKind.INTERPOLATED)} "
        "interpolated), "
        f"{n_kept} kept, rejected: {rej}; threshold {thr}; error {ev.error:.3e} m^2; "
        f"step ({ev.increment.x:+.4f} m, {ev.increment.y:+.4f} m, "
        f"{math.degrees(ev.increment.theta):+.3f} deg)"
        + (
            f"; held along heading {ev.held.heading_deg:+.0f} deg (surface condition number "
            f"{ev.held.condition_number:.0f}): the step left the guess's value there"
            if ev.held
            else ""
        )
        + (
            "; extrapolated (Aitken): MbICP's own step was shorter than the one before and within "
            "90 deg of it, "
            f"so the step went on to {1.0 + ev.extrapolated:.2f} times its length"
            if ev.extrapolated
            else ""
        )
        + (f"; {ev.note}" if ev.note else "")
    )


def match_report(label: str, m: PairMatch, frame: str, truth: Pose2 | None) -> list[str]:
    """``match``'s report: the pair, the guess (laser frame, as the iterations) and where it came
    from, one line per iteration, the result as reported (``m.result`` in ``frame``), the
    agreement with the data and, when known, the error against the answer (``truth``, in the same
    frame)."""
    from mbicp_viz.core.agreement import INLIER_RADIUS_M

    lines = [
        label,
        f"initial guess {m.guess} (laser frame; from: {m.guess_source})",
        "",
        ITERATION_HEADER,
    ]
    lines += [iteration_line(e) for e in m.iterations]
    lines += [
        "",
        *result_lines(m.result, frame),
        f"{'on ref':<11} {agreement_line(m.on_ref, INLIER_RADIUS_M)}",
    ]
    if truth is not None:
        lines.append(f"{'truth':<11} {truth_line(m.result.pose, truth)} ({m.truth_source})")
    how = "; interpreted while numba compiled the kernels" if m.interpreted else ""
    lines.append(f"{'time':<11} {m.time_ms:.1f} ms (with the recording observer{how})")
    return lines
