"""mbicp-viz: an interactive visual debugger and teaching tool for 2-D laser scan matching.

From Python: ``import mbicp_viz as mv``, then ``mv.read_log``, ``mv.match``, ``mv.run``,
``mv.write_rrd``, ``mv.show``, ``mv.open_debugger`` ... (``api.py``; ``docs/api.md``). The names
load their module on first use (PEP 562): importing the package, as every ``--help`` does, loads
neither numpy nor the matchers.

Rooms, by role: ``core`` (the matchers and their events; no I/O), ``readers`` (file formats),
``evaluation`` (protocols, criteria, sequences), ``views`` (the scene mapping, rerun, the viser
debugger) and ``cli`` (thin glue, one module per command group).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
from pathlib import Path

# Top-level folders of a checkout that are installed inside this package (pyproject.toml's
# package-dir; a test keeps the two in step). Run from a checkout, this finder gives them the
# names they have once installed, so `mbicp_viz.core` means the same module everywhere.
CHECKOUT_PACKAGES = {"mbicp_viz.core": "core"}
_HERE = Path(__file__).resolve().parent


class _CheckoutFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        folder = CHECKOUT_PACKAGES.get(name)
        init = _HERE.parent / folder / "__init__.py" if folder else None
        if init is None or not init.is_file():
            return None
        return importlib.util.spec_from_file_location(
            name, init, submodule_search_locations=[str(init.parent)]
        )


def __getattr__(name: str):
    # a submodule's name is asked for while it is imported (``from mbicp_viz import cli``)
    if name.startswith("_") or (_HERE / name).is_dir() or (_HERE / f"{name}.py").is_file():
        raise AttributeError(name)
    api = importlib.import_module(f"{__name__}.api")
    if name not in api.__all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(api, name)


def __dir__() -> list[str]:
    api = importlib.import_module(f"{__name__}.api")
    return sorted({*globals(), *api.__all__})


if not (_HERE / "core").is_dir():  # a checkout (installed, core/ sits inside the package)
    sys.meta_path.append(_CheckoutFinder())
