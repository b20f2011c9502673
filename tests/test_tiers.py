"""The kernels' two tiers (core/tiers.py): interpreted while numba compiles them in a background
process, compiled after; a first match after an install that does not wait for the compiler."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from mbicp_viz.core import MATCHERS, Pose2, Recorder, tiers
from mbicp_viz.readers import read_log
from mbicp_viz.readers.params_toml import make_params

from .conftest import EXAMPLES, INTEL, interpreted_kernels, wait_for

HOKUYO = EXAMPLES / "hokuyo-125-130.npz"


def _cases():
    """Real pairs from guesses off the answer: the Hokuyo pair, two Intel corridor pairs."""
    hokuyo, intel = read_log(HOKUYO), read_log(INTEL)
    return [
        (hokuyo.scans[0], hokuyo.scans[1], Pose2(0.05, -0.02, -0.25)),
        (intel.scans[3], intel.scans[4], Pose2(0.1, 0.05, 0.1)),
        (intel.scans[10], intel.scans[11], Pose2(-0.1, 0.1, -0.15)),
    ]


@pytest.mark.parametrize("name", list(MATCHERS))
def test_interpreted_kernels_compute_what_the_compiled_ones_do(name):
    """Same poses (numpy may sum in another order than the compiled loop: 1e-12), iterations,
    ending and recorded iterations, on real scans."""
    m = MATCHERS[name]
    for ref, obj, guess in _cases():
        compiled, events = m.run(ref, obj, guess, m.params_type()), Recorder()
        with interpreted_kernels():
            assert tiers.compiling()
            interpreted = m.run(ref, obj, guess, m.params_type(), events)
        assert np.allclose(
            interpreted.pose.as_array(), compiled.pose.as_array(), rtol=0, atol=1e-12
        )
        assert (interpreted.iterations, interpreted.reason) == (
            compiled.iterations,
            compiled.reason,
        )
        assert len(events.iterations) == compiled.iterations


@pytest.mark.parametrize("option", ["poor-guess", "hold-corridor"])
def test_interpreted_kernels_follow_the_compiled_ones_through_improved_mbicps_options(option):
    """The options' code paths too (extrapolated steps, held directions): the same iterations."""
    params = make_params("improved", option)
    for ref, obj, guess in _cases():
        compiled, events = MATCHERS["improved"].run(ref, obj, guess, params), Recorder()
        with interpreted_kernels():
            interpreted = MATCHERS["improved"].run(ref, obj, guess, params, events)
        assert np.allclose(
            interpreted.pose.as_array(), compiled.pose.as_array(), rtol=0, atol=1e-12
        )
        assert (interpreted.iterations, interpreted.reason) == (
            compiled.iterations,
            compiled.reason,
        )


def _background_pid(cache) -> int | None:
    """The pid the background compile's lock names, while it holds the lock."""
    locks = list(cache.rglob(tiers.LOCK_NAME))
    return int(locks[0].read_text()) if locks and tiers.held(locks[0]) else None


