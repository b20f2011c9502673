"""The guided lesson: every step runs, its numbers are the step's own (recomputed here apart from
the lesson's code), its picture shows what its text says, and it exports as a handout and an .rrd
that rerun's viewer renders."""

import json
import math
import re
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from rerun.chunk import RrdReader

from mbicp_viz.core import PairKind, PairStatus, Recorder, match, pose_error
from mbicp_viz.errors import InputError
from mbicp_viz.views import scene
from mbicp_viz.views.lesson.steps import load_lesson, run_step, step_paths
from mbicp_viz.views.rrd import BACKGROUND

from .conftest import rerun_viewer, settled_screenshot, wait_for


@pytest.fixture(scope="module")
def lesson():
    return [run_step(s) for s in load_lesson()]


# ---- the numbers, recomputed without lesson/facts.py ------------------------------------------


def _ns(d):
    return SimpleNamespace(**{k: _ns(v) if isinstance(v, dict) else v for k, v in d.items()})


def _scan(scan):
    r = scan.ranges[scan.valid]
    span = float(scan.bearings[-1] - scan.bearings[0])
    return {
        "beams": scan.ranges.size,
        "valid": int(scan.valid.sum()),
        "invalid": int((~scan.valid).sum()),
        "fov_deg": math.degrees(span),
        "step_deg": math.degrees(span / (scan.ranges.size - 1)),
        "nearest_m": r.min(),
        "farthest_m": r.max(),
        "median_m": np.median(r),
    }


def _iteration(ev):
    p = ev.pairs
    kept = int(np.sum(p.status == PairStatus.KEPT))
    return {
        "number": ev.iteration,
        "pairs": len(p.status),
        "point": int(np.sum(p.kind == PairKind.POINT)),
        "interpolated": int(np.sum(p.kind == PairKind.INTERPOLATED)),
        "kept": kept,
        "rejected": len(p.status) - kept,
        "threshold_m": ev.threshold if ev.threshold is not None else math.nan,
        "median_m": np.median(p.distance),
        "step_mm": 1000 * math.hypot(ev.increment.x, ev.increment.y),
        "step_deg": math.degrees(ev.increment.theta),
    }


def _run(ref, obj, guess, params, truth, shown):
    rec = Recorder()
    r = match(ref, obj, guess, params, rec)
    its = rec.iterations
    out = {
        "iterations": r.iterations,
        "status": "converged" if r.converged else f"stopped ({r.reason.value})",
        "kept": r.pairs_kept,
        "rejected": r.pairs_rejected,
        "x_m": r.pose.x,
        "y_m": r.pose.y,
        "theta_deg": math.degrees(r.pose.theta),
        "first": _iteration(its[0]),
        "last": _iteration(its[-1]),
        "shown": _iteration(its[min(max(shown or len(its), 1), len(its)) - 1]),
    }
    if truth is not None:
        et, er = pose_error(r.pose, truth)
        out |= {"error_mm": 1000 * et, "error_deg": math.degrees(er)}
    if its[-1].polar is not None and its[-1].polar.metric_weight is not None:
        out["metric_weight"] = its[-1].polar.metric_weight
    if r.degeneracy is not None:
        out |= {
            "condition": r.degeneracy.condition_number,
            "weakest_deg": r.degeneracy.weakest_heading_deg,
        }
    rs = rec.start.resampling
    if rs is not None:
        out["grid"] = {
            "cells": len(rs.cells),
            "before": int(rs.count.sum()),
            "after": int(rs.kept_count.sum()),
            "thinned_cells": int(np.sum(rs.kept_count < rs.count)),
            "cell_m": rs.cell_size,
        }
    return out


def _distances(d, k):
    med = np.median(d)
    mad = np.median(np.abs(d - med))
    thr, sigma = med + k * mad, d.mean() + 2 * d.std()
    listed = lambda v: ", ".join(f"{x:g}" for x in sorted(v, reverse=True))  # noqa: E731
    return {
        "n": len(d),
        "median": med,
        "mad": mad,
        "k": k,
        "threshold": thr,
        "rejected": int(np.sum(d > thr)),
        "rejected_values": listed(d[d > thr]),
        "mean": d.mean(),
        "sigma_threshold": sigma,
        "sigma_rejected": int(np.sum(d > sigma)),
        "sigma_rejected_values": listed(d[d > sigma]),
    }


