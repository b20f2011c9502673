"""The compiled kernels, and the same kernels interpreted while numba compiles them.

numba compiles a kernel at its first call and keeps the machine code in its cache (beside the
module, or under ``NUMBA_CACHE_DIR``). The matchers' loops take 9 s (improved MbICP) to about 26 s
(all six: the background compile as last measured) on a 2-core machine: after an install, a
person's first match would stall that long. So there are two tiers, as in a JIT-compiled
language runtime:

- **eager** (the default, and what batch work wants: evaluations, tuning, tests): a kernel is
  compiled, or loaded from the cache, at its first call, in this process — numba as it is.
- **quick start** (the front ends a person waits on: ``match`` and the debugger call
  ``quick_start()``): a kernel missing from the cache runs *interpreted* — the very same Python
  function, its callees interpreted too — while one background process compiles every kernel
  into the cache (``python -m mbicp_viz.core.warmup``). Once that process has ended, calls go to
  the compiled code again. Interpreted is ~100x slower (0.35 s for improved MbICP on the bundled
  681-beam pair) and computes the same arithmetic in the same order: equal poses and iteration
  counts (to ~1e-14 where numpy reduces in another order; tests/test_tiers.py). A process that
  cannot start the background compile (no ``fcntl``: not POSIX; a cache it cannot write) stays
  eager.

``MBICP_VIZ_JIT=eager`` in the environment keeps a process eager even where a front end asks for
quick start (the test suite sets it: its numbers must not depend on a compile's progress).

Python code calls a kernel through ``run(kernel, *args)``; compiled code calls kernels directly.
"""

from __future__ import annotations

import functools
import os
import pickle
import subprocess
import sys
import threading
import types
from pathlib import Path

import numpy as np
from numba import njit, vectorize
from numba.core.dispatcher import Dispatcher
from numba.np.ufunc.dufunc import DUFunc

try:
    import fcntl
except ImportError:  # not POSIX: no background compile, every process eager
    fcntl = None

LOCK_NAME = "mbicp-viz-compiling.lock"  # held by the background compile while it runs
# What the front ends say while it runs (the command line on stderr, the debugger on its page)
INTERPRETED = (
    "numba is compiling the matchers' kernels in the background (the first run after an install): "
    "until it is done they run interpreted — the same results, slower"
)
_KERNELS: list = []  # every kernel (with a cache entry of its own) of the modules imported so far


def kernel(fn=None, *, inline: str = "never"):
    """A compiled kernel (numba's njit, cached, releasing the GIL): ``@kernel`` or
    ``@kernel(inline="always")``."""
    if fn is None:
        return lambda f: kernel(f, inline=inline)
    # nogil: a match's budget timer and a stop pressed on the page run while it does (budget.py)
    k = njit(cache=True, nogil=True, inline=inline)(fn)
    # an inlined kernel is compiled into its callers only: no cache entry of its own
    if inline == "never":
        _guard_index(k)
        _KERNELS.append(k)
    return k


def elementwise(fn):
    """A compiled scalar kernel that broadcasts as a numpy ufunc (numba's vectorize, cached)."""
    k = vectorize(cache=True)(fn)
    _guard_index(k)
    _KERNELS.append(k)
    return k


def _guard_index(k) -> None:
    """Make numba's cache index of ``k`` read as stale whenever it should, and never raise.

    - numba stamps an index with the kernel's own file only, yet compiled code freezes the
      module-level constants it reads, some from other modules of the core (the cycle period of
      stopping.py in mbicp.py's loop): a change there kept the old machine code. The stamp here
      also covers every module of the kernel's folder.
    - numba unpickles an index before it checks the stamp; an index written by an earlier version
      whose argument types named a class since renamed or removed (a named tuple a loop takes)
      then raises instead of reading as stale, and every match fails. Such an index reads as
      empty, as numba means a stale one to: the kernel compiles anew and overwrites it."""
    index = function_cache(k)._cache_file
    folder = Path(python_function(k).__code__.co_filename).parent
    index._source_stamp = (index._source_stamp, _folder_stamp(folder))
    load = index._load_index

    def tolerant():
        try:
            return load()
        except (AttributeError, ImportError, pickle.UnpicklingError, EOFError):
            return {}

    index._load_index = tolerant


@functools.cache
def _folder_stamp(folder: Path) -> tuple:
    """Name, modification time and size of every module in ``folder`` (numba's own stamp of one
    file, for all of them)."""
    stats = ((f.name, f.stat()) for f in sorted(folder.glob("*.py")))
    return tuple((name, st.st_mtime_ns, st.st_size) for name, st in stats)