def test_a_first_match_after_an_install_answers_at_once_and_the_next_ones_run_compiled(tmp_path):
    """The quick tier end to end, as after ``pip install``: an empty kernel cache, the real command.
    The first match runs interpreted (and says so) while one background process compiles every
    kernel; after it, matching real scans with every matcher compiles nothing."""
    env = {k: v for k, v in os.environ.items() if k != "MBICP_VIZ_JIT"} | {
        "NUMBA_CACHE_DIR": str(tmp_path)
    }
    command = [
        sys.executable,
        "-m",
        "mbicp_viz",
        "match",
        str(HOKUYO),
        "--pair",
        "0",
        "1",
        "--guess",
        "identity",
        "--json",
    ]
    expected = MATCHERS["improved"].run(
        *[read_log(HOKUYO).scans[i] for i in (0, 1)], Pose2(), MATCHERS["improved"].params_type()
    )
    try:
        t0 = time.monotonic()
        first = subprocess.run(command, env=env, capture_output=True, text=True, timeout=120)
        took = time.monotonic() - t0
        assert first.returncode == 0, first.stderr
        assert "compiling the matchers' kernels in the background" in first.stderr
        row = json.loads(first.stdout)
        assert np.allclose(
            [row["x"], row["y"], row["theta"]], expected.pose.as_array(), rtol=0, atol=1e-12
        )
        assert row["iterations"] == expected.iterations and row["interpreted"] is True
        assert _background_pid(tmp_path) is not None, f"no background compile ({took:.1f} s)"
        assert wait_for(lambda: _background_pid(tmp_path) is None, timeout=300)
        second = subprocess.run(command, env=env, capture_output=True, text=True, timeout=120)
        assert second.returncode == 0 and "background" not in second.stderr
        assert json.loads(second.stdout) == row | {
            "time_ms": json.loads(second.stdout)["time_ms"],
            "interpreted": False,
        }
        check = (
            "from numba.core import event\n"
            "from tests.test_tiers import _cases\n"
            "from mbicp_viz.core import MATCHERS, Recorder\n"
            "with event.install_recorder('numba:compile') as rec:\n"
            "    for ref, obj, guess in _cases():\n"
            "        for m in MATCHERS.values():\n"
            "            m.run(ref, obj, guess, m.params_type()); m.run(ref, obj, guess, "
            "m.params_type(), Recorder())\n"
            "print(len(rec.buffer))\n"
        )
        compiled = subprocess.run(
            [sys.executable, "-c", check],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
            cwd=str(EXAMPLES.parent.parent),
        )
        assert compiled.returncode == 0 and compiled.stdout.split() == ["0"], (
            compiled.stdout + compiled.stderr
        )
    finally:
        pid = _background_pid(tmp_path)
        if pid is not None:
            os.killpg(pid, signal.SIGTERM)
            wait_for(lambda: _background_pid(tmp_path) is None, timeout=30)