def recomputed(step):
    s = step.scenario
    f = {
        "scan": _scan(s.ref),
        "object_scan": _scan(s.obj),
        "guess": {
            "x_m": s.guess.x,
            "y_m": s.guess.y,
            "theta_deg": math.degrees(s.guess.theta),
            "distance_m": math.hypot(s.guess.x, s.guess.y),
        },
    }
    for name, p in s.params.items():
        f[name] = _run(s.ref, s.obj, s.guess, p, s.truth, step.iteration)
        if hasattr(p, "L"):
            r = np.median(s.ref.ranges[s.ref.valid])
            f["metric"] = {"L_m": p.L, "range_m": r, "ratio": math.sqrt(r * r + p.L**2) / p.L}
            if step.L_try is not None:
                f["metric"] |= {
                    "L_try_m": step.L_try,
                    "ratio_try": math.sqrt(r * r + step.L_try**2) / step.L_try,
                }
    if step.variant is not None:
        f[step.variant.name] = _run(
            s.ref, s.obj, s.guess, step.variant.params, s.truth, step.iteration
        )
    if step.distances is not None:
        f["distances"] = _distances(step.distances, step.mad_k)
    if s.truth is not None:
        f["truth"] = {
            "x_m": s.truth.x,
            "y_m": s.truth.y,
            "theta_deg": math.degrees(s.truth.theta),
            "distance_m": math.hypot(s.truth.x, s.truth.y),
        }
    return _ns(f)


def test_every_number_in_the_texts_is_the_steps_own(lesson):
    assert len(lesson) >= 9
    for sr in lesson:
        facts = vars(recomputed(sr.step))
        assert sr.text == sr.step.text.format(**facts), sr.step.path.name
        assert sr.try_text == sr.step.try_text.format(**facts), sr.step.path.name


def test_no_number_is_typed_into_a_text(lesson):
    """A text's digits come from its placeholders, or cite the paper (§, Fig., eq., paper 00N), or
    name things (the 2-D scanner, its model, bearing 0)."""
    cited = re.compile(r"§[\d.]+|Figs?\. [\d-]+|eq\. \d+|[Pp]aper 00\d|2-D|URG-04LX|bearing 0")
    for sr in lesson:
        bare = cited.sub("", re.sub(r"\{[^}]*\}", "", sr.step.text))
        assert not re.search(r"\d", bare), (sr.step.path.name, bare)


def test_the_steps_show_what_their_texts_say(lesson):
    by = {sr.step.number: sr.facts for sr in lesson}
    assert by[1]["scan"]["invalid"] > 0  # a scan with invalid readings, drawn
    # ICP fails, MbICP lands
    assert by[2]["icp"]["error_mm"] > 1000 and by[4]["mbicp"]["error_mm"] < 10
    # a smaller L: a wider ellipse
    assert by[3]["metric"]["ratio_try"] > by[3]["metric"]["ratio"] > 1
    assert by[5]["improved"]["shown"]["interpolated"] > 0
    assert by[6]["distances"]["rejected_values"] == "86.305, 38.76, 34.497"  # paper 000 §2.4.2
    assert by[6]["improved"]["error_mm"] < by[6]["mbicp"]["error_mm"] / 10
    assert by[7]["without_grid"]["first"]["threshold_m"] < by[7]["improved"]["first"]["threshold_m"]
    assert by[7]["improved"]["grid"]["after"] < by[7]["improved"]["grid"]["before"]
    assert by[8]["improved"]["condition"] > 100 and abs(by[8]["improved"]["weakest_deg"]) < 15
    assert by[8]["improved"]["error_mm"] > 500  # shortened along the corridor
    assert {"psm", "pmwn"} <= set(by[9]) and by[9]["pmwn"]["metric_weight"] > 0


