import atexit
import contextlib
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

from mbicp_viz.readers import read_log

# The suite's numbers must not depend on how far a background compile has come: every process it
# starts compiles its kernels itself (core/tiers.py; tests/test_tiers.py starts the quick tier).
os.environ["MBICP_VIZ_JIT"] = "eager"
# Logs read whole are cached (readers/log_cache.py): the suite's own cache, never the user's,
# removed when the process that made it ends (xdist's workers inherit it from the controller).
if "MBICP_VIZ_CACHE" not in os.environ:
    os.environ["MBICP_VIZ_CACHE"] = tempfile.mkdtemp(prefix="mbicp-viz-cache-")
    atexit.register(shutil.rmtree, os.environ["MBICP_VIZ_CACHE"], ignore_errors=True)

# No deadline: a test's first example may compile a matcher's kernels (numba), which takes
# seconds on a cold cache; a deadline there measures the compiler, not the code.
settings.register_profile("mbicp-viz", deadline=None)
settings.load_profile("mbicp-viz")

DATA = Path(__file__).parent / "data"
EXAMPLES = Path(__file__).parent.parent / "mbicp_viz" / "examples"
INTEL = EXAMPLES / "intel-excerpt.log.gz"
LASERAZOS = DATA / "laserazosSM3-40.log"
HOKUYO_BAG = DATA / "hokuyo-demo.bag"
# the rerun CLI of the environment running the tests (the wheel installs it beside python)
RERUN = str(Path(sys.executable).parent / "rerun")


def rerun_binary() -> str:
    """The viewer's own binary: the ``rerun`` on PATH is a Python wrapper that starts it as a child,
    which a kill of the wrapper leaves running (~290 MB each)."""
    import rerun_cli

    binary = Path(rerun_cli.__file__).parent / "rerun"
    return str(binary) if binary.is_file() else RERUN


def wait_for(cond, timeout: float = 30.0) -> bool:
    """Whether ``cond()`` becomes true within ``timeout`` seconds (polled, never a fixed sleep)."""
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.05)
    return False


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def rerun_viewer(size: str = "1400x900"):
    """rerun's own viewer, headless, on a free loopback port, driven through its (experimental)
    ViewerClient: open a file, move the time cursor, screenshot a view. Stopped on the way out."""
    import os
    import signal
    import subprocess
    import tempfile
    import time

    from rerun.experimental import ViewerClient

    port = free_port()
    log = tempfile.TemporaryFile()
    proc = subprocess.Popen(
        [rerun_binary(), "--headless", "--port", str(port), "--bind", "127.0.0.1"]
        + ["--window-size", size],
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,  # its own process group: killed whole, whatever it starts
    )
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                client = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")
                client.get_state()
                break
            except Exception as e:  # not listening yet
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(viewer_failure(log, proc.poll())) from e
                time.sleep(0.2)
        yield client
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        log.close()


def viewer_failure(log, code) -> str:
    """Why rerun's headless viewer did not answer: the driver it lacks, else its output."""
    log.seek(0)
    text = log.read().decode(errors="replace")
    if any(w in text.lower() for w in ("vulkan", "no suitable adapter", "wgpu")):
        hint = "rerun's headless viewer needs a Vulkan driver (Debian: mesa-vulkan-drivers)"
    else:
        hint = "rerun's headless viewer did not answer"
    state = "running" if code is None else f"exit code {code}"
    return f"{hint} ({state}); its output ends: {text[-600:]}"


def settled_screenshot(client, path, view_id=None, timeout: float = 30.0):
    """A screenshot of the viewer (or one view) once it stops changing: after a time change a view
    can take a few frames to fit its data."""
    import time

    from PIL import Image

    last, deadline = None, time.monotonic() + timeout
    while time.monotonic() < deadline:
        client.save_screenshot(str(path), view_id)
        img = np.asarray(Image.open(path).convert("RGB"))
        if last is not None and last.shape == img.shape and np.array_equal(last, img):
            return img.astype(int)
        last = img
    return last.astype(int)


def viewer_screenshot(rrd, shot, size: str = "1400x900") -> np.ndarray:
    """What rerun's own viewer (headless) draws of ``rrd`` once loaded and settled, as RGB pixels
    (also saved to ``shot``)."""
    import time

    with rerun_viewer(size) as viewer:
        viewer.open(str(rrd))
        deadline = time.monotonic() + 60
        while viewer.get_state().loading and time.monotonic() < deadline:
            time.sleep(0.1)
        return settled_screenshot(viewer, shot)


os.environ.setdefault("RERUN_ANALYTICS", "0")


@pytest.fixture(scope="session")
def intel():
    return read_log(INTEL)


@pytest.fixture(scope="session")
def laserazos():
    return read_log(LASERAZOS)


@pytest.fixture(scope="session")
def hokuyo():
    return read_log(HOKUYO_BAG)


@contextlib.contextmanager
def interpreted_kernels():
    """This process in core/tiers.py's quick start with a background compile "running" (a lock
    held here): every kernel runs interpreted inside the block."""
    import fcntl
    import tempfile

    from mbicp_viz.core import tiers

    t = tiers._TIERS
    saved = t.quick, t.lock, t.ready
    with tempfile.TemporaryDirectory() as d, open(Path(d) / tiers.LOCK_NAME, "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        t.quick, t.lock, t.ready = True, Path(held.name), set()
        try:
            yield
        finally:
            t.quick, t.lock, t.ready = saved


def json_lines(path) -> list[dict]:
    """The objects of a JSON lines file (rows files), in order."""
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]
