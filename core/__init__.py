"""mbicp-viz core: scans, SE(2), and the scan matchers with their per-iteration event stream.

numpy and scipy only: no I/O, no front ends.
"""

from .events import (Correspondences, Event, FinishEvent, IterationEvent, Observer, PairKind, PairStatus,
                     PolarStep, Recorder, Resampling, StartEvent, broadcast)
from .matchers import MATCHERS, Matcher, match, matcher_for
from .params import (FieldSpec, IcpParams, ImprovedParams, MbicpParams, ParamError, Params, PmwnParams, PsmParams,
                     field_specs)
from .result import Degeneracy, MatchResult, Termination
from .scan import Scan, ScanError, ScanSource, make_scan, scan_from_points, uniform_bearings
from .se2 import Pose2, pose_error, relative, wrap_angle

__all__ = [
    "Correspondences", "PolarStep", "Event", "Observer", "broadcast", "FinishEvent", "IterationEvent", "PairKind", "PairStatus", "Recorder", "Resampling",
    "StartEvent", "MATCHERS", "Matcher", "match", "matcher_for", "FieldSpec", "IcpParams", "ImprovedParams",
    "MbicpParams", "PsmParams", "PmwnParams", "ParamError", "Params", "field_specs", "Degeneracy", "MatchResult", "Termination", "Scan",
    "ScanError", "ScanSource", "make_scan", "scan_from_points", "uniform_bearings", "Pose2", "pose_error",
    "relative", "wrap_angle",
]
