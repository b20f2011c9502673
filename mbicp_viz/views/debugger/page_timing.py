"""``bench page``: how soon a person sees the run view, the way they open it — ``mbicp-viz serve
LOG --rows ROWS`` started as a command, its page loaded in a browser already running (a headless
Chromium driven by Playwright, the test extra's), until the page shows the run's legend — and how
long a step of its slider takes there, timed by the page itself from the key to the pair's
numbers shown and the scene drawn (``STEP_TIMER``). The server side alone is ``bench run``.

Without a GPU the browser draws WebGL in software, and viser's page draws every frame of the quarter
second after a change: a step's time is then mostly frames, and a step made while the frames of the
one before are still drawn waits for them. So steps are timed two ways, one right after another
(scrubbing) and from a page at rest (``REST_S``); the bench says which renderer drew (the fastest
found, ``launch_drawing``) and times the same steps on a bare viser page, a slider and one small
cloud (``bare_page_steps``): what no run view can go below in this browser."""

from __future__ import annotations

import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.bench import Timing
from mbicp_viz.views import scene

# what Chromium needs here to draw WebGL without a GPU (the browser tests' flags start with them):
# its own SwiftShader, which every Chromium has
CHROMIUM_ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox"]
# Mesa's llvmpipe through EGL, where the machine has Mesa's EGL (Debian's libegl-mesa0): a run
# view's slider step 0.28 s against SwiftShader's 0.56 s here, both in software
MESA_ARGS = ["--use-gl=angle", "--use-angle=gl-egl", "--ignore-gpu-blocklist", "--no-sandbox"]
# the renderer's own name, empty where the page gets no WebGL 2
RENDERER = """() => { const gl = document.createElement('canvas').getContext('webgl2');
  if (!gl) return ''; const info = gl.getExtension('WEBGL_debug_renderer_info');
  return gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER); }"""
URL = re.compile(r"open (http://\S+)")
FIRST_PAIR = re.compile(r"pair 1 of (\d+)")  # the run view's words on its first pair (run_model)
# Arms the page's own timer of the next step: from the key's keydown to the step's words in the
# page and two frames drawn after them (the one they are painted in, and the next: the scene's
# messages come before the words), in ms; null when the words do not come within the timeout.
# Timed in the page, so the driver's own round trips (Playwright's, about 10-40 ms a step) are
# not counted: a person has none.
STEP_TIMER = """([words, timeoutMs]) => { window.mbicpStep = new Promise((resolve) => {
  let t0 = null;
  const key = () => { if (t0 === null) t0 = performance.now(); };
  const end = (took) => { clearTimeout(timer); observer.disconnect();
    document.removeEventListener('keydown', key, true); resolve(took); };
  const observer = new MutationObserver(() => {
    if (t0 === null || !document.body.textContent.includes(words)) return;
    observer.disconnect();
    requestAnimationFrame(() => requestAnimationFrame(() => end(performance.now() - t0)));
  });
  document.addEventListener('keydown', key, true);
  observer.observe(document.body, { subtree: true, childList: true, characterData: true });
  const timer = setTimeout(() => end(null), timeoutMs);
}); }"""
STEP_TAKEN = "() => window.mbicpStep"
# A page at rest: longer than the quarter second of frames viser's page draws after a change
REST_S = 0.5
STEP_KINDS = ("in a row", "at rest")  # ``slider_steps``' two lists, in order
VIEWPORT = {"width": 1400, "height": 900}


def find_chromium(path: str | None) -> str:
    """The browser to drive: ``path`` (never another in its place), else Chromium on the PATH."""
    if path is not None:
        if (found := shutil.which(path)) is None:
            raise InputError(f"no browser to run at {path!r}", field="--browser")
        return found
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        raise InputError("no Chromium found (Debian: apt-get install chromium)", field="--browser")
    return found


@contextmanager
def serving(args: list[str], timeout_s: float) -> Iterator[tuple[str, float]]:
    """``mbicp-viz ARGS`` started in a process group of its own: its page's address and when it
    printed it [s since the start]. Ended with Ctrl-C (SIGINT), then killed if it lingers."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "mbicp_viz", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    lines: queue.Queue[str | None] = queue.Queue()

    def read() -> None:  # a server that says nothing must not hold the bench past its timeout
        for line in proc.stdout:
            lines.put(line)
        lines.put(None)

    threading.Thread(target=read, daemon=True).start()
    try:
        said = ["nothing"]
        while (left := timeout_s - (time.perf_counter() - t0)) > 0:
            try:
                line = lines.get(timeout=left)
            except queue.Empty:
                break
            if line is None:  # it ended
                break
            said.append(line.strip())
            if m := URL.search(line):
                yield m.group(1), time.perf_counter() - t0
                return
        raise InputError(f"serve did not open a page; its last words: {said[-1]}")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


def launch_drawing(playwright, exe: str):
    """Chromium at ``exe`` drawing WebGL with the fastest software renderer it has here (Mesa's,
    else SwiftShader), and that renderer's name."""
    for args in (MESA_ARGS, CHROMIUM_ARGS):
        browser = playwright.chromium.launch(executable_path=exe, args=args)
        page = browser.new_page()
        name = page.evaluate(RENDERER)
        page.close()
        if name:
            return browser, name
        browser.close()
    raise InputError(
        f"{exe} draws no WebGL here, neither with Mesa nor SwiftShader", field="--browser"
    )