def test_each_step_shows_its_own_layers(lesson):
    for sr in lesson:
        drawn = {
            ly.style
            for r in sr.runs
            for ly in sr.layers(r, shown_only=True)
            if ly.path.startswith(f"{scene.SCANS}/") and scene.has_content(ly)
        }
        compared = (
            {scene.run_style(r.matcher) for r in sr.runs}
            if scene.OBJECT in sr.step.layers
            else set()
        )
        assert scene.REFERENCE in drawn
        # nothing the step did not ask for
        assert drawn <= set(sr.step.layers) | compared, sr.step.path.name
    assert {scene.BEAMS, scene.INVALID, scene.SENSOR} <= set(lesson[0].step.layers)


def test_a_text_reaches_only_the_steps_numbers(tmp_path):
    for bad, why in (
        ("{scan.__class__}", "no number called {scan.__class__}"),
        ("{nothing.here:.1f}", "no number called {nothing.here}"),
        ("{scan.beams:.1q}", "cannot format"),
    ):
        path = _step_file(tmp_path, text=bad)
        with pytest.raises(InputError) as e:
            run_step(load_lesson(path.parent)[0])
        assert why in str(e.value) and "text" in str(e.value) and str(path) in str(e.value)


def _step_file(tmp_path, **fields):
    import shutil

    from mbicp_viz.evaluation.scenarios import recordings_dir

    (tmp_path / "lesson").mkdir(exist_ok=True)
    if not (tmp_path / "inputs").exists():
        shutil.copytree(recordings_dir() / "inputs", tmp_path / "inputs")
    text = json.dumps(fields.pop("text", "x"))  # a JSON string is a TOML string
    spec = {
        "title": '"t"',
        "text": text,
        "try": '"y"',
        "input": '"inputs/hokuyo-125-130.npz"',
        "pair": "[0, 1]",
        "algorithms": '["improved"]',
        "layers": '["reference"]',
    } | fields
    path = tmp_path / "lesson" / "01-step.toml"
    path.write_text("".join(f"{k} = {v}\n" for k, v in spec.items()))
    return path


