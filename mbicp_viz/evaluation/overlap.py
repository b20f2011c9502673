"""``eval overlap``: paper 000's partial-overlap protocol (§3.1) on any log.

For each scene (a real scan), each overlap ratio eta and each run: keep eta of one copy's points
(a contiguous block removed — occlusion-like — or a random subset), see the object copy from a
random displacement (seeded), match from the identity with every chosen matcher, and classify the
result as the paper does (failure: error > 0.1 m or > 3.14 deg): true positive (converged,
correct), false positive (converged, wrong), true negative (not converged, correct), false
negative (not converged, wrong). Tables 1-3 of the paper come out per matcher.

Which copy loses the points: by default the reference, so that 1 - eta of the object's points
have no counterpart — the non-overlap that paper 000's correspondence and rejection steps are for
(§2.3-2.4, Fig. 6 area 1). The paper's own tables need it: its Table 3 gives the improved
algorithm a growing error (1.4 mm at 90 %, 18.6 mm at 60 %), and its Table 1 a standard MbICP that
fails more as eta falls; with the object a subset of the reference, every object point has an exact
counterpart, improved MbICP lands exactly (0 mm) and standard MbICP does not degrade.
``thin="object"`` keeps that variant for comparison.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mbicp_viz.choices import Removal, Thin
from mbicp_viz.core import Params, Pose2, Scan, match, pose_error

from .criteria import PAPER_000
from .pairs import block_mask, displaced_pair
from .pool import ordered_map

CLASSES = ("TP", "FP", "TN", "FN")


@dataclass(frozen=True)
class OverlapCase:
    scene: int  # index into the scenes
    ratio: float  # eta, the kept fraction
    run: int
    removal: str  # a Removal's value
    thin: str  # a Thin's value: the copy that loses the points
    truth: Pose2
    keep: np.ndarray  # bool over the scene's valid points


@dataclass(frozen=True)
class OverlapRow:
    matcher: str
    scene: int
    ratio: float
    run: int
    removal: str
    thin: str
    error_m: float
    error_deg: float
    converged: bool
    iterations: int
    cls: str


def make_cases(
    scenes: list[Scan],
    ratios,
    runs: int,
    removal: Removal | str,
    seed: int,
    max_xy: float,
    max_theta: float,
    thin: Thin | str = Thin.reference,
) -> list[OverlapCase]:
    removal, thin = Removal(removal).value, Thin(thin).value
    rng = np.random.default_rng(seed)
    cases = []
    for s, scan in enumerate(scenes):
        n = scan.n_valid
        for ratio in ratios:
            for r in range(runs):
                truth = Pose2(
                    *rng.uniform([-max_xy, -max_xy, -max_theta], [max_xy, max_xy, max_theta])
                )
                drop = int(round((1.0 - ratio) * n))
                if removal == "block":
                    a = int(rng.integers(0, n - drop + 1))
                    keep = block_mask(n, a / n, (a + drop) / n)
                else:
                    keep = np.ones(n, dtype=bool)
                    keep[rng.choice(n, drop, replace=False)] = False
                cases.append(OverlapCase(s, float(ratio), r, removal, thin, truth, keep))
    return cases


def scene_scans(log, per_log: int, picked: list[int] | None = None) -> list[Scan]:
    """The scenes of one log: the scans numbered ``picked``, else ``per_log`` scans picked
    evenly."""
    if picked:
        return [log.scan(i) for i in picked]
    return [log.scans[int(round(k))] for k in np.linspace(0, len(log.scans) - 1, per_log + 2)[1:-1]]


def classify(converged: bool, correct: bool) -> str:
    return ("TP" if correct else "FP") if converged else ("TN" if correct else "FN")


def case_pair(scan: Scan, case: OverlapCase) -> tuple[Scan, Scan]:
    """(reference, object) of a case; the object is seen from the displacement ``case.truth``."""
    return displaced_pair(scan, case.truth, case.keep, case.thin)


def run_case(args) -> list[OverlapRow]:
    scan, case, params = args
    ref, obj = case_pair(scan, case)
    rows = []
    for name, p in params.items():
        r = match(ref, obj, Pose2(), p)
        et, er = pose_error(r.pose, case.truth)
        rows.append(
            OverlapRow(
                name,
                case.scene,
                case.ratio,
                case.run,
                case.removal,
                case.thin,
                et,
                math.degrees(er),
                r.converged,
                r.iterations,
                classify(r.converged, PAPER_000.correct(et, er)),
            )
        )
    return rows


def run_overlap(
    scenes: list[Scan],
    params: dict[str, Params],
    cases: list[OverlapCase],
    workers: int | None = None,
    on_done=None,
) -> list[OverlapRow]:
    """Every case with every matcher, spread over the machine's cores (standard library process
    pool).

    ``on_done(rows)`` is called as each case finishes (progress); interrupting keeps the rows so
    far.
    """
    rows: list[OverlapRow] = []

    def collect(out: list[OverlapRow]) -> None:
        rows.extend(out)
        if on_done:
            on_done(rows)

    ordered_map(run_case, [(scenes[c.scene], c, params) for c in cases], workers, collect)
    return rows


def tables(rows: list[OverlapRow]) -> dict[str, list[dict]]:
    """Per matcher and ratio: class percentages (Tables 1-2) and mean TP errors (Table 3)."""
    out: dict[str, list[dict]] = {}
    for m in dict.fromkeys(r.matcher for r in rows):
        lines = []
        for ratio in sorted({r.ratio for r in rows}, reverse=True):
            sel = [r for r in rows if r.matcher == m and r.ratio == ratio]
            tp = [r for r in sel if r.cls == "TP"]
            line = {"ratio": ratio, "n": len(sel)}
            line |= {c: 100.0 * sum(r.cls == c for r in sel) / len(sel) for c in CLASSES}
            line["trans_mm"] = (
                1000.0 * float(np.mean([r.error_m for r in tp])) if tp else float("nan")
            )
            line["rot_deg"] = float(np.mean([r.error_deg for r in tp])) if tp else float("nan")
            line["iterations"] = float(np.mean([r.iterations for r in sel]))
            lines.append(line)
        out[m] = lines
    return out


def markdown(tab: dict[str, list[dict]]) -> str:
    head = (
        "| overlap % | n | TP % | FP % | TN % | FN % | TP translation mm | TP rotation deg | "
        "iterations |"
    )
    parts = []
    for m, lines in tab.items():
        parts += [f"**{m}**", "", head, "|" + "---|" * 9]
        for ln in lines:
            parts.append(
                f"| {100 * ln['ratio']:.0f} | {ln['n']} | {ln['TP']:.1f} | {ln['FP']:.1f} | "
                f"{ln['TN']:.1f} | "
                f"{ln['FN']:.1f} | {ln['trans_mm']:.3f} | {ln['rot_deg']:.3f} | "
                f"{ln['iterations']:.1f} |"
            )
        parts.append("")
    return "\n".join(parts)


def csv_text(rows: list[OverlapRow]) -> str:
    fields = list(OverlapRow.__dataclass_fields__)
    out = [",".join(fields)]
    for r in rows:
        out.append(
            ",".join(
                f"{v:.6g}" if isinstance(v, float) else str(v)
                for v in (getattr(r, f) for f in fields)
            )
        )
    return "\n".join(out) + "\n"


def plot_png(tab: dict[str, list[dict]], path: str) -> None:
    from mbicp_viz.pyplot import pyplot, save_png

    plt = pyplot()

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for m, lines in tab.items():
        x = [100 * ln["ratio"] for ln in lines]
        axes[0].plot(x, [ln["TP"] for ln in lines], "o-", label=m)
        axes[1].plot(x, [ln["trans_mm"] for ln in lines], "o-", label=m)
        axes[2].plot(x, [ln["rot_deg"] for ln in lines], "o-", label=m)
    for ax, title in zip(
        axes, ("true positives [%]", "TP translation error [mm]", "TP rotation error [deg]")
    ):
        ax.set_title(title)
        ax.set_xlabel("overlap [%]")
        ax.invert_xaxis()
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.tight_layout()
    save_png(fig, path, 110)
