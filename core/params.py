"""Parameter dataclasses: one frozen dataclass per matcher, fields carrying unit, bounds and help.

Every front end (CLI ``--params`` TOML files, the viser panel, the docs) is generated from the
field metadata declared with :func:`param`, so there is one source of truth.
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from dataclasses import dataclass
from typing import Any


class ParamError(ValueError):
    """A parameter value outside its declared type or bounds."""

    def __init__(self, name: str, message: str):
        super().__init__(f"parameter {name!r}: {message}")
        self.name, self.message = name, message

    def __reduce__(self):  # worker processes send errors back pickled; keep the arguments
        return type(self), (self.name, self.message)


def param(
    default,
    *,
    unit: str,
    lo: float | None = None,
    hi: float | None = None,
    help: str,
    tune: tuple[float, float, bool] | None = None,
):
    """A dataclass field with unit ('m', 'rad', '1', 'count', 'bool'), closed bounds and a help
    line; ``tune``: the range (lo, hi, log scale) ``mbicp-viz tune`` searches by default."""
    return dataclasses.field(
        default=default, metadata={"unit": unit, "lo": lo, "hi": hi, "help": help, "tune": tune}
    )


def redefault(cls, name: str, default, help: str | None = None, tuned: bool = True):
    """The field ``name`` of the parameter dataclass ``cls`` with another default (a subclass's
    own value: improved MbICP's windows), its unit, bounds, help and tuning range kept (or the
    help replaced, or the range dropped: a field the subclass does not use by default)."""
    f = next(f for f in dataclasses.fields(cls) if f.name == name)
    m = f.metadata
    return param(
        default,
        unit=m["unit"],
        lo=m["lo"],
        hi=m["hi"],
        help=help or m["help"],
        tune=m["tune"] if tuned else None,
    )


@dataclass(frozen=True)
class FieldSpec:
    name: str
    type: type
    default: Any
    unit: str
    lo: float | None
    hi: float | None
    help: str
    tune: tuple[float, float, bool] | None = (
        None  # (lo, hi, log) searched by ``mbicp-viz tune`` by default
    )


def field_specs(cls) -> list[FieldSpec]:
    """The declared parameters of a parameter dataclass, in declaration order."""
    out = []
    for f in dataclasses.fields(cls):
        m = f.metadata
        out.append(
            FieldSpec(
                f.name,
                type(f.default),
                f.default,
                m["unit"],
                m["lo"],
                m["hi"],
                m["help"],
                m.get("tune"),
            )
        )
    return out


def check_value(spec: FieldSpec, value) -> Any:
    """The value converted to the field's type, or ParamError naming the field."""
    if spec.type is bool:
        if not isinstance(value, bool):
            raise ParamError(spec.name, f"expected true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParamError(spec.name, f"expected a number, got {value!r}")
    if spec.type is int:
        if isinstance(value, float) and not value.is_integer():
            raise ParamError(spec.name, f"expected a whole number, got {value!r}")
        value = int(value)
    else:
        value = float(value)
        if not math.isfinite(value):
            raise ParamError(spec.name, f"must be finite, got {value!r}")
    unit = "" if spec.unit == "1" else f" {spec.unit}"  # a ratio has no unit to name
    if spec.lo is not None and value < spec.lo:
        raise ParamError(spec.name, f"{value!r} is below the minimum {spec.lo}{unit}")
    if spec.hi is not None and value > spec.hi:
        raise ParamError(spec.name, f"{value!r} is above the maximum {spec.hi}{unit}")
    return value


_INTERNED: weakref.WeakValueDictionary = weakref.WeakValueDictionary()


def _interned(cls: type, values: tuple) -> Params:
    """The parameters ``cls(*values)``: the one object of this process that has those values while
    any is held (``Params.__reduce__``), checked once when first made."""
    key = (cls, values)
    p = _INTERNED.get(key)
    if p is None:
        p = _INTERNED[key] = cls(*values)
    return p


class Params:
    """Mixin for the parameter dataclasses: validation on construction, typed copies."""

    def small(self, motion) -> bool:
        """Whether a motion (an increment, or the gap between two estimates) is below every stopping
        threshold ``errx_out``, ``erry_out``, ``errt_out`` (every matcher declares them)."""
        return (
            abs(motion.x) < self.errx_out
            and abs(motion.y) < self.erry_out
            and abs(motion.theta) < self.errt_out
        )

    def __post_init__(self):
        for spec in field_specs(type(self)):
            object.__setattr__(self, spec.name, check_value(spec, getattr(self, spec.name)))

    def __reduce__(self):
        # A pool's rows come back pickled, each with its parameters: unpickled as one object per
        # value (``_interned``), not a copy per row nor a comparison and a copy of each record.
        return _interned, (type(self), tuple(self.as_dict().values()))

    def replace(self, **changes):
        unknown = set(changes) - {s.name for s in field_specs(type(self))}
        if unknown:
            raise ParamError(sorted(unknown)[0], f"unknown parameter for {type(self).__name__}")
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict[str, Any]:
        # the fields are numbers and flags: dataclasses.asdict's deep copy was a tenth of the time
        # a run's parent spends writing a row. Made once (the object never changes; set past the
        # frozen __setattr__), a copy given: each row of a run writes them
        made = self.__dict__.get("_as_dict")
        if made is None:
            made = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
            object.__setattr__(self, "_as_dict", made)
        return dict(made)

    # What the front ends show of a matcher's per-iteration threshold (IterationEvent.threshold)
    # and of the distance beyond which it never pairs: each matcher's parameters say it.
    def threshold_label(self) -> str:
        return "threshold [m]"

    def hard_cut(self) -> tuple[str, float] | None:
        """(legend label, distance [m]) beyond which no pair is made, or None."""
        return None


@dataclass(frozen=True)
class StopParams(Params):
    """Stopping rules every iterative matcher shares (names as in MbICP's C code)."""

    MaxIter: int = param(100, unit="count", lo=1, hi=10000, help="maximum number of iterations")
    errx_out: float = param(
        1e-4,
        unit="m",
        lo=0.0,
        hi=1.0,
        help="an iteration counts as converged when |dx| of "
        "its increment is below this (and |dy|, |dtheta| below theirs)",
    )
    erry_out: float = param(
        1e-4, unit="m", lo=0.0, hi=1.0, help="... |dy| of the increment below this"
    )
    errt_out: float = param(
        1e-4, unit="rad", lo=0.0, hi=1.0, help="... |dtheta| of the increment below this"
    )
    AsocError: float = param(
        0.1,
        unit="1",
        lo=0.0,
        hi=1.0,
        help="fail when fewer than this fraction of object points find a pair",
    )


@dataclass(frozen=True)
class IcpParams(Params):
    """ICP as Censi's CSM runs it (``sm_icp``; names and defaults of its options as its ``sm2``
    program sets them): pairs to the segment between the nearest reference ray and its nearer
    neighbour, adaptive trimming, the exact closed-form pose, restarts (core/icp.py)."""

    max_iterations: int = param(
        1000, unit="count", lo=1, hi=100000, help="maximum number of iterations"
    )
    epsilon_xy: float = param(
        1e-4, unit="m", lo=0.0, hi=1.0, help="stop when the step moves less than this ..."
    )
    epsilon_theta: float = param(
        1e-4, unit="rad", lo=0.0, hi=1.0, help="... and turns less than this"
    )
    max_correspondence_dist: float = param(
        2.0,
        unit="m",
        lo=1e-3,
        hi=100.0,
        tune=(0.1, 3.0, True),
        help="an object point farther than this from its nearest reference point gets no pair",
    )
    outliers_maxPerc: float = param(
        0.95,
        unit="1",
        lo=0.0,
        hi=1.0,
        tune=(0.5, 1.0, False),
        help="keep at most this share of the pairs (the nearest to their segments)",
    )
    outliers_adaptive_order: float = param(
        0.7,
        unit="1",
        lo=0.0,
        hi=1.0,
        tune=(0.5, 1.0, False),
        help="adaptive trimming: the quantile of the segment distances that ...",
    )
    outliers_adaptive_mult: float = param(
        2.0,
        unit="1",
        lo=0.0,
        hi=100.0,
        tune=(1.0, 5.0, False),
        help="... times this is the largest distance kept (1 and 1 with outliers_maxPerc 1: no "
        "trimming)",
    )
    outliers_remove_doubles: bool = param(
        True,
        unit="bool",
        help="of several object points paired with one reference point, drop those 3x farther than "
        "the nearest",
    )
    restart: bool = param(
        True,
        unit="bool",
        help="restart six times from the result moved by restart_dt / restart_dtheta when its mean "
        "distance "
        "exceeds restart_threshold_mean_error, keeping the run of smallest total distance",
    )
    restart_threshold_mean_error: float = param(
        0.01,
        unit="m",
        lo=0.0,
        hi=100.0,
        help="mean distance of the kept pairs above which the restarts run",
    )
    restart_dt: float = param(
        0.01, unit="m", lo=0.0, hi=10.0, help="restarts move the result by this in x and in y"
    )
    restart_dtheta: float = param(
        math.radians(1.5), unit="rad", lo=0.0, hi=math.pi, help="restarts turn the result by this"
    )
    min_reading: float = param(
        0.0, unit="m", lo=0.0, hi=1000.0, help="readings at or below this are not used"
    )
    max_reading: float = param(
        1000.0, unit="m", lo=0.0, hi=1000.0, help="readings beyond this are not used"
    )

    def threshold_label(self) -> str:
        return (
            f"trim limit: the {100 * self.outliers_maxPerc:g} % quantile or "
            f"{self.outliers_adaptive_mult:g} x the {100 * self.outliers_adaptive_order:g} % "
            "quantile of the segment distances, the smaller [m]"
        )

    def hard_cut(self) -> tuple[str, float] | None:
        return (
            f"max_correspondence_dist, {self.max_correspondence_dist:g} m",
            self.max_correspondence_dist,
        )


@dataclass(frozen=True)
class PlIcpParams(IcpParams):
    """PL-ICP (Censi, ICRA 2008) as CSM runs it: the point-to-line distance to the line through the
    nearest reference ray and its nearer neighbour; it also stops when the pairs repeat."""


@dataclass(frozen=True)
class MbicpParams(StopParams):
    """MbICP (Minguez, Lamiraux & Montesano, T-RO 2006). Names and defaults as in the original C
    code with the defaults of Player's ``mbicp`` driver, which it reproduces, but for the range
    limit (the ``player`` preset has that too)."""

    MaxIter: int = param(50, unit="count", lo=1, hi=10000, help="maximum number of iterations")
    # Player's driver limits the range to 7.9 m (a SICK in its 8 m mode; the `player` preset);
    # here every reading the scan holds is used, whatever the sensor's range.
    max_range: float = param(
        1000.0,
        unit="m",
        lo=0.01,
        hi=1000.0,
        help="readings at or beyond this range are not used (1000: every valid reading, the "
        "scan's own range; Player's mbicp driver: 7.9, the `player` preset)",
    )
    L: float = param(
        3.0,
        unit="m",
        lo=1e-3,
        hi=100.0,
        tune=(0.3, 10.0, True),
        help="metric length: ||q|| = sqrt(x^2 + y^2 + L^2 theta^2); large L tends to plain ICP",
    )
    Bw: float = param(
        1.57 / 3.0,
        unit="rad",
        lo=math.radians(0.1),
        hi=math.pi,
        tune=(math.radians(10.0), math.radians(90.0), False),
        help="angular window: reference points within +/-Bw of an object point's bearing are "
        "candidates",
    )
    Br: float = param(
        0.3,
        unit="m",
        lo=1e-3,
        hi=100.0,
        tune=(0.05, 3.0, True),
        help="radial window: pairs with a metric distance above Br are discarded",
    )
    laserStep: int = param(
        1, unit="count", lo=1, hi=100, help="use every laserStep-th object point"
    )
    MaxDistInter: float = param(
        0.5,
        unit="m",
        lo=0.0,
        hi=100.0,
        tune=(0.1, 2.0, True),
        help="interpolate only on reference segments shorter than this; MbICP compares the "
        "segment's squared "
        "length with it, as the original code does (0.5: segments up to 0.71 m), improved MbICP's "
        "point-to-line pairs its length",
    )
    filter: float = param(
        0.85,
        unit="1",
        lo=0.05,
        hi=1.0,
        tune=(0.5, 1.0, False),
        help="fraction of the best pairs kept each iteration (trimmed estimator)",
    )
    ProjectionFilter: bool = param(
        True,
        unit="bool",
        help="drop object points hidden from the reference viewpoint (Lu & Milios)",
    )
    projection_zbuffer: bool = param(
        False,
        unit="bool",
        help="the projection filter as a z-buffer over bearing bins (hides what lies behind a "
        "nearer surface, "
        "whatever the order; needed for 360-degree scans) instead of the original's rule (a point "
        "whose "
        "bearing falls below the last kept one's is hidden)",
    )
    errorRatio: float = param(
        1e-4,
        unit="1",
        lo=0.0,
        hi=1.0,
        help="an iteration also counts as converged when |1 - error/previous error| is below this "
        "(error: the "
        "summed squared residual of the kept pairs, as the original code sums it)",
    )
    IterSmoothConv: int = param(
        2,
        unit="count",
        lo=0,
        hi=100,
        help="stop after more than this many consecutive converged iterations",
    )

    def threshold_label(self) -> str:
        return f"trim cut: the best {100 * self.filter:g} % of the pairs kept [m]"

    def hard_cut(self) -> tuple[str, float] | None:
        return f"Br: radial window, {self.Br:g} m", self.Br


@dataclass(frozen=True)
class ImprovedParams(MbicpParams):
    """Improved MbICP (Li et al. 2018, paper 000): MbICP plus three switchable additions. The paper
    gives no parameter values; these defaults are this project's (docs/results.md measures them):
    wider windows than Player's MbICP and the z-buffer projection filter."""

    MaxIter: int = redefault(MbicpParams, "MaxIter", 100)
    Bw: float = redefault(MbicpParams, "Bw", math.radians(45.0))
    Br: float = redefault(MbicpParams, "Br", 1.0)
    # unused while mad_rejection
    filter: float = redefault(MbicpParams, "filter", 0.95, tuned=False)
    projection_zbuffer: bool = redefault(MbicpParams, "projection_zbuffer", True)
    resample: bool = param(
        True, unit="bool", help="grid resampling of the object scan (paper 000 §2.3)"
    )
    cell_size: float = param(
        0.1,
        unit="m",
        lo=0.005,
        hi=10.0,
        tune=(0.02, 0.5, True),
        help="grid cell side for resampling (§2.3)",
    )
    point_line: bool = param(
        True,
        unit="bool",
        help="point-to-point + point-to-line correspondences for shared targets (§2.4.1)",
    )
    mad_rejection: bool = param(
        True,
        unit="bool",
        help="reject pairs above median + k*MAD of the distances (§2.4.2); replaces 'filter' when "
        "on",
    )
    mad_k: float = param(
        2.0,
        unit="1",
        lo=0.0,
        hi=100.0,
        tune=(1.0, 5.0, False),
        help="k in the rejection threshold median + k*MAD (eq. 5)",
    )
    mad_floor: float = param(
        0.1,
        unit="m",
        lo=0.0,
        hi=100.0,
        tune=(0.01, 0.5, True),
        help="never reject a pair closer than this (0: the paper's rule as published)",
    )
    mad_anneal: float = param(
        0.0,
        unit="1",
        lo=0.0,
        hi=0.999,
        tune=(0.0, 0.95, False),
        help="0: MAD from the first iteration, as published; else the rejection floor starts at Br "
        "and shrinks by "
        "this factor each iteration down to mad_floor (a wider basin from a poor guess, more "
        "iterations)",
    )
    hold_weak: float = param(
        0.0,
        unit="1",
        lo=0.0,
        hi=1e9,
        help="0: off; else, when the condition number of an iteration's normal equations (in x, y, "
        "L theta) exceeds "
        "this, its step leaves the weakest direction alone, so that the estimate keeps the guess's "
        "value "
        "along a corridor instead of sliding (Zhang, Kaess & Singh, ICRA 2016: solution remapping)",
    )
    extrapolate: float = param(
        0.0,
        unit="1",
        lo=0.0,
        hi=100.0,
        help="0: off, as published; else an iteration whose step points within 90 degrees of the "
        "previous one and "
        "is shorter (ratio r) goes on by r/(1-r) times its length, at most this many: Aitken's "
        "extrapolation, "
        "after Besl & McKay's accelerated ICP (1992); fewer iterations along slowly converging "
        "directions",
    )

    def threshold_label(self) -> str:
        if not self.mad_rejection:
            return super().threshold_label()
        return f"MAD threshold: median + {self.mad_k:g} MAD, at least {self.mad_floor:g} m [m]"


@dataclass(frozen=True)
class PolarParams(Params):
    """Preprocessing, projection and stopping shared by PSM and PMWN (Diosi's published values, in
    metres)."""

    median_window: int = param(
        5, unit="count", lo=1, hi=21, help="median filter window on ranges (PSM §3.1)"
    )
    min_range: float = param(
        0.1, unit="m", lo=0.0, hi=100.0, help="readings closer than this are ignored"
    )
    max_range: float = param(
        30.0, unit="m", lo=0.1, hi=1000.0, help="readings farther than this are ignored"
    )
    max_jump: float = param(
        0.2,
        unit="m",
        lo=0.001,
        hi=100.0,
        tune=(0.05, 1.0, True),
        help="a new segment starts where consecutive ranges differ by more (scan projection "
        "interpolates "
        "only inside segments)",
    )
    max_error: float = param(
        1.0,
        unit="m",
        lo=0.001,
        hi=100.0,
        tune=(0.1, 3.0, True),
        help="range residuals larger than this are excluded from the translation step",
    )
    search_window: float = param(
        math.radians(20.0),
        unit="rad",
        lo=0.0,
        hi=math.pi,
        tune=(math.radians(5.0), math.radians(45.0), False),
        help="the orientation step tries rotations within +/- this",
    )
    min_pairs: int = param(
        40, unit="count", lo=3, hi=100000, help="fail with fewer range comparisons than this"
    )
    MaxIter: int = param(50, unit="count", lo=1, hi=10000, help="maximum number of iterations")
    errx_out: float = param(
        5e-4, unit="m", lo=0.0, hi=1.0, help="a correction is small when |dx| is below this"
    )
    erry_out: float = param(5e-4, unit="m", lo=0.0, hi=1.0, help="... and |dy| below this")
    errt_out: float = param(5e-4, unit="rad", lo=0.0, hi=1.0, help="... and |dtheta| below this")
    surface_jacobian: bool = param(
        False,
        unit="bool",
        help="translation step with the reference surface normals instead of Diosi's range change "
        "u.dt "
        "(not published; holds corridors, see core/polar.py translation_step)",
    )
    stop_after: int = param(
        3, unit="count", lo=1, hi=100, help="stop after this many small corrections in a row"
    )
    relaxed_cut: bool = param(
        False,
        unit="bool",
        help="keep at least min_pairs residuals in the translation step, raising max_error when "
        "fewer lie "
        "within it (not published; see core/polar.py translation_residuals)",
    )
    truncated_orientation: bool = param(
        False,
        unit="bool",
        help="orientation cost with each |range difference| capped at max_error, as the "
        "translation step "
        "caps its residuals (not published; see core/polar.py shift_costs)",
    )
    # The translation weights w = C / (C + e^2) of Diosi's code (after Dudek 2000), which paper 003
    # §4.2 takes over for its projected circle (its ref. [22]), with the code's schedule: C is
    # lowered after 10 iterations so that only the closest residuals steer the end of the match.
    C: float = param(
        0.49,
        unit="m^2",
        lo=1e-6,
        hi=100.0,
        tune=(0.01, 2.0, True),
        help="weight constant w = C / (C + e^2) of the translation step (Diosi: 70 cm squared)",
    )
    C_late: float = param(
        0.01, unit="m^2", lo=1e-6, hi=100.0, help="weight constant after C_switch iterations"
    )
    C_switch: int = param(
        10, unit="count", lo=0, hi=10000, help="iteration from which C_late is used"
    )

    def weight_constant(self, iteration: int) -> float:
        """C of the translation weights at an iteration (counted from 1)."""
        return self.C if iteration <= self.C_switch else self.C_late

    def threshold_label(self) -> str:
        return "max_error: residuals beyond are not used [m]"


@dataclass(frozen=True)
class PsmParams(PolarParams):
    """Polar Scan Matching (Diosi & Kleeman, IJRR 2007)."""

    orientation_every: int = param(
        1,
        unit="count",
        lo=1,
        hi=100,
        help="run the orientation step on every n-th iteration; each iteration has a translation "
        "step "
        "(Diosi's code alternates one orientation and one translation pass: 1)",
    )


@dataclass(frozen=True)
class PmwnParams(PolarParams):
    """Polar Metric-Weighted Norm (Huo et al. 2016, paper 003); equations reconstructed, see
    core/pmwn.py."""

    lambda0: float = param(
        0.0,
        unit="m/rad",
        lo=0.0,
        hi=1000.0,
        help="metric weight of the first iteration (0: the first rotation is free)",
    )
    lambda_max: float = param(
        0.5,
        unit="m/rad",
        lo=0.0,
        hi=1e6,
        tune=(0.05, 5.0, True),
        help="upper bound of the adaptive metric weight (larger values lock the rotation when the "
        "translation is far off)",
    )


@dataclass(frozen=True)
class SearchParams(Params):
    """The window and grid of the correlative search (around the given guess)."""

    window_xy: float = param(
        1.5, unit="m", lo=0.0, hi=20.0, help="candidates within +/- this in x and in y"
    )
    window_theta: float = param(
        math.radians(40.0),
        unit="rad",
        lo=0.0,
        hi=math.pi,
        help="candidates within +/- this in rotation",
    )
    cell: float = param(
        0.1, unit="m", lo=0.01, hi=1.0, help="grid step in x and y (and of the likelihood field)"
    )
    # as low as fine_angle_step's: the fine pass runs with angle_step = fine_angle_step
    angle_step: float = param(
        math.radians(1.0),
        unit="rad",
        lo=math.radians(0.01),
        hi=math.radians(10.0),
        help="grid step in rotation",
    )
    # 1.5 cells: at sigma = one cell the field is nearly binary at its own resolution and a point's
    # score jumps as it crosses a cell. Measured on Intel's 909 consecutive pairs (docs/results.md):
    # the search alone within 0.1 m and 3 deg 839 -> 848, improved MbICP refining it 879 -> 885.
    sigma: float = param(
        0.15,
        unit="m",
        lo=0.005,
        hi=2.0,
        help="likelihood exp(-d^2 / sigma^2) of a point d metres from the reference scan",
    )
    weight_cap: float = param(
        8.0,
        unit="m",
        lo=0.1,
        hi=1000.0,
        help="a point weighs its range, up to this (the arc its beam covers)",
    )
    # Measured on Intel's 909 consecutive pairs (docs/results.md): the search alone within 0.1 m and
    # 3 deg 848 -> 887, improved MbICP refining it 885 -> 889.
    refine: bool = param(
        True, unit="bool", help="a second, finer pass around the best candidate of the first"
    )
    fine_cell: float = param(0.02, unit="m", lo=0.01, hi=1.0, help="grid step of the second pass")
    fine_angle_step: float = param(
        math.radians(0.25),
        unit="rad",
        lo=math.radians(0.01),
        hi=math.radians(10.0),
        help="rotation step of the second pass",
    )
    fine_sigma: float = param(
        0.05, unit="m", lo=0.005, hi=2.0, help="sigma of the second pass's likelihood field"
    )

    def window_text(self) -> str:
        """The window as users read it (degrees at the edge)."""
        return f"+/-{self.window_xy:g} m, +/-{math.degrees(self.window_theta):g} deg"
