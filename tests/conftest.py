import os
import sys
from pathlib import Path

import pytest
from hypothesis import settings

from mbicp_viz.readers import read_log

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


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def viewer_screenshot(rrd, shot, size: str = "1400x900"):
    """rerun's own viewer, headless, renders ``rrd`` into ``shot``: on a free loopback port, never
    rerun's default 9876 (where a user's viewer may listen and would receive the file instead)."""
    import subprocess

    return subprocess.run([RERUN, str(rrd), "--headless", "--port", str(free_port()), "--bind", "127.0.0.1",
                           "--window-size", size, "--screenshot-to", str(shot)], capture_output=True, text=True,
                          timeout=180)
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