def test_the_debugger_after_an_install_compiles_nothing_in_its_own_process(tmp_path):
    """Its first tab draws and matches interpreted while the background process compiles: no kernel
    (the first scan's points for the camera included) compiles in the debugger's process, where a
    person would wait for it."""
    env = {k: v for k, v in os.environ.items() if k != "MBICP_VIZ_JIT"} | {
        "NUMBA_CACHE_DIR": str(tmp_path)
    }
    script = (
        "from numba.core import event\n"
        "from mbicp_viz.views.debugger.latency import first_result_at\n"
        "with event.install_recorder('numba:compile') as rec:\n"
        f"    first_result_at({str(HOKUYO)!r})\n"
        "print(len(rec.buffer))\n"
    )
    try:
        run = subprocess.run(
            [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120
        )
        assert run.returncode == 0, run.stderr
        assert run.stdout.split()[-1:] == ["0"], run.stdout + run.stderr
        assert _background_pid(tmp_path) is not None  # the compile it relies on runs elsewhere
    finally:
        pid = _background_pid(tmp_path)
        if pid is not None:
            os.killpg(pid, signal.SIGTERM)
            wait_for(lambda: _background_pid(tmp_path) is None, timeout=30)


def test_the_background_compile_imports_the_package_of_its_parent(tmp_path):
    """Run from a folder that holds another mbicp_viz (a checkout, after `pip install .`), the
    background compile compiled that one into its cache instead of the one running."""
    decoy = tmp_path / "checkout" / "mbicp_viz"
    decoy.mkdir(parents=True)
    marker = tmp_path / "the decoy was imported"
    (decoy / "__init__.py").write_text(f"open({str(marker)!r}, 'w').close()\n")
    code = (
        "from pathlib import Path\n"
        "from mbicp_viz.core import tiers\n"
        f"lock = Path({str(tmp_path / 'compile.lock')!r})\n"
        "assert tiers.start_background(lock)\n"
        "tiers.wait_unlocked(lock)\n"  # until the child has ended
    )
    # -P: this parent imports the package under test, as the console script does from any folder
    res = subprocess.run(
        [sys.executable, "-P", "-c", code],
        cwd=decoy.parent,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr
    assert not marker.exists()


LOOP_MODULE = """
from typing import NamedTuple

import numpy as np

from mbicp_viz.core.tiers import kernel


class {name}(NamedTuple):
    scale: float
    values: np.ndarray


@kernel
def total(p):
    return p.scale * p.values.sum()


print(total({name}(2.0, np.arange(4.0))))
"""


def _printed_on_import(tmp_path, module: str) -> str:
    """What importing ``module`` (from ``tmp_path``) prints in a fresh process whose numba cache is
    ``tmp_path / "cache"``."""
    env = os.environ | {
        "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
        "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path]),
    }
    run = subprocess.run(
        [sys.executable, "-c", f"import {module}"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, run.stderr
    return run.stdout.strip()


def test_a_cache_naming_a_class_since_renamed_is_compiled_anew(tmp_path):
    """A kernel that takes a named tuple, cached, then its class renamed (an upgrade): numba's index
    of the old source names a class that is gone. The next run compiles anew instead of failing
    (numba unpickles an index before it checks that the index is this source's)."""
    module = tmp_path / "loop_of_an_old_version.py"
    outputs = []
    for name in ("Params", "Params", "RenamedParams"):  # compiled, loaded from cache, renamed
        module.write_text(LOOP_MODULE.format(name=name))
        outputs.append(_printed_on_import(tmp_path, "loop_of_an_old_version"))
    assert outputs == ["12.0"] * 3
    assert any((tmp_path / "cache").rglob("*.nbi"))  # the kernel was cached


def test_a_cached_kernel_is_compiled_anew_when_a_constant_it_reads_from_another_module_changes(
    tmp_path,
):
    """mbicp.py's compiled loop freezes stopping.py's cycle period, and numba stamps a kernel's
    cache with the kernel's own file alone: an edit of the period kept the old machine code. Here
    a kernel returns a constant of a module beside it; the constant changes between two runs."""
    package = tmp_path / "loops_of_a_package"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "loop.py").write_text(
        "from mbicp_viz.core.tiers import kernel\n"
        "from .limits import PERIOD\n\n\n"
        "@kernel\n"
        "def period():\n"
        "    return PERIOD\n\n\n"
        "print(period())\n"
    )
    outputs = []
    for period in (4, 4, 12):  # compiled, loaded from the cache, the constant changed
        (package / "limits.py").write_text(f"PERIOD = {period}\n")
        outputs.append(_printed_on_import(tmp_path, "loops_of_a_package.loop"))
    assert outputs == ["4", "4", "12"]
    assert any((tmp_path / "cache").rglob("*.nbi"))  # the kernel was cached


def test_a_runs_kernels_are_loaded_before_its_first_pair():
    """``load_kernels`` loads, for each matcher, every kernel a real pair's match and record call
    (so a pool's forked workers share them, and the run's pace leaves out loading them): matching
    a real pair afterwards loads none."""
    check = (
        "from mbicp_viz.core import MATCHERS, tiers\n"
        "from mbicp_viz.core.warmup import load_kernels\n"
        "from mbicp_viz.evaluation.single import match_pair\n"
        "from mbicp_viz.readers import read_log\n"
        f"log = read_log({str(EXAMPLES / 'intel-excerpt.log.gz')!r})\n"
        "def loaded():\n"
        "    return {k.__name__: len(getattr(k, 'overloads', getattr(k, 'types', ())))\n"
        "            for k in tiers._KERNELS}\n"
        "for m in MATCHERS.values():\n"
        "    load_kernels(m.params_type())\n"
        "    before = loaded()\n"
        "    match_pair(log.scan(0), log.scan(1), m.params_type())\n"
        "    print(m.name, sorted(k for k, n in loaded().items() if n != before.get(k)))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", check], capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[:-1] == [f"{name} []" for name in MATCHERS], done.stdout
