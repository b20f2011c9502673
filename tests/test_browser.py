"""The debugger in a real headless Chromium (Debian's, driven by Playwright): what a person sees
and what the boxes really send."""

import math
import re
from dataclasses import replace

import numpy as np
import pytest
from playwright.sync_api import sync_playwright

from mbicp_viz.core import ImprovedParams, Pose2, relative
from mbicp_viz.readers import read_log
from mbicp_viz.views.debugger.app import App
from mbicp_viz.views.debugger.page_timing import CHROMIUM_ARGS
from mbicp_viz.views.debugger.state import Source
from mbicp_viz.views.scene import OBJECT, REFERENCE

from .conftest import DATA, EXAMPLES, INTEL, interpreted_kernels, wait_for

CHROMIUM = "/usr/bin/chromium"
ARGS = [
    *CHROMIUM_ARGS,
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def scroll_to(locator) -> None:
    """Scrolls to what a locator finds. A plot's legend is replaced when the page sends its data
    again, and Playwright does not retry a scroll on an element that went: find it afresh."""
    from playwright.sync_api import Error

    def scrolled() -> bool:
        try:
            locator.scroll_into_view_if_needed(timeout=2000)
            return True
        except Error:
            return False

    assert wait_for(scrolled)


@pytest.fixture(scope="module")
def app():
    a = App(
        Source("hokuyo pair", read_log(EXAMPLES / "hokuyo-125-130.npz"), guess=Pose2()),
        "127.0.0.1",
        0,
    )
    # a cold numba cache compiles the kernels first (a minute on a loaded 2-core CI): the tabs'
    # timeouts then time the page, not the compile
    assert a.ready.wait(600)
    yield a
    a.stop()


@pytest.fixture(scope="module")
def browser():
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


def open_tab(browser, app):
    before = set(app.sessions)
    page = browser.new_page(viewport={"width": 1400, "height": 900}, accept_downloads=True)
    page.goto(f"http://127.0.0.1:{app.port}")
    page.get_by_role("slider").first.wait_for(timeout=60000)
    assert wait_for(lambda: set(app.sessions) - before)
    session = app.sessions[(set(app.sessions) - before).pop()]
    assert wait_for(lambda: bool(session.state.runs))
    page.get_by_text("after ").first.wait_for(timeout=30000)  # the result is on the page
    return page, session


def box(page, label):
    """The input of the GUI row labelled ``label`` (viser's text boxes are not tied to their
    labels)."""
    return page.locator(
        f"xpath=//label[normalize-space(.)='{label}']"
        "/ancestor::div[contains(@class, 'mantine-Flex-root')][1]//*[self::input or self::textarea]"
    ).first


def type_into(page, label, text):
    b = box(page, label)
    b.fill(text)
    b.press("Enter")


def key_to_iteration(page, session, k: int) -> None:
    """Move the iteration slider to ``k`` with the keyboard, as a person does: Home, then one
    arrow press at a time, each seen by the server before the next (a loaded machine otherwise
    merges presses with the slider's own echo)."""
    slider = page.get_by_role("slider").first
    with session.lock:  # the server has shown its last match (a re-match moves the slider) ...
        shown = (str(int(session.playback.slider.value)), str(int(session.playback.slider.max)))
    # ... and the page has it: a key pressed before would be undone by the late move
    assert wait_for(
        lambda: (
            (slider.get_attribute("aria-valuenow"), slider.get_attribute("aria-valuemax")) == shown
        )
    )
    slider.focus()
    slider.press("Home")
    assert wait_for(lambda: session.state.iteration == 0)
    for n in range(1, k + 1):
        slider.press("ArrowRight")
        assert wait_for(lambda n=n: session.state.iteration == n)


def test_slider_parameter_export_and_colours(browser, app, tmp_path):
    page, session = open_tab(browser, app)
    assert session.state.max_iteration() > 5
    key_to_iteration(page, session, 2)  # the iteration slider, moved with the keyboard
    page.get_by_text("iteration 2:").first.wait_for(timeout=10000)
    type_into(page, "MaxIter", "4")  # the match re-runs; the page shows the new result
    assert wait_for(lambda: session.state.max_iteration() == 4)
    page.get_by_text("after 4 iterations").first.wait_for(timeout=10000)
    with page.expect_download(timeout=30000) as dl:
        page.get_by_role("button", name="export .rrd").click()
    path = tmp_path / "session.rrd"
    dl.value.save_as(path)
    from rerun.chunk import RrdReader

    entities = {c.entity_path for c in RrdReader(str(path)).stream().to_chunks()}
    assert "/improved/scene/reference" in entities and "/improved/scene/pairs/point" in entities
    shot = tmp_path / "page.png"
    page.screenshot(path=str(shot))
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    near = lambda rgb: int(np.count_nonzero(np.abs(img - np.array(rgb)).max(axis=2) < 45))  # noqa: E731
    assert near(REFERENCE.color) > 100 and near(OBJECT.color) > 100  # reference red, object blue
    page.close()


def test_number_boxes_send_exactly_what_was_typed(browser, app):
    page, session = open_tab(browser, app)
    type_into(page, "errx_out [m]", "1e-5")
    assert wait_for(lambda: session.state.params["improved"].errx_out == 1e-5)
    # as a person waits for the page's answer before typing on: the server has re-matched and the
    # page holds its echo of the box (the next box typed while they travel can be overwritten)
    with session.lock:
        pass
    assert wait_for(lambda: box(page, "errx_out [m]").input_value() == "1e-5")
    type_into(page, "MaxIter", "2.5")  # refused: a whole number is needed, nothing changes
    page.get_by_text("expected a whole number").first.wait_for(timeout=10000)
    assert session.state.params["improved"].MaxIter == 100
    # the box shows what the matcher uses
    assert wait_for(lambda: box(page, "MaxIter").input_value() == "100")
    type_into(page, "Bw [deg]", "500")  # out of bounds: refused, not clamped
    page.get_by_text("outside").first.wait_for(timeout=10000)
    box(page, "L [m]").click()  # the box loses focus: still nothing applied
    assert session.state.params["improved"].Bw == pytest.approx(math.radians(45.0))
    box(page, "Br [m]").fill("0.75")  # typed without Enter: not applied ...
    type_into(page, "MaxIter", "7")
    assert wait_for(lambda: session.state.params["improved"].MaxIter == 7)
    assert wait_for(lambda: box(page, "Br [m]").input_value() == "1.0")  # ... and the page says so
    assert session.state.params["improved"].Br == 1.0
    page.close()


def test_two_tabs_keep_their_own_state(browser, app):
    p1, s1 = open_tab(browser, app)
    p2, s2 = open_tab(browser, app)
    assert s1 is not s2
    type_into(p2, "MaxIter", "2")
    assert wait_for(lambda: s2.state.max_iteration() == 2)
    assert s1.state.params["improved"].MaxIter == 100 and s1.state.max_iteration() > 2
    key_to_iteration(p2, s2, 0)  # Home, once the page shows the re-match's slider
    assert s1.state.iteration == s1.state.max_iteration()
    p1.close()
    p2.close()


def test_plots_read_numbers_not_dates(browser, app):
    """uPlot's x axis is a time axis unless told otherwise: hovering a plot must show a number.
    The distance plot's marks are vertical lines, which a live legend reads as "NaN" under the
    cursor: its legend gives each mark's value at the iteration shown instead."""
    from playwright.sync_api import Error

    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger import report

    page, session = open_tab(browser, app)
    legend = page.locator(".u-legend").first

    def hovered() -> bool:  # a plot's element is replaced when its data change: find it afresh
        try:
            plot = page.locator(".u-over").first  # error and threshold per iteration
            plot.scroll_into_view_if_needed(timeout=2000)
            box = plot.bounding_box()
            page.mouse.move(box["x"] + box["width"] * 0.3, box["y"] + box["height"] * 0.5)
            return legend.locator(".u-value").first.inner_text(timeout=2000).strip() not in (
                "",
                "--",
            )
        except Error:
            return False

    assert wait_for(hovered)
    shown = legend.locator(".u-value").first.inner_text().strip()
    assert 0 <= float(shown) <= session.state.max_iteration(), shown  # not "1970-01-01 12:00am"
    labels = " ".join(legend.inner_text().split())
    assert "mean squared residual [mm²]" in labels and "MAD threshold" in labels
    with session.lock:
        ev = report.event(session.state, session.state.runs[0])
        median = scene.histogram(ev.pairs.distance, ev.threshold).median
    distances = page.locator(".u-legend").nth(1)
    assert wait_for(lambda: f"median distance: {median:.3g} m" in distances.inner_text())
    assert "NaN" not in distances.inner_text() and "pairs)" in distances.inner_text()
    page.close()


def test_the_layers_offered_are_the_ones_this_pair_can_have(browser, app):
    """The bundled pair is neither corrected for motion nor a 360-degree scan: no box offers the
    scans as measured or the seam; the pairs' boxes are there."""
    from mbicp_viz.views import scene

    page, session = open_tab(browser, app)
    rejected = page.get_by_text(scene.PAIR_REJECTED.label, exact=True)
    scroll_to(rejected.first)
    assert rejected.first.is_visible()
    for label in (scene.RAW.label, scene.SEAM.label):
        box = page.get_by_text(label, exact=True).first
        assert wait_for(lambda b=box: not b.is_visible())
    page.close()


def dense(scan, n: int):
    """A real scan resampled to ``n`` beams over its own field of view (a lidar of that many)."""
    from mbicp_viz.core import Scan

    b = np.linspace(scan.bearings[0], scan.bearings[-1], n)
    k = np.clip(np.searchsorted(scan.bearings, b), 1, len(scan.bearings) - 1)
    near = np.where(b - scan.bearings[k - 1] < scan.bearings[k] - b, k - 1, k)
    ok = scan.valid
    return Scan(np.interp(b, scan.bearings[ok], scan.ranges[ok]), b, ok[near])


def test_a_long_match_shows_its_time_and_budget_and_stops_from_the_page(browser, tmp_path):
    """A match that would run for minutes (20,000 beams, stopping thresholds 0): the page says how
    long it has run and the budget, the stop button ends it at its next iteration, and the result
    says halted with the pose of the last iteration."""
    from dataclasses import replace

    from mbicp_viz.core import MATCHERS, Termination
    from mbicp_viz.readers import ScanLog

    log = read_log(EXAMPLES / "hokuyo-125-130.npz")
    big = ScanLog("dense", [dense(log.scan(0), 20000), dense(log.scan(1), 20000)])
    slow = replace(
        MATCHERS["improved"].params_type(),
        MaxIter=10000,
        errx_out=0.0,
        erry_out=0.0,
        errt_out=0.0,
        errorRatio=0.0,
    )
    application = App(
        Source("dense pair", big, guess=Pose2(), params={"improved": slow}), "127.0.0.1", 0
    )
    try:
        assert application.ready.wait(600)
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.goto(f"http://127.0.0.1:{application.port}")
        stop = page.get_by_role("button", name="stop the match")
        stop.wait_for(timeout=60000)
        page.get_by_text("working for").first.wait_for(timeout=10000)
        assert "budget 60 s a match" in page.inner_text("body")
        stop.click()
        page.get_by_text("stopped from the page").first.wait_for(timeout=60000)
        session = next(iter(application.sessions.values()))
        r = session.state.runs[0].result
        assert r.reason is Termination.HALTED and r.iterations < slow.MaxIter
        assert wait_for(lambda: not stop.is_visible())
        assert "working for" not in page.inner_text("body")
        page.screenshot(path=str(tmp_path / "halted.png"))
        page.close()
    finally:
        application.stop()


def test_arrow_keys_on_the_slider_leave_the_view_top_down(browser, app):
    from mbicp_viz.views.debugger.camera import TopDownCamera

    page, session = open_tab(browser, app)
    pts = session.state.runs[0].start.ref_points
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
    cam = session.client.camera  # a new tab opens top-down over the whole reference scan
    assert wait_for(lambda: np.allclose(cam.look_at[:2], centre, atol=1e-3)), (cam.look_at, centre)
    assert TopDownCamera.is_top_down(cam.position, cam.look_at, cam.up_direction)
    slider = page.get_by_role("slider").first
    slider.focus()
    placed = session.camera.placed_at
    for _ in range(35):  # each press also turns viser's camera: it is put back top-down
        slider.press("ArrowLeft")
    page.keyboard.down("ArrowUp")  # held keys tilt it continuously
    # the tab reported a tilted camera and the session levelled it (a tilt lasts one report: a
    # loaded machine may never show it to a poll)
    assert wait_for(lambda: session.camera.placed_at > placed, 10)
    page.keyboard.up("ArrowUp")
    cam = session.client.camera
    assert wait_for(
        lambda: TopDownCamera.is_top_down(cam.position, cam.look_at, cam.up_direction), 20
    )
    # the keys moved the slider too: down to 0, one up
    assert wait_for(lambda: session.state.iteration == 1)
    page.close()


def test_compare_two_matchers_two_colours_and_two_legend_entries(browser, app, tmp_path):
    from PIL import Image

    from mbicp_viz.core import MATCHERS
    from mbicp_viz.views.scene import run_style

    page, session = open_tab(browser, app)
    page.locator(
        "xpath=//label[normalize-space(.)='icp']/ancestor::div[contains(@class, "
        "'mantine-Flex-root')][1]"
        "//input"
    ).first.check()
    assert wait_for(lambda: [r.matcher for r in session.state.runs] == ["icp", "improved"])
    legend = page.locator(".mbicp-legend")
    assert wait_for(lambda: run_style("icp").label in legend.inner_text())
    assert run_style("improved").label in legend.inner_text()
    page.get_by_text("icp: iteration").first.wait_for(timeout=10000)  # each run its own text
    page.get_by_text("improved: iteration").first.wait_for(timeout=10000)
    for name in ("icp", "improved"):  # each compared run its own distance plot
        page.get_by_text(f"{name}: pair distances (this iteration)").first.wait_for(timeout=10000)
    shot = tmp_path / "compare.png"

    def both_drawn() -> bool:  # the view draws the new nodes on its next frames
        page.screenshot(path=str(shot))
        # the view, not the panel
        img = np.asarray(Image.open(shot).convert("RGB")).astype(int)[:, :1000]
        near = lambda rgb: int(np.count_nonzero(np.abs(img - np.array(rgb)).max(axis=2) < 30))  # noqa: E731
        return near(MATCHERS["icp"].colour) > 100 and near(MATCHERS["improved"].colour) > 100

    assert wait_for(both_drawn)
    page.close()


# the health timeline's plotting area (left, right) and the track of the slider right under it
# (left, right, its middle's height), in page pixels
TIMELINE_AND_TRACK = """() => {
  const title = [...document.querySelectorAll('.u-title')]
    .find(e => e.textContent.startsWith('health of every pair'));
  const over = title.closest('.uplot').querySelector('.u-over').getBoundingClientRect();
  const below = [...document.querySelectorAll('.mantine-Slider-track')]
    .map(e => e.getBoundingClientRect()).filter(b => b.top > over.bottom)
    .sort((a, b) => a.top - b.top)[0];
  return [[over.left, over.right], [below.left, below.right, below.top + below.height / 2]];
}"""


def test_the_run_view_finds_the_flagged_pair_and_opens_it(browser, tmp_path):
    """serve LOG --rows on a whole run: "show the run" draws the trajectory and the map in the
    world frame with their legend; "next flagged" moves to the first flagged pair, whose signs the
    panel names; a click on the trajectory brings the pair that ends there, and one on the
    timeline's track the pair under it; "open this pair"
    opens it in the pair debugger as the run matched it."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli
    from mbicp_viz.evaluation.health import flags_text
    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger.sources import files_source

    rows = tmp_path / "rows.jsonl"
    res = CliRunner().invoke(
        cli, ["eval", "sequence", str(INTEL), "--guess", "identity", "--out", str(rows)]
    )
    assert res.exit_code == 0, res.output
    src = files_source(str(INTEL), None, rows=str(rows))
    assert src.run is not None and len(src.run) == 59
    application = App(src, "127.0.0.1", 0)
    try:
        page, session = open_tab(browser, application)  # the rows of a run open on the run
        legend = page.locator(".mbicp-legend")
        legend.get_by_text(scene.RUN_MAP.label).wait_for(timeout=30000)
        for style in (scene.RUN_TRAJECTORY, scene.RUN_REFERENCE, scene.RUN_OBJECT, scene.SUSPECT):
            assert style.label in legend.inner_text()
        assert "the world frame" in legend.inner_text()
        page.screenshot(path=str(tmp_path / "run-view.png"))
        # a click on the trajectory brings the pair that ends there: the pose farthest from the
        # others, projected through the tab's own top-down camera onto the page
        track = np.array([[p.x, p.y] for p in session.run.model.poses])
        apart = [np.sort(np.hypot(*(track - t).T))[1] for t in track]
        k = int(np.argmax(apart[2:])) + 2  # not the first pair: the slider starts there
        # the tab's view once it has taken the run's framing (under load it reports it late)
        cam = session.client.camera
        centre, _ = session.camera.framing(session.run.model.extent(), cam.fov, cam.aspect)
        assert wait_for(lambda: np.allclose(cam.look_at[:2], centre, atol=0.01))
        canvas = page.locator("canvas").first.bounding_box()
        half_h = (cam.position[2] - 0.0) * np.tan(cam.fov / 2)
        u = 0.5 + (track[k, 0] - cam.look_at[0]) / (2 * half_h * cam.aspect)
        v = 0.5 - (track[k, 1] - cam.look_at[1]) / (2 * half_h)
        page.mouse.click(canvas["x"] + u * canvas["width"], canvas["y"] + v * canvas["height"])
        assert wait_for(lambda: session.run.n == k - 1)
        row = src.run[k - 1]
        page.get_by_text(f"scans {row.ref} → {row.obj}").first.wait_for(timeout=30000)
        # the health timeline's area is over the pair slider's track: a click on the track under
        # a flagged pair's spike picks that pair
        plot, track = page.evaluate(TIMELINE_AND_TRACK)
        assert abs(plot[0] - track[0]) < 1.5 and abs(plot[1] - track[1]) < 1.5, (plot, track)
        spike = max(n for n, r in enumerate(src.run) if r.flags and n != k - 1)
        x = plot[0] + spike / (len(src.run) - 1) * (plot[1] - plot[0])
        page.mouse.click(x, track[2])
        assert wait_for(lambda: session.run.n == spike)
        page.get_by_role("button", name="previous flagged").click()
        first = max(n for n, r in enumerate(src.run) if r.flags and n < spike)
        assert wait_for(lambda: session.run.n == first)
        page.get_by_role("button", name="next flagged").click()
        first = min(n for n, r in enumerate(src.run) if r.flags and n > first)
        row = src.run[first]
        page.get_by_text(f"scans {row.ref} → {row.obj}").first.wait_for(timeout=30000)
        assert f"**flagged**: {flags_text(row)}".replace("**", "") in page.inner_text("body")
        assert session.run.n == first
        page.screenshot(path=str(tmp_path / "run-view-flagged.png"))
        page.get_by_role("button", name="open this pair").click()
        page.get_by_text(f"line {row.line}): {row.matcher} gave").first.wait_for(timeout=30000)
        assert session.state.pair == (row.ref, row.obj) and session.state.guess == row.guess
        legend.get_by_text(scene.REFERENCE.label, exact=True).wait_for(timeout=30000)
        assert scene.RUN_MAP.label not in legend.inner_text()
        # and back to the run, at the same pair
        page.get_by_role("button", name="show the run").click()
        legend.get_by_text(scene.RUN_MAP.label).wait_for(timeout=30000)
        assert session.run.n == first and session.run.active
        page.close()
    finally:
        application.stop()


def test_two_runs_in_the_run_view(browser, tmp_path):
    """serve LOG --rows A --versus B: run B's trajectory is drawn beside A's with its own legend
    entry, the verdict is on the page, the pairs where they differ are listed farthest first, and
    "open run B's match" opens B's row of the pair in view."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli
    from mbicp_viz.evaluation.health import suspect_label
    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger.sources import files_source

    paths = []
    for algo in ("improved", "plicp"):
        paths.append(tmp_path / f"{algo}.jsonl")
        res = CliRunner().invoke(
            cli,
            ["eval", "sequence", str(INTEL), "--algo", algo, "--guess", "identity"]
            + ["--out", str(paths[-1]), "--workers", "1"],
        )
        assert res.exit_code == 0, res.output
    src = files_source(str(INTEL), None, rows=str(paths[0]), versus=str(paths[1]))
    v = src.versus
    application = App(src, "127.0.0.1", 0)
    try:
        page, session = open_tab(browser, application)
        legend = page.locator(".mbicp-legend")
        legend.get_by_text(f"{scene.RUN_OTHER.label}: {paths[1]}").wait_for(timeout=30000)
        assert v.verdict()[0] in page.inner_text("body")
        page.screenshot(path=str(tmp_path / "two-runs.png"))
        page.get_by_role("combobox", name="open where they differ").click()
        options = page.get_by_role("option").all_inner_texts()
        assert options == [suspect_label(k + 1, r) for k, r in enumerate(v.differing())]
        page.keyboard.press("Escape")
        page.get_by_role("button", name="open run B's match of this pair").click()
        b = v.b[0]
        page.get_by_text(f"line {b.line}): {b.matcher} gave").first.wait_for(timeout=30000)
        assert session.state.pair == (b.ref, b.obj) and session.state.matchers == ["plicp"]
        page.close()
    finally:
        application.stop()


def test_the_relations_a_run_misses_most_open_in_the_run_view(browser, tmp_path):
    """serve LOG --rows ROWS --relations F: the run's score on the relations is the one `eval
    relations --run` prints; the costliest relation, chosen, is drawn (its legend entry) and the
    slider goes to the pair that ends at its later scan."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli
    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger.sources import files_source

    log, relations, offset = (
        DATA / "intel-relations.log",
        DATA / "intel-relations.relations",
        976052857.337,
    )
    rows = tmp_path / "rows.jsonl"
    res = CliRunner().invoke(
        cli, ["eval", "sequence", str(log), "--guess", "odometry", "--out", str(rows)]
    )
    assert res.exit_code == 0, res.output
    score = CliRunner().invoke(
        cli,
        ["eval", "relations", str(log), str(relations), "--offset", str(offset), "--run"]
        + [str(rows)],
    )
    chained = next(x for x in score.output.splitlines() if x.strip().startswith("matches chained"))
    mean_sd = re.search(r"translation (\S+ ± \S+) m", chained).group(1)
    src = files_source(str(log), None, rows=str(rows), relations=str(relations), offset=offset)
    application = App(src, "127.0.0.1", 0)
    try:
        page, session = open_tab(browser, application)
        page.get_by_text(f"translation {mean_sd} m").first.wait_for(timeout=30000)
        model = session.run.model
        worst = model.costliest()[0]
        label = model.relation_label(1, worst)
        page.get_by_role("combobox", name="relations, costliest first").click()
        page.get_by_role("option", name=label).click()
        page.locator(".mbicp-legend").get_by_text(scene.RELATION.label).wait_for(timeout=30000)
        j = int(model.relation_errors.ends[worst][1])
        assert wait_for(lambda: session.run.n == j - 1)
        page.screenshot(path=str(tmp_path / "relation.png"))
        page.close()
    finally:
        application.stop()


def test_suspicious_pairs_of_a_run_without_truth_open_as_they_ran(browser, tmp_path):
    """serve LOG --rows on a run without truth: the pairs flagged without truth are listed, the
    most suspicious first with their signs; choosing one opens it as it ran, its signs on the
    page."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli
    from mbicp_viz.evaluation.health import flags_text, suspect_label
    from mbicp_viz.views.debugger.sources import files_source

    log, rows = DATA / "intel-relations.log", tmp_path / "rows.jsonl"
    res = CliRunner().invoke(
        cli,
        ["eval", "sequence", str(log), "--guess", "identity", "--out", str(rows)]
        + ["--workers", "1"],
    )
    assert res.exit_code == 0, res.output
    src = files_source(str(log), None, rows=str(rows))
    assert len(src.suspects) >= 2 and all(r.score is None for r in src.suspects)
    application = App(src, "127.0.0.1", 0)
    try:
        page, session = open_tab(browser, application)
        page.get_by_text("this run reproduces it").first.wait_for(timeout=30000)
        page.get_by_role("combobox", name="open flagged").click()
        options = page.get_by_role("option").all_inner_texts()
        assert options == [suspect_label(k + 1, r) for k, r in enumerate(src.suspects)]
        page.get_by_role("option").nth(1).click()
        second = src.suspects[1]
        page.get_by_text(f"line {second.line}): {second.matcher} gave").first.wait_for(
            timeout=30000
        )
        page.get_by_text("this run reproduces it").first.wait_for(timeout=30000)
        assert session.state.pair == (second.ref, second.obj)
        assert f"flagged: {flags_text(second)}" in page.inner_text("body")
        page.screenshot(path=str(tmp_path / "suspicious-pairs.png"))
        page.close()
    finally:
        application.stop()


def test_failures_of_an_evaluation_open_as_they_failed(browser, tmp_path):
    """serve LOG --rows: the failures listed worst first with their reason; choosing one opens it
    with the evaluation's own matcher, parameters and guess, and the page says it reproduces."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli
    from mbicp_viz.evaluation.failures import failure_kind, failure_label
    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger.sources import files_source
    from mbicp_viz.views.debugger.state import WHY_LAYERS

    log, rows = DATA / "intel-relations.log", tmp_path / "rows.json"
    res = CliRunner().invoke(
        cli,
        [
            "eval",
            "sequence",
            str(log),
            "--guess",
            "identity",
            "--truth",
            "pose",
            "--out",
            str(rows),
            "--workers",
            "1",
        ],
    )
    assert res.exit_code == 0, res.output
    src = files_source(str(log), None, rows=str(rows))
    assert len(src.failures) >= 2
    application = App(src, "127.0.0.1", 0)
    try:
        page, session = open_tab(browser, application)
        page.get_by_text("this run reproduces it").first.wait_for(timeout=30000)
        assert f"line {src.failures[0].line}" in page.inner_text("body")
        page.get_by_role("combobox", name="open", exact=True).click()
        options = page.get_by_role("option").all_inner_texts()
        assert options == [failure_label(k + 1, r) for k, r in enumerate(src.failures)]
        # a later failure whose reason is seen in the scene (low overlap, degenerate, wrong basin)
        k = next(k for k, r in enumerate(src.failures) if k and failure_kind(r) in WHY_LAYERS)
        page.get_by_role("option").nth(k).click()
        second = src.failures[k]
        page.get_by_text(f"line {second.line}): {second.matcher} gave").first.wait_for(
            timeout=30000
        )
        page.get_by_text("this run reproduces it").first.wait_for(timeout=30000)
        assert (
            session.state.pair == (second.ref, second.obj) and session.state.guess == second.guess
        )
        assert box(page, "reference scan").input_value() == str(second.ref)
        # it opens on the layers its reason is seen in, and the legend lists only those
        page.get_by_text("(the Layers panel has the others)").first.wait_for(timeout=10000)
        entries = page.locator(".mbicp-legend .legend-entry")
        wanted = {s.label for s in WHY_LAYERS[failure_kind(second)]}
        shown = lambda: {t for t in entries.all_inner_texts() if not t.startswith("grid:")}  # noqa: E731
        assert wait_for(lambda: shown() <= wanted)
        assert {scene.REFERENCE.label, scene.TRUTH.label} <= shown()
        page.close()
    finally:
        application.stop()


def test_the_lesson_step_by_step(browser, tmp_path):
    """A student takes the lesson: every step opens with its text, matchers, layers (the legend says
    which) and iteration, and its picture draws the reference scan; back returns; a live change of
    L re-runs the step's matcher while its text keeps the step's own numbers."""
    from PIL import Image

    from mbicp_viz.views.debugger.lesson import step_source
    from mbicp_viz.views.lesson.steps import load_lesson, run_step

    steps = tuple(load_lesson())
    app = App(step_source(steps[0], steps), "127.0.0.1", 0)
    try:
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.goto(f"http://127.0.0.1:{app.port}")
        for k, step in enumerate(steps):
            if k:
                page.get_by_role("button", name="next step").click()
            page.get_by_text(f"Step {step.number} of {len(steps)}: {step.title}").first.wait_for(
                timeout=60000
            )
            session = next(iter(app.sessions.values()))
            sr = run_step(step)
            # the text, with its numbers
            page.get_by_text(sr.text[:60]).first.wait_for(timeout=30000)
            state = session.state
            assert state.matchers == list(step.scenario.params) and state.iteration == sr.iteration
            own = {s.label for s in step.layers} | {f"{r}: object scan" for r in state.matchers}

            # what the legend lists: the step's layers, and the grid
            def legend_is_the_steps(own=own) -> bool:
                legend = page.locator(".mbicp-legend .legend-entry").all_inner_texts()
                return REFERENCE.label in legend and all(
                    e in own or e.startswith("grid:") for e in legend
                )

            assert wait_for(legend_is_the_steps), page.locator(
                ".mbicp-legend .legend-entry"
            ).all_inner_texts()
            shot = tmp_path / f"step{step.number}.png"

            # the canvas draws once the scene has arrived
            def reference_drawn(shot=shot) -> bool:
                page.screenshot(path=str(shot))
                img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
                img = img[:, :1000]  # the view, not the panel
                return (
                    np.count_nonzero(np.abs(img - np.array(REFERENCE.color)).max(axis=2) < 45) > 100
                )

            assert wait_for(reference_drawn), step.title
        page.get_by_role("button", name="previous step").click()
        page.get_by_text(f"Step {steps[-2].number} of {len(steps)}").first.wait_for(timeout=30000)
        page.get_by_role("combobox", name="step").click()  # the step list
        assert page.get_by_role("option").all_inner_texts() == [
            f"{s.number}. {s.title}" for s in steps
        ]
        page.get_by_role("option", name=f"3. {steps[2].title}").click()
        page.get_by_text(f"Step 3 of {len(steps)}").first.wait_for(timeout=30000)
        session = next(iter(app.sessions.values()))
        before = session.state.runs[0].result.pose

        def shows_the_steps_L() -> bool:  # the box is step 3's (L = 1.5), not the panel it replaced
            try:
                return (
                    float(box(page, "L [m]").input_value())
                    == session.state.params["mbicp"].L
                    == 1.5
                )
            except ValueError:
                return False

        with session.lock:  # the server is done with the step (its match and what it sends) ...
            pass
        # ... and the page shows it: typing before that, a late echo of the step's 1.5 undid it
        assert wait_for(shows_the_steps_L), box(page, "L [m]").input_value()
        type_into(page, "L [m]", "0.5")
        assert wait_for(
            lambda: (
                session.state.params["mbicp"].L == 0.5
                and session.state.runs[0].result.pose != before
            )
        ), (
            box(page, "L [m]").input_value(),
            session.state.params["mbicp"].L,
            session.h_status.content,
        )
        # the step's own numbers
        page.get_by_text(run_step(steps[2]).text[:60]).first.wait_for(timeout=10000)
        page.close()
    finally:
        app.stop()


def test_a_tab_that_matches_interpreted_says_so_until_the_kernels_are_compiled(browser, app):
    """After an install (core/tiers.py's quick start) the page tells why a match is slow, and stops
    once the background compile has ended."""
    from mbicp_viz.core.tiers import INTERPRETED

    with interpreted_kernels():
        page, session = open_tab(browser, app)
        notice = page.get_by_text(INTERPRETED)
        notice.wait_for(timeout=30000)
        # the notice shows while the interpreted match runs; its result follows (slowly, loaded)
        assert wait_for(lambda: "converged" in session.h_result.content, timeout=120)
    session.compiled()  # what the server does when the background compile ends
    notice.wait_for(state="detached", timeout=30000)
    page.close()


def test_extrapolated_steps_are_named_in_the_playback_text(browser, app):
    """Typing ``extrapolate`` re-matches with it (the box sends the number), and the playback text
    of an extrapolated iteration says so, with its factor, as a person reads it."""
    page, session = open_tab(browser, app)
    assert not any(e.extrapolated for e in session.state.runs[0].iterations)  # off by default
    type_into(page, "extrapolate", "3")
    assert wait_for(lambda: session.state.params["improved"].extrapolate == 3.0)
    assert wait_for(lambda: any(e.extrapolated for e in session.state.runs[0].iterations))
    ev = next(e for e in session.state.runs[0].iterations if e.extrapolated)
    key_to_iteration(page, session, ev.iteration)
    page.get_by_text(f"went on to {1.0 + ev.extrapolated:.2f} times its length").first.wait_for(
        timeout=10000
    )
    assert (
        float(box(page, "extrapolate").input_value())
        == session.state.params["improved"].extrapolate
    )
    page.close()


def test_a_preset_picked_on_the_page_loads_and_the_picker_says_what_is_loaded(browser, app):
    """The preset picker offers the edited matcher's presets; picking one fills the boxes and
    re-matches; typing a value makes it 'as typed'; 'defaults' goes back."""
    from mbicp_viz.readers.params_toml import presets_for
    from mbicp_viz.views.debugger.state import DEFAULTS, TYPED

    page, session = open_tab(browser, app)
    picker = page.get_by_role("combobox", name="preset")
    assert picker.input_value() == DEFAULTS
    picker.click()
    assert page.get_by_role("option").all_inner_texts() == [
        DEFAULTS,
        *presets_for("improved"),
        TYPED,
    ]
    before = session.state.max_iteration()
    page.get_by_role("option", name="poor-guess").click()
    assert wait_for(
        lambda: session.state.params["improved"] == presets_for("improved")["poor-guess"]
    )
    assert wait_for(lambda: box(page, "mad_anneal").input_value() == "0.7")  # what the page shows
    assert wait_for(lambda: session.state.max_iteration() != before)
    page.get_by_text(f"after {session.state.max_iteration()} iterations").first.wait_for(
        timeout=10000
    )
    type_into(page, "MaxIter", "7")
    assert wait_for(lambda: session.state.params["improved"].MaxIter == 7)
    assert wait_for(lambda: picker.input_value() == TYPED)
    picker.click()
    page.get_by_role("option", name=DEFAULTS).click()
    assert wait_for(
        lambda: (
            box(page, "MaxIter").input_value() == "100"
            and box(page, "mad_anneal").input_value() == "0.0"
        )
    )
    assert wait_for(lambda: picker.input_value() == DEFAULTS)
    page.close()


def test_a_log_with_two_lasers_opens_the_front_one_and_the_page_says_which_stream_it_shows(
    browser, tmp_path, intel
):
    """A CARMEN log with FLASER, RAWLASER1 and RAWLASER2 opens on FLASER with a note naming the
    others; picking RAWLASER2 in "scan stream" shows that laser's scans, and the note that said
    FLASER is gone from the page."""
    from mbicp_viz.views.debugger.sources import files_source

    from .test_readers import two_lasers

    path = two_lasers(tmp_path / "two-lasers.log", intel)
    application = App(files_source(str(path), None, guess="identity"), "127.0.0.1", 0)
    try:
        page, session = open_tab(browser, application)
        note = "read FLASER (4 scans), the front laser with its poses"
        assert note in page.inner_text("body") and "records 0 .. 3 of FLASER" in page.inner_text(
            "body"
        )
        picker = page.get_by_role("combobox", name="scan stream")
        assert picker.input_value() == "FLASER"
        picker.click()
        page.get_by_role("option", name="RAWLASER2").click()
        page.get_by_text("records 0 .. 3 of RAWLASER2").first.wait_for(timeout=30000)
        assert wait_for(lambda: note not in page.inner_text("body"))
        assert np.allclose(session.state.ref.points(), intel.scans[10].points(), atol=1e-9)
        page.close()
    finally:
        application.stop()


def test_a_files_name_on_the_page_shows_as_written_and_breaks_at_the_panels_edge(
    browser, tmp_path, intel
):
    """A note naming a file shows the name as written: the markdown and the HTML in it are not
    read (an image whose error handler would run, words that would turn italic), and a name
    longer than the panel is wide breaks at its edge instead of running past it."""
    from mbicp_viz.views.debugger.sources import files_source

    from .test_readers import two_lasers

    folder = tmp_path / ("a_b_*c*_<img src=x onerror=window.pwned=1>_" + "x" * 150)
    folder.mkdir()
    path = two_lasers(folder / "two-lasers.log", intel)
    application = App(files_source(str(path), None, guess="identity"), "127.0.0.1", 0)
    try:
        page, _ = open_tab(browser, application)
        note = page.get_by_text("read FLASER (4 scans)").first
        assert f"{path}: read FLASER" in note.inner_text()
        assert page.evaluate("window.pwned === undefined")
        # the text's extent, not the element's: a word running past the edge overflows its box
        text_right, box_right = note.evaluate(
            "e => { const r = document.createRange(); r.selectNodeContents(e); "
            "return [r.getBoundingClientRect().right, e.getBoundingClientRect().right]; }"
        )
        assert text_right <= box_right + 1
        page.close()
    finally:
        application.stop()


def test_a_box_left_without_enter_says_so_on_the_page(browser, app):
    """Text typed into a parameter box and not applied is never passed off as the matcher's."""
    page, session = open_tab(browser, app)
    b, before = box(page, "Bw [deg]"), session.state.params["improved"].Bw
    b.fill("60")
    page.get_by_text("Bw [deg]: '60' is not applied yet: Enter applies it").wait_for(timeout=10000)
    assert session.state.params["improved"].Bw == before
    b.press("Enter")
    assert wait_for(lambda: session.state.params["improved"].Bw == pytest.approx(math.radians(60)))
    assert wait_for(lambda: page.get_by_text("is not applied yet").count() == 0)
    page.close()


def test_the_debugger_opened_from_a_notebook_cell_shows_in_the_cell(browser, tmp_path):
    """``mv.open_debugger`` in a Jupyter kernel (nbclient): the cell's output embeds the debugger;
    put in a page as Jupyter puts it, it opens on the run view of the rows given; stopping it from
    the next cell ends the server."""
    import urllib.request

    import nbformat
    from nbclient import NotebookClient

    from mbicp_viz.views import scene

    nb = nbformat.v4.new_notebook()
    nb.cells = [
        nbformat.v4.new_code_cell(
            "import mbicp_viz as mv\n"
            f"log = mv.read_log({str(INTEL)!r})\n"
            "rows = mv.run(log, guess='identity', limit=20, workers=1)\n"
            "debugger = mv.open_debugger(log, rows=rows)\n"
            "debugger"
        ),
        nbformat.v4.new_code_cell("debugger.stop()"),
    ]
    client = NotebookClient(nb, timeout=600, kernel_name="python3")
    with client.setup_kernel():
        client.execute_cell(nb.cells[0], 0)
        shown = [o.data.get("text/html", "") for o in nb.cells[0].outputs if "data" in o]
        (html,) = [h for h in shown if "<iframe" in h]
        url = re.search(r'src="(http://127\.0\.0\.1:\d+)"', html)[1]
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.set_content(f"<h3>a notebook cell's output</h3>{html}")
        frame = page.frame_locator("iframe")
        frame.get_by_role("slider").first.wait_for(timeout=60000)
        frame.locator(".mbicp-legend").get_by_text(scene.RUN_MAP.label).wait_for(timeout=60000)
        page.screenshot(path=str(tmp_path / "notebook-debugger.png"))
        page.close()
        client.execute_cell(nb.cells[1], 1)
        with pytest.raises(OSError):
            urllib.request.urlopen(url, timeout=5)


def test_a_run_matched_in_the_background_shows_its_progress_then_opens(browser, tmp_path):
    """eval sequence --serve: the log's pairs open at once while the run is matched; the page
    follows the run's progress (bar and words) and opens the run view when it is done."""
    from mbicp_viz.evaluation.sequence import match_sequence
    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger.background import Background
    from mbicp_viz.views.debugger.sources import log_source

    log = read_log(str(INTEL))
    rows = match_sequence(log, ImprovedParams(), guess="odometry", workers=1)
    background = Background(len(rows))
    application = App(replace(log_source("intel", log), background=background), "127.0.0.1", 0)
    try:
        page, session = open_tab(browser, application)  # a pair's result is on the page already
        page.get_by_text(f"0 of {len(rows)} pairs").wait_for(timeout=30000)
        # a run reading its log as it goes knows how many pairs it has at most
        background.update(10, len(rows) + 3, True, "40/s, 1 s left")
        page.get_by_text(f"10 of up to {len(rows) + 3} pairs").wait_for(timeout=30000)
        page.screenshot(path=str(tmp_path / "matching-up-to.png"))
        background.update(20, len(rows), False, "40/s, 1 s left")
        page.get_by_text(f"20 of {len(rows)} pairs (40/s, 1 s left)").wait_for(timeout=30000)
        bar = page.get_by_role("progressbar")
        assert wait_for(lambda: float(bar.get_attribute("aria-valuenow")) == 2000 / len(rows))
        page.screenshot(path=str(tmp_path / "matching.png"))
        background.finish(log_source("intel", log, run=rows, rows_label="rows"))
        page.locator(".mbicp-legend").get_by_text(scene.RUN_TRAJECTORY.label).wait_for(
            timeout=30000
        )
        page.get_by_role("button", name="back to the pair").wait_for(timeout=30000)
        assert page.get_by_role("progressbar").count() == 0
        assert session.run is not None and len(session.run.model.rows) == len(rows)
        page.screenshot(path=str(tmp_path / "matched.png"))
        page.close()
    finally:
        application.stop()


def test_a_runs_loops_are_drawn_listed_opened_and_decided_by_hand(browser, tmp_path):
    """serve LOG --rows R --close-loops: the run view draws the trajectory with the loops closed
    and every candidate in its verdict's colour, with legend entries, and the map at either poses;
    each candidate is listed with its verdict and opens as it was matched (from the search's best
    peak) beside its response over rotation and what it does to the run's relation score; "reject
    this closure" solves the graph again and the page shows it rejected by hand."""
    from mbicp_viz.evaluation.loops import close_loops
    from mbicp_viz.evaluation.run_score import relation_errors
    from mbicp_viz.evaluation.trajectory import accumulate, stamps
    from mbicp_viz.readers.pair_match import Verdict
    from mbicp_viz.readers.relations import Relation
    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger.loops import NONE
    from mbicp_viz.views.debugger.run_model import RELATION_TOLERANCE_S, MapAt
    from mbicp_viz.views.debugger.sources import files_source

    from .conftest import HOKUYO_BAG
    from .test_loops import HAND_HELD_LOOPS, hand_held_run

    rows = tmp_path / "rows.jsonl"
    res = hand_held_run(rows)
    assert res.exit_code == 0, res.output
    src = files_source(str(HOKUYO_BAG), None, rows=str(rows))
    loops = close_loops(src.log, src.run, src.run[0].params, HAND_HELD_LOOPS)
    verdicts = {c.verdict for c in loops.closures}
    assert Verdict.ACCEPTED in verdicts and len(verdicts) > 1
    # relations between scans far apart along the run, as the chained run has them: the page's
    # scores are checked against the scorer of `eval relations`
    t, chained = stamps(src.log, src.run), accumulate(src.run)
    relations = [
        Relation(t[i], t[i + 150], relative(chained[i], chained[i + 150])) for i in range(0, 150, 5)
    ]
    application = App(replace(src, loops=loops, relations=relations), "127.0.0.1", 0)

    def score(run):
        return relation_errors(np.array(t), run.optimised, relations, RELATION_TOLERANCE_S).trans

    try:
        page, session = open_tab(browser, application)
        legend = page.locator(".mbicp-legend")
        legend.get_by_text(scene.LOOP_TRAJECTORY.label).wait_for(timeout=30000)
        for v in verdicts:
            assert scene.CLOSURE[v].label in legend.inner_text()
        page.get_by_text(f"loops: {loops.around(1)}").wait_for(timeout=30000)  # at pair 1
        page.get_by_text(
            f"with the loops closed: translation {score(loops).mean():.3f} m (chained: 0.000 m)"
        ).wait_for(timeout=30000)
        page.get_by_role("combobox", name="map at").click()
        page.get_by_role("option", name=MapAt.BOTH.value).click()
        legend.get_by_text(scene.RUN_LOOP_MAP.label).wait_for(timeout=30000)
        assert scene.RUN_MAP.label in legend.inner_text()  # the map before, under the one after
        page.screenshot(path=str(tmp_path / "run-view-loops.png"))

        def pick(k):
            page.get_by_role("combobox", name="open candidate").click()
            options = page.get_by_role("option").all_inner_texts()
            assert options == [
                NONE,
                *(
                    f"{n + 1}. scans {c.old} -> {c.key}: {c.says()}"
                    for n, c in enumerate(session.state.source.loops.closures)
                ),
            ]
            page.get_by_role("option").nth(k + 1).click()

        k = next(n for n, c in enumerate(loops.closures) if c.verdict is not Verdict.ACCEPTED)
        c = loops.closures[k]
        pick(k)
        # the pair and the guess from the search's peak, as it was matched (the page's thread sets
        # the one after the other: both awaited)
        opened = ((c.old, c.key), c.match.guess)
        assert wait_for(lambda: (session.state.pair, session.state.guess) == opened)
        page.get_by_text(f"loop candidate ({c.verdict.value}").first.wait_for(timeout=30000)
        for label in (scene.RESPONSE.label, scene.CHOSEN_PEAK.label, scene.SECOND_PEAK.label):
            page.get_by_text(label).first.wait_for(timeout=30000)
        forced = loops.decided({k: True})
        page.get_by_text(
            f"relation score with it {score(forced).mean():.3f} m, without it "
            f"{score(loops).mean():.3f} m"
        ).wait_for(timeout=30000)
        scroll_to(page.get_by_text(scene.SECOND_PEAK.label).first)
        page.screenshot(path=str(tmp_path / "loop-candidate.png"))

        a = next(n for n, c in enumerate(loops.closures) if c.verdict is Verdict.ACCEPTED)
        pick(a)
        page.get_by_text("taking it out moves the scans").wait_for(timeout=30000)
        page.get_by_role("button", name="reject this closure").click()
        page.get_by_text("rejected by hand (its match: accepted)").first.wait_for(timeout=30000)
        rejected = session.state.source.loops
        assert rejected.closures[a].verdict is Verdict.SET_ASIDE
        assert np.allclose(score(rejected), score(loops.decided({a: False})))
        page.get_by_role("button", name="show the run").click()
        legend.get_by_text(scene.CLOSURE[Verdict.SET_ASIDE].label).wait_for(timeout=30000)
        page.get_by_text(
            f"with the loops closed: translation {score(rejected).mean():.3f} m"
        ).wait_for(timeout=30000)
        page.screenshot(path=str(tmp_path / "loop-rejected.png"))
        page.close()
    finally:
        application.stop()