def bare_page_steps(chromium, steps: int, timeout_s: float) -> tuple[list[float], list[float]]:
    """``slider_steps`` on a bare viser page: a slider whose step redraws one cloud of 200 points
    and says the pair it is on, as the run view's does, lit as the run view is. Its steps are
    this browser's floor."""
    from .app import stop_server, viser_server

    server = viser_server("127.0.0.1", 0)
    try:
        n, rng = 2 * steps + 1, np.random.default_rng(0)
        slider = server.gui.add_slider("pair", min=1, max=n, step=1, initial_value=1)
        words = server.gui.add_markdown(f"pair 1 of {n}")
        cloud = server.scene.add_point_cloud("/pair", rng.random((200, 3)), colors=(255, 0, 0))

        @slider.on_update
        def _(_) -> None:
            cloud.points = rng.random((200, 3))
            words.content = f"pair {slider.value} of {n}"

        page = chromium.new_page(viewport=VIEWPORT)
        page.goto(f"http://127.0.0.1:{server.get_port()}", timeout=1000 * timeout_s)
        took = slider_steps(page, steps, timeout_s)
        page.close()
        return took
    finally:
        stop_server(server)


def slider_steps(page, steps: int, timeout_s: float) -> tuple[list[float], list[float]]:
    """Steps of the run view's slider as a person makes them (the right arrow on it), each timed
    by the page (``STEP_TIMER``) [s]: up to ``steps`` one right after another, then as many from
    the page at rest."""
    first = page.get_by_text(FIRST_PAIR).first
    first.wait_for(timeout=1000 * timeout_s)
    n = int(FIRST_PAIR.search(first.inner_text())[1])
    slider = page.locator(f'[role=slider][aria-valuemin="1"][aria-valuemax="{n}"]').first
    slider.focus()
    at = 1

    def step(rest_s: float) -> float:
        nonlocal at
        at += 1
        # the pause a step from rest needs (not a wait for a result)
        page.wait_for_timeout(1000 * rest_s)
        page.evaluate(STEP_TIMER, [f"pair {at} of {n}", 1000 * timeout_s])
        slider.press("ArrowRight")
        took = page.evaluate(STEP_TAKEN)
        if took is None:
            raise InputError(f"the page did not show pair {at} of {n} within {timeout_s} s")
        return took / 1000.0

    scrubbed = [step(0.0) for _ in range(min(steps, (n - 1) // 2))]
    return scrubbed, [step(REST_S) for _ in scrubbed]


def page_timings(
    log: str,
    rows: str,
    repeat: int,
    browser: str | None = None,
    topic: str | None = None,
    steps: int = 10,
    timeout_s: float = 120.0,
) -> tuple[str, list[Timing]]:
    """The renderer that drew (``launch_drawing``) and, from the command to the run view on the
    page, ``repeat`` times: the server listening, the page loaded, the run view shown (its
    legend's run trajectory entry) [ms], then ``steps`` slider steps one after another and as
    many from the page at rest each time (``slider_steps``), and as many on a bare viser page
    (``bare_page_steps``); and the browser's own start, once.
    ``topic``: the scan stream of a log with several (``serve --topic``)."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        raise InputError(
            "bench page drives a browser with Playwright: pip install '.[test]'", field="--browser"
        ) from None
    exe = find_chromium(browser)
    parts: dict[str, list[float]] = {"listening": [], "page loaded": [], "run view shown": []}
    # run view's and bare page's steps, one after another and from the page at rest
    stepped: dict[str, list[float]] = {
        f"{view} step, {how}": [] for view in ("run view", "bare page") for how in STEP_KINDS
    }
    with sync_playwright() as p:
        t0 = time.perf_counter()
        chromium, renderer = launch_drawing(p, exe)
        started = 1000.0 * (time.perf_counter() - t0)
        args = ["serve", log, "--rows", rows, "--port", "0"] + (["--topic", topic] if topic else [])
        try:
            for _ in range(repeat):
                with serving(args, timeout_s) as (url, listening):
                    t0 = time.perf_counter() - listening
                    page = chromium.new_page(viewport=VIEWPORT)
                    page.goto(url, timeout=1000 * timeout_s)
                    loaded = time.perf_counter() - t0
                    legend = page.locator(".mbicp-legend")
                    legend.get_by_text(scene.RUN_TRAJECTORY.label).first.wait_for(
                        timeout=1000 * timeout_s
                    )
                    shown = time.perf_counter() - t0
                    for how, took in zip(STEP_KINDS, slider_steps(page, steps, timeout_s)):
                        stepped[f"run view step, {how}"] += took
                    page.close()
                for name, t in zip(parts, (listening, loaded, shown), strict=True):
                    parts[name].append(1000.0 * t)
                if steps:  # alternated with the run view's: a drift in speed falls on both
                    for how, took in zip(STEP_KINDS, bare_page_steps(chromium, steps, timeout_s)):
                        stepped[f"bare page step, {how}"] += took
        finally:
            chromium.close()
    timings = [Timing("browser started", np.array([started]), "starts")]
    timings += [Timing(name, np.array(t), "opens") for name, t in parts.items()]
    timings += [  # a run of one pair has no step to make
        Timing(name, 1000.0 * np.array(t), "steps") for name, t in stepped.items() if t
    ]
    return renderer, timings
