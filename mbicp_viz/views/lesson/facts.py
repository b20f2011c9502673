"""The numbers a lesson step's text may quote, computed from the step's own runs and data.

A text names them as ``{group.name:format}`` (``{improved.error_mm:.1f}``); ``render`` fills them
in, and a name that is not there is an error naming the step's file. Only dictionary keys are
looked up (no attributes, no indexing): a text cannot reach into the program.
"""

from __future__ import annotations

import math
import string

import numpy as np

from mbicp_viz.core import IterationEvent, PairKind, PairStatus, Pose2, Scan, pose_error
from mbicp_viz.core.metric import mad_threshold
from mbicp_viz.core.tiers import run
from mbicp_viz.errors import InputError
from mbicp_viz.readers.pair_match import PairMatch

Facts = dict[str, dict[str, object]]


def scan_facts(scan: Scan) -> dict[str, object]:
    """A laser scan as the sensor reports it: beams, valid and invalid readings, field of view,
    angular step and the ranges of its valid readings."""
    r = scan.ranges[scan.valid]
    return {
        "beams": len(scan.ranges),
        "valid": scan.n_valid,
        "invalid": len(scan.ranges) - scan.n_valid,
        "fov_deg": math.degrees(scan.angular_span()),
        "step_deg": math.degrees(scan.angular_span() / max(len(scan.ranges) - 1, 1)),
        "nearest_m": float(r.min()),
        "farthest_m": float(r.max()),
        "median_m": float(np.median(r)),
    }


def pose_facts(pose: Pose2) -> dict[str, object]:
    """A pose (the guess, the known answer): x, y, heading, and how far it is from the origin."""
    return {
        "x_m": pose.x,
        "y_m": pose.y,
        "theta_deg": math.degrees(pose.theta),
        "distance_m": math.hypot(pose.x, pose.y),
    }


def iteration_facts(ev: IterationEvent) -> dict[str, object]:
    """One iteration's pairs by kind and status, its threshold and its step."""
    p = ev.pairs
    kept = p.count(status=PairStatus.KEPT)
    return {
        "number": ev.iteration,
        "pairs": len(p.kind),
        "point": p.count(kind=PairKind.POINT),
        "interpolated": p.count(kind=PairKind.INTERPOLATED),
        "kept": kept,
        "rejected": len(p.kind) - kept,
        "threshold_m": ev.threshold if ev.threshold is not None else float("nan"),
        "median_m": float(np.median(p.distance)) if len(p.distance) else float("nan"),
        "step_mm": 1000.0 * math.hypot(ev.increment.x, ev.increment.y),
        "step_deg": math.degrees(ev.increment.theta),
    }


def run_facts(run: PairMatch, truth: Pose2 | None, shown: int) -> dict[str, object]:
    """A matcher's run: its result, its error against the known answer, its first, last and shown
    iterations (``first.kept``, ``last.threshold_m``, ``shown.interpolated`` ...), its resampling
    grid and its degeneracy indicator when it has them."""
    r = run.result
    out: dict[str, object] = {
        "iterations": r.iterations,
        "status": "converged" if r.converged else f"stopped ({r.reason.value})",
        "kept": r.pairs_kept,
        "rejected": r.pairs_rejected,
        "x_m": r.pose.x,
        "y_m": r.pose.y,
        "theta_deg": math.degrees(r.pose.theta),
    }
    if truth is not None:
        et, er = pose_error(r.pose, truth)
        out |= {"error_mm": 1000.0 * et, "error_deg": math.degrees(er)}
    if run.iterations:
        out |= {
            "first": iteration_facts(run.iterations[0]),
            "last": iteration_facts(run.iterations[-1]),
            "shown": iteration_facts(run.iterations[min(max(shown, 1), len(run.iterations)) - 1]),
        }
        polar = run.iterations[-1].polar
        if polar is not None and polar.metric_weight is not None:
            out["metric_weight"] = polar.metric_weight
    if r.degeneracy is not None:
        out |= {
            "condition": r.degeneracy.condition_number,
            "weakest_deg": r.degeneracy.weakest_heading_deg,
        }
    rs = run.start.resampling
    if rs is not None:
        out["grid"] = {
            "cells": len(rs.cells),
            "before": int(rs.count.sum()),
            "after": int(rs.kept_count.sum()),
            "thinned_cells": int(np.count_nonzero(rs.kept_count < rs.count)),
            "cell_m": rs.cell_size,
        }
    return out


def metric_facts(scan: Scan, L: float, L_try: float | None) -> dict[str, object]:
    """How MbICP's metric bends at the scan's median range r: its iso-distance ellipse is
    sqrt(r^2 + L^2) / L times as wide across the ray as along it (paper 000 Fig. 3)."""
    r = float(np.median(scan.ranges[scan.valid]))
    out: dict[str, object] = {"L_m": L, "range_m": r, "ratio": math.sqrt(r * r + L * L) / L}
    if L_try is not None:
        out |= {"L_try_m": L_try, "ratio_try": math.sqrt(r * r + L_try * L_try) / L_try}
    return out


def _listed(values) -> str:
    """Values as a text quotes them: largest first, as written (``%g``)."""
    return ", ".join(f"{x:g}" for x in sorted(values, reverse=True))


def distance_facts(d: np.ndarray, k: float) -> dict[str, object]:
    """Paper 000 §2.4.2's rejection rules on a list of distances: median + k MAD (eq. 5) against
    mean + 2 standard deviations."""
    thr = run(mad_threshold, d, k)
    median = float(np.median(d))
    sigma = float(d.mean() + 2.0 * d.std())
    return {
        "n": len(d),
        "median": median,
        "mad": float(np.median(np.abs(d - median))),
        "k": k,
        "threshold": thr,
        "rejected": int(np.count_nonzero(d > thr)),
        "rejected_values": _listed(d[d > thr]),
        "mean": float(d.mean()),
        "sigma_threshold": sigma,
        "sigma_rejected": int(np.count_nonzero(d > sigma)),
        "sigma_rejected_values": _listed(d[d > sigma]),
    }


class _Lookup(string.Formatter):
    """``str.format`` restricted to nested dictionary keys."""

    def get_field(self, field_name, args, kwargs):
        value = kwargs
        for part in field_name.split("."):
            if not isinstance(value, dict) or part not in value:
                raise KeyError(field_name)
            value = value[part]
        return value, field_name


def names(facts: Facts, prefix: str = "") -> list[str]:
    """Every name a text can quote."""
    out = []
    for key, value in facts.items():
        out += names(value, f"{prefix}{key}.") if isinstance(value, dict) else [f"{prefix}{key}"]
    return out


def render(template: str, facts: Facts, path: str, field: str) -> str:
    """``template`` with its ``{names}`` filled in from ``facts``; an unknown name or a bad format
    is an error naming the file and field."""
    try:
        return _Lookup().vformat(template, (), facts)
    except KeyError as e:
        raise InputError(
            f"no number called {{{e.args[0]}}} in this step; it has: {', '.join(names(facts))}",
            path,
            field=field,
        ) from None
    except (ValueError, IndexError, TypeError) as e:
        raise InputError(f"cannot format: {e}", path, field=field) from None