@pytest.mark.parametrize(
    "field,value,why",
    [
        ("layers", '["reference", "sparkles"]', "unknown layer 'sparkles'"),
        ("view_m", "[1, 0, 0, 1]", "minima below maxima"),
        ("iteration", "-1", "expected a whole number"),
        ("algorithms", '["magic"]', "unknown algorithm"),
        ("algorithms", '["icp", "mbicp", "improved"]', "at most 2 matchers"),
    ],
)
def test_a_bad_step_file_is_one_line_naming_its_field(tmp_path, field, value, why):
    path = _step_file(tmp_path, **{field: value})
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "mbicp_viz",
            "lesson",
            "--dir",
            str(path.parent),
            "--export",
            str(tmp_path / "out"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 2 and res.stdout == "", res.stderr
    assert why in res.stderr and field in res.stderr and str(path) in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr


def test_a_teacher_adds_a_step_with_one_file(tmp_path):
    path = _step_file(
        tmp_path, text="{scan.valid} valid readings, {improved.iterations} iterations"
    )
    [sr] = [run_step(s) for s in load_lesson(path.parent)]
    assert (
        sr.text == f"{sr.step.scenario.ref.n_valid} valid readings, {sr.runs[0].result.iterations} "
        "iterations"
    )
    assert [p.name for p in step_paths(path.parent)] == ["01-step.toml"]
    absolute = _step_file(
        tmp_path, input=json.dumps(str(tmp_path / "inputs" / "hokuyo-125-130.npz"))
    )
    assert (
        run_step(load_lesson(absolute.parent)[0]).facts["scan"]["valid"]
        == sr.step.scenario.ref.n_valid
    )


def test_handout_and_rrd_export(lesson, tmp_path):
    from PIL import Image

    out = tmp_path / "handout"
    res = subprocess.run(
        [sys.executable, "-m", "mbicp_viz", "lesson", "--export", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr
    md = (out / "lesson.md").read_text()
    for sr in lesson:
        png = out / f"step-{sr.step.number:02d}.png"
        assert f"]({png.name})" in md and sr.text in md and sr.try_text in md
        img = np.asarray(Image.open(png).convert("RGB")).astype(int)
        assert (
            np.count_nonzero(np.abs(img - np.array(scene.REFERENCE.color)).max(axis=2) < 30) > 50
        ), png.name

    # the .rrd: one text per step on the step timeline, each step's layers at its step; and every
    # iteration of every step on the lesson_iteration timeline
    texts, reference_steps, object_ticks = {}, set(), set()
    for chunk in RrdReader(str(out / "lesson.rrd")).stream().to_chunks():
        rb = chunk.to_record_batch()
        if (
            chunk.entity_path == "/lesson/first/scene/object"
            and "lesson_iteration" in rb.schema.names
        ):
            object_ticks |= set(rb.column("lesson_iteration").to_pylist())
        if "step" not in rb.schema.names:
            continue
        steps = rb.column("step").to_pylist()
        if chunk.entity_path == "/lesson/text":
            column = next(n for n in rb.schema.names if n.endswith(":text"))
            for k, t in zip(steps, rb.column(column).to_pylist()):
                texts.setdefault(k, []).append(t[0] if isinstance(t, list) else t)
        if chunk.entity_path == "/lesson/first/scene/reference" and any(
            ":positions" in n for n in rb.schema.names
        ):
            reference_steps |= set(steps)
    assert sorted(texts) == [sr.step.number for sr in lesson]
    for sr in lesson:
        assert len(texts[sr.step.number]) == 1 and sr.text in texts[sr.step.number][0]
    assert reference_steps == {sr.step.number for sr in lesson}
    for sr in lesson:
        if scene.OBJECT in sr.step.layers:
            n = max(len(r.iterations) for r in sr.runs)
            assert {sr.step.number * 1000 + i for i in range(n + 1)} <= object_ticks, sr.step.title


def test_rerun_viewer_shows_every_step(lesson, tmp_path):
    """rerun's own viewer, moved to each step of the lesson's .rrd: the first matcher's view draws
    the reference scan (red), the second one's draws scans when the step has two matchers and
    nothing when it has one, and the plot beside them is drawn when the step has one."""
    from mbicp_viz.views.lesson.handout import side_plot
    from mbicp_viz.views.lesson.recording import record_lesson

    path = tmp_path / "lesson.rrd"
    record_lesson(lesson, str(path))
    red = np.array(scene.REFERENCE.color)
    with rerun_viewer() as viewer:
        viewer.open(str(path))
        assert wait_for(lambda: not viewer.get_state().loading, 60.0)
        views = {v.name.split(":")[0]: v.view_id for v in viewer.get_state().views}
        for sr in lesson:
            viewer.set_time("step", sequence=sr.step.number, play_state="paused")
            first = settled_screenshot(
                viewer, tmp_path / f"{sr.step.number}-first.png", views["first matcher of the step"]
            )
            assert np.count_nonzero(np.abs(first - red).max(axis=2) < 40) > 100, sr.step.title
            second = settled_screenshot(
                viewer,
                tmp_path / f"{sr.step.number}-second.png",
                views["second matcher of the step"],
            )
            assert (ink(second) > 500) == (len(sr.runs) == 2), (sr.step.title, ink(second))
            plot = settled_screenshot(
                viewer, tmp_path / f"{sr.step.number}-plot.png", views["plot beside the scans"]
            )
            assert (ink(plot) > 500) == (side_plot(sr) is not None), (sr.step.title, ink(plot))
        # the other timeline: the iterations of the MbICP step, its first and its last
        step = next(sr for sr in lesson if sr.step.title.startswith("MbICP, iteration"))
        pictures = []
        for i in (1, len(step.runs[0].iterations)):
            viewer.set_time(
                "lesson_iteration", sequence=step.step.number * 1000 + i, play_state="paused"
            )
            pictures.append(
                settled_screenshot(
                    viewer, tmp_path / f"it{i}.png", views["first matcher of the step"]
                )
            )
            assert ink(pictures[-1]) > 500
        # the scan has moved between them: at the last it covers the reference (little red shows)
        first, last = (np.count_nonzero(np.abs(p - red).max(axis=2) < 40) for p in pictures)
        assert first > 100 and last < first / 2


def ink(img) -> int:
    """Pixels of a view that are not its light background: what it draws."""
    return int(np.count_nonzero(np.abs(img - np.array(BACKGROUND)).max(axis=2) > 60))
