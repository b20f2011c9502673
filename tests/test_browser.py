"""The debugger in a real headless Chromium (Debian's, driven by Playwright)."""

import time

import numpy as np
import pytest
from playwright.sync_api import sync_playwright

from core import Pose2
from mbicp_viz.readers import read_log
from mbicp_viz.scene import OBJECT, REFERENCE
from mbicp_viz.viser_app import App, Source

from .conftest import EXAMPLES

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run"]


@pytest.fixture(scope="module")
def app():
    a = App(Source("hokuyo pair", read_log(EXAMPLES / "hokuyo-125-130.npz"), guess=Pose2()), "127.0.0.1", 0)
    yield a
    a.stop()


@pytest.fixture(scope="module")
def browser():
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


def wait_for(cond, timeout=30.0):
    deadline = time.time() + timeout
    while time.time() < deadline:
        if cond():
            return True
        time.sleep(0.1)
    return False


def open_tab(browser, app):
    before = set(app.sessions)
    page = browser.new_page(viewport={"width": 1400, "height": 900}, accept_downloads=True)
    page.goto(f"http://127.0.0.1:{app.port}")
    page.get_by_role("slider").first.wait_for(timeout=60000)
    assert wait_for(lambda: set(app.sessions) - before)
    session = app.sessions[(set(app.sessions) - before).pop()]
    assert wait_for(lambda: bool(session.runs))
    return page, session


def test_slider_parameter_export_and_colours(browser, app, tmp_path):
    page, session = open_tab(browser, app)
    n = session.max_iteration()
    assert n > 5
    # move the iteration slider with the keyboard, as a user would
    slider = page.get_by_role("slider").first
    slider.focus()
    slider.press("Home")
    assert wait_for(lambda: session.iteration == 0)
    slider.press("ArrowRight")
    slider.press("ArrowRight")
    assert wait_for(lambda: session.iteration == 2)
    page.get_by_text("iteration 2:").first.wait_for(timeout=10000)
    # change a parameter: the match re-runs and the result panel changes in the page
    box = page.get_by_label("MaxIter")
    box.fill("4")
    box.press("Enter")
    assert wait_for(lambda: session.max_iteration() == 4)
    page.get_by_text("after 4 iterations").first.wait_for(timeout=10000)
    # export: the browser downloads a real .rrd that reads back
    with page.expect_download(timeout=30000) as dl:
        page.get_by_role("button", name="export .rrd").click()
    path = tmp_path / "session.rrd"
    dl.value.save_as(path)
    from rerun.chunk import RrdReader

    entities = {c.entity_path for c in RrdReader(str(path)).stream().to_chunks()}
    assert "/improved/scene/reference" in entities and "/improved/scene/pairs/point" in entities
    # the picture: reference red, object blue
    shot = tmp_path / "page.png"
    time.sleep(1.0)
    page.screenshot(path=str(shot))
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    near = lambda rgb: int(np.count_nonzero(np.abs(img - np.array(rgb)).max(axis=2) < 45))  # noqa: E731
    assert near(REFERENCE) > 100 and near(OBJECT) > 100
    page.close()


def test_two_tabs_keep_their_own_state(browser, app):
    p1, s1 = open_tab(browser, app)
    p2, s2 = open_tab(browser, app)
    assert s1 is not s2
    box = p2.get_by_label("MaxIter")
    box.fill("2")
    box.press("Enter")
    assert wait_for(lambda: s2.max_iteration() == 2)
    assert s1.params["improved"].MaxIter == 100 and s1.max_iteration() > 2
    p2.get_by_role("slider").first.focus()
    p2.get_by_role("slider").first.press("Home")
    assert wait_for(lambda: s2.iteration == 0)
    assert s1.iteration == s1.max_iteration()
    p1.close()
    p2.close()