class _Tiers:
    """This process's choice between the tiers (one per process)."""

    def __init__(self):
        self.quick = False
        self.lock: Path | None = (
            None  # the background compile's lock, once one was started or found
        )
        self.tried = (
            False  # one background compile per process: after it, kernels compile here if need be
        )
        self.ready: set[int] = set()  # ids of kernels known compiled or cached in this process
        self.twins: dict[int, types.FunctionType] = {}

    def run(self, k, args):
        if self.quick and id(k) not in self.ready:
            if self.compiling() or (not self.tried and not cached(k) and self.start(k)):
                with np.errstate(all="ignore"):  # compiled code wraps and divides without a warning
                    return self.twin(k)(*args)
            # cached, or the background compile ended: numba loads (or compiles)
            self.ready.add(id(k))
        return k(*args)

    def compiling(self) -> bool:
        """Whether the background compile this process relies on still runs."""
        return self.lock is not None and held(self.lock)

    def start(self, k) -> bool:
        """Start the background compile (unless one already runs for this cache); whether one
        runs."""
        self.tried = True
        try:
            self.lock = lock_path(k)
            return start_background(self.lock) or held(self.lock)
        except OSError:  # no lock or no process here: this process compiles for itself
            self.lock = None
            return False

    def twin(self, k) -> types.FunctionType:
        """``k``'s Python function with every kernel it calls replaced by that kernel's twin."""
        twin = self.twins.get(id(k))
        if twin is None:
            f = python_function(k)
            # a copy: numba reads the module's own names when it compiles
            names = dict(f.__globals__)
            twin = self.twins[id(k)] = types.FunctionType(
                f.__code__, names, f.__name__, f.__defaults__, f.__closure__
            )
            for name, value in f.__globals__.items():
                if isinstance(value, (Dispatcher, DUFunc)):
                    names[name] = self.twin(value)
        return twin


_TIERS = _Tiers()


def run(k, *args):
    """Call kernel ``k`` from Python: compiled, or interpreted while the background compile runs."""
    return _TIERS.run(k, args)


def quick_start() -> None:
    """Make this process a front end that never stalls on compilation (see the module's doc)."""
    _TIERS.quick = fcntl is not None and os.environ.get("MBICP_VIZ_JIT", "quick") != "eager"


def compiling() -> bool:
    """Whether kernels of this process run interpreted because the background compile runs."""
    return _TIERS.compiling()


def compile_in_background() -> bool:
    """In quick start, start the background compile now if a kernel imported so far is missing
    from the cache (a front end that knows it will match soon); whether one runs."""
    if _TIERS.compiling():
        return True
    cold = (
        next((k for k in _KERNELS if not cached(k)), None)
        if _TIERS.quick and not _TIERS.tried
        else None
    )
    return cold is not None and _TIERS.start(cold)


def wait_compiled() -> None:
    """Block until the background compile this process started or found has ended (if any)."""
    if _TIERS.lock is not None:
        wait_unlocked(_TIERS.lock)


def wait_unlocked(lock: Path) -> None:
    """Block until no process holds ``lock`` (a background compile's, if the file exists)."""
    if lock.exists():
        with open(lock, "a") as f:
            fcntl.flock(f, fcntl.LOCK_SH)


def lock_path(k) -> Path:
    """The background compile's lock, beside numba's cache of the kernels (they share one
    folder)."""
    return Path(function_cache(k).cache_path) / LOCK_NAME


def function_cache(k):
    """numba's cache object of kernel ``k`` (a ufunc's lives on its dispatcher)."""
    return k._dispatcher.cache if isinstance(k, DUFunc) else k._cache


def python_function(k) -> types.FunctionType:
    return k._dispatcher.py_func if isinstance(k, DUFunc) else k.py_func


def cached(k) -> bool:
    """Whether numba's cache holds machine code for ``k`` that is valid for its source as it is now
    (numba's own index check: a stale entry, from an older file, does not count)."""
    return bool(function_cache(k)._cache_file._load_index())


def held(lock: Path) -> bool:
    """Whether some process holds ``lock`` (the background compile runs)."""
    try:
        with open(lock, "a") as f:
            fcntl.flock(f, fcntl.LOCK_SH | fcntl.LOCK_NB)
            return False
    except BlockingIOError:
        return True


def _package_path() -> str:
    """PYTHONPATH for a child that imports this process's package first: the folder holding it."""
    package = sys.modules[__name__.split(".")[0]]
    root = str(Path(package.__file__).resolve().parent.parent)
    return os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)


def start_background(lock: Path) -> bool:
    """Start ``python -m mbicp_viz.core.warmup`` holding ``lock`` (taken here, so that two front
    ends starting at once start one compile); False if the lock is taken already."""
    lock.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(lock, os.O_WRONLY | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return False
    try:  # the child inherits the locked file (the lock ends when the child does), which names it
        child = subprocess.Popen(
            # -P: not the working folder first, which `-m` would put there: run from a checkout
            # after `pip install .`, the child compiled the checkout's kernels into the checkout's
            # cache and left the installed package's empty. It imports this process's package.
            [sys.executable, "-P", "-m", "mbicp_viz.core.warmup"],
            pass_fds=(fd,),
            start_new_session=True,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=os.environ | {"MBICP_VIZ_JIT": "eager", "PYTHONPATH": _package_path()},
        )
        os.ftruncate(fd, 0)
        os.write(fd, f"{child.pid}\n".encode())
        threading.Thread(
            target=child.wait, daemon=True
        ).start()  # reaped when it ends (a server lives on)
    finally:
        os.close(fd)
    return True
