"""mbicp-viz core: scans, SE(2), and the scan matchers with their per-iteration event stream.

numpy, scipy and numba only: no I/O, no front ends. Installed as ``mbicp_viz.core``.

The names below load their module on first use (PEP 562), so that importing the package — as
every command-line ``--help`` does — compiles no kernel and loads neither scipy nor numba.
"""

from __future__ import annotations

import importlib

# a checkout's folder on sys.path must not pose as a package `core`
if __name__ != "mbicp_viz.core":
    raise ImportError("the matchers of mbicp-viz are imported as mbicp_viz.core, not as 'core'")

_EXPORTS = {
    "events": (
        "Correspondences",
        "Event",
        "FinishEvent",
        "HeldDirection",
        "IterationEvent",
        "Observer",
        "PairKind",
        "PairStatus",
        "PolarStep",
        "Recorder",
        "Resampling",
        "StartEvent",
        "broadcast",
    ),
    "matchers": ("MATCHERS", "Matcher", "match", "matcher_for"),
    "params": (
        "FieldSpec",
        "IcpParams",
        "ImprovedParams",
        "MbicpParams",
        "ParamError",
        "Params",
        "PlIcpParams",
        "PmwnParams",
        "SearchParams",
        "PsmParams",
        "field_specs",
    ),
    "result": ("Degeneracy", "MatchResult", "Termination"),
    "errors": ("ScanError", "ScanSource", "UnusableScan"),
    "deskew": ("deskew", "twist"),
    "scan": ("Scan", "bearing_layout", "make_scan", "uniform_bearings"),
    "se2": ("Pose2", "pose_error", "relative", "wrap_angle"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = sorted(_MODULE_OF)


def __getattr__(name: str):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
