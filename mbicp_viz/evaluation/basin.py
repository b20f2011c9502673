"""``eval basin``: a convergence atlas — which initial guesses lead each matcher to the answer.

A grid of initial offsets (x, y, theta) around the reference answer; every grid point is matched
by every chosen matcher and coloured by outcome: correct (within ``CONSECUTIVE``'s tolerances of
the answer), converged wrong, or not converged. The reference answer is ``--truth`` when given, else
the relative pose of the scans' stored poses, else each matcher's own answer from the zero offset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mbicp_viz.core import Params, Pose2, Scan, match
from mbicp_viz.errors import InputError

from .criteria import CONSECUTIVE
from .pool import ordered_map

CORRECT, WRONG, NOT_CONVERGED = 0, 1, 2
OUTCOME_NAMES = ("correct", "converged wrong", "not converged")
OUTCOME_COLORS = ((40, 160, 70), (220, 40, 40), (160, 160, 160))


@dataclass(frozen=True)
class Atlas:
    offsets_xy: np.ndarray  # (G,) offsets along x and y [m]
    thetas: np.ndarray  # (T,) theta offsets [rad]
    answers: dict[str, Pose2]  # per matcher, the answer outcomes are judged against
    outcome: dict[str, np.ndarray]  # per matcher, (T, G, G) indexed [theta, y, x]


def _run(args):
    ref, obj, guesses, params, answer = args
    out = []
    for g in guesses:
        r = match(ref, obj, g, params)
        ok = CONSECUTIVE.judge(r.pose, answer)
        out.append(CORRECT if ok and r.converged else (WRONG if r.converged else NOT_CONVERGED))
    return out


def basin(
    ref: Scan,
    obj: Scan,
    params: dict[str, Params],
    truth: Pose2 | None,
    range_xy: float,
    steps: int,
    thetas_rad: list[float],
    workers: int | None = None,
) -> Atlas:
    xy = np.linspace(-range_xy, range_xy, steps)
    answers = {}
    for name, p in params.items():
        answers[name] = truth if truth is not None else match(ref, obj, Pose2(), p).pose
    jobs = [
        (ref, obj, [Pose2(a.x + dx, a.y + dy, a.theta + th) for dx in xy], p, a)
        for name, p in params.items()
        for a in [answers[name]]
        for th in thetas_rad
        for dy in xy
    ]
    rows = ordered_map(_run, jobs, workers)
    if len(rows) < len(jobs):
        raise InputError(
            f"interrupted after {len(rows)} of {len(jobs)} rows of the atlas; nothing was written"
        )
    per = len(thetas_rad) * steps
    outcome = {
        name: np.array(rows[k * per : (k + 1) * per], dtype=np.int8).reshape(
            len(thetas_rad), steps, steps
        )
        for k, name in enumerate(params)
    }
    return Atlas(xy, np.array(thetas_rad), answers, outcome)


def plot_png(atlas: Atlas, path: str) -> None:
    from matplotlib.colors import ListedColormap

    from mbicp_viz.pyplot import pyplot, save_png

    plt = pyplot()

    names = list(atlas.outcome)
    T = len(atlas.thetas)
    fig, axes = plt.subplots(
        len(names), T, figsize=(2.4 * T + 1, 2.4 * len(names) + 0.6), squeeze=False
    )
    cmap = ListedColormap(np.array(OUTCOME_COLORS) / 255.0)
    ext = [atlas.offsets_xy[0], atlas.offsets_xy[-1]] * 2
    for i, name in enumerate(names):
        for t in range(T):
            ax = axes[i, t]
            ax.imshow(atlas.outcome[name][t], origin="lower", extent=ext, cmap=cmap, vmin=0, vmax=2)
            ax.set_title(f"{name}, dtheta {math.degrees(atlas.thetas[t]):+.0f} deg", fontsize=8)
            ax.set_xlabel("dx [m]", fontsize=7)
            ax.set_ylabel("dy [m]", fontsize=7)
            ax.tick_params(labelsize=6)
    handles = [plt.Rectangle((0, 0), 1, 1, color=np.array(c) / 255.0) for c in OUTCOME_COLORS]
    fig.legend(handles, OUTCOME_NAMES, loc="lower center", ncol=3, fontsize=8)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    save_png(fig, path, 110)


def summary(atlas: Atlas) -> str:
    lines = []
    for n, o in atlas.outcome.items():
        parts = [
            f"{math.degrees(th):+.0f} deg: {np.mean(o[t] == CORRECT) * 100:.0f} %"
            for t, th in enumerate(atlas.thetas)
        ]
        lines.append(
            f"{n:<9} correct from {np.mean(o == CORRECT) * 100:5.1f} % of the grid "
            f"({', '.join(parts)})"
        )
    return "\n".join(lines)
