"""Loop closures on a run (issue 36): key frames along the run's chain, old key frames proposed
where the chain's own uncertainty allows the robot to be back, each candidate verified by a
correlative search and a scan match, and a pose graph over the key frames optimised on GTSAM.

The run's chain is a pose graph without loops: one edge per key frame, the motion the matches
chained between two key frames. A closure adds an edge between a key frame and an old one it sees
again. Wrong closures are the danger of graph mapping (one wrecks the map); three guards, in order:
the candidate's own match (the response surface must have one clear peak, the scans must overlap,
no direction may be weak), then at every optimisation graduated non-convexity with a truncated
least squares loss (Yang et al. 2020, GTSAM's ``GncLMOptimizer``) over all closures, the chain's
edges known inliers, and least squares on the closures it keeps. GNC needs no initial guess of
which closures are right and tolerates most being wrong; a robust kernel (Cauchy) alone depends on
the starting estimate, and on a chain whose heading drifts steadily it let the right closures go
(a three-lap square in tests/test_loops.py: 2.2 m off at home with it, 0.24 m with least squares).
The closures GNC turns off at the end are rejected as "inconsistent with other closures".

A person may overrule any verdict (the run view's "accept / reject this closure"):
``LoopRun.decided`` solves the graph again in one batch, a closure accepted by hand a known inlier,
one rejected by hand left out.
"""

from __future__ import annotations

import bisect
import math
import time
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from mbicp_viz.core import Params, Pose2, SearchParams, relative
from mbicp_viz.core.search import MAX_WORK, SearchResult, correlative_search
from mbicp_viz.readers import ScanLog
from mbicp_viz.readers.pair_match import PairMatch, Suspicion, Verdict

from .keyframes import KeyFrames
from .single import Setup, match_pair
from .trajectory import accumulate, scan_indices

# The covariance a match reports is that of its residuals: centimetres where the true error of a
# chained run is tenths of a degree per metre. Floors on each edge's sigmas (m, m, rad) keep the
# graph from trusting one match more than the scans allow.
EDGE_FLOOR = (0.01, 0.01, math.radians(0.5))
CLOSURE_FLOOR = (0.05, 0.05, math.radians(1.0))


@dataclass(frozen=True)
class LoopParams:
    """How closures are proposed and judged (lengths in metres, angles in radians)."""

    keyframes: KeyFrames = field(default_factory=KeyFrames)
    min_path_m: float = 10.0  # a key frame this far back along the run or more is "old"
    reach_m: float = 1.0  # two key frames this near see the same place, beside the uncertainty
    chi2: float = 9.21  # the gate on the chain's position uncertainty: chi-squared, 2 dof, 99 %
    # candidates matched per key frame, the most likely first (tried instead: one from each pass,
    # 5 m apart along the run; it closed fewer of Intel's loops, 0.044 m against 0.022 m)
    per_key: int = 2
    # the correlative search's half window, at most (x and y): ACES's chain comes back 6 m off
    window_max_m: float = 7.0
    window_theta: float = math.radians(30.0)  # its half window in rotation
    # share of the object points on the old key frame's surface. A revisit 1 m and 28 degrees
    # apart holds 40 % (ACES); 0.35 lets wrong closures through on Intel (0.047 m against 0.021)
    min_overlap: float = 0.45
    peak_ratio: float = 0.9  # a second peak this high, 10 degrees or more off, is ambiguous
    peak_apart: float = math.radians(10.0)


@dataclass(frozen=True)
class Closure:
    """One candidate: the old key frame ``old`` and the newer ``key`` (record numbers), the match
    (old -> key, the run's frame), what its match was judged (``judged``) and what became of it
    in the graph (``verdict``: judged, turned off as inconsistent, or set by hand), with what it
    was judged on."""

    old: int
    key: int
    match: PairMatch
    verdict: Verdict
    judged: Verdict  # the match's own verdict, before the graph and any hand
    peak_ratio: float  # the best second peak's score over the best's (1: two equal peaks)
    search: SearchResult | None  # the correlative search's response the match started from
    guess: Pose2 = Pose2()  # where the search was centred: the chain's prediction (laser frame)
    by_hand: bool = False  # the verdict was set by a person

    @property
    def accepted(self) -> bool:
        return self.verdict is Verdict.ACCEPTED

    def says(self) -> str:
        """The verdict in words, and the match's own where a hand overruled it."""
        if self.by_hand:
            hand = "accepted by hand" if self.accepted else "rejected by hand"
            return f"{hand} (its match: {self.judged.value})"
        return self.verdict.value


@dataclass(frozen=True)
class LoopRun:
    """A run with its loops closed: the key frames (positions in the run's scans), every
    candidate, and the poses of every scan of the run, chained and optimised."""

    scans: list[int]  # record numbers of the run's scans, in its order
    keys: list[int]
    edges: list[tuple[Pose2, np.ndarray]]  # the chain's step from key frame n-1 to n, covariance
    closures: list[Closure]
    chained: list[Pose2]
    optimised: list[Pose2]
    optimise_s: list[float]  # each optimisation's time, in the order they ran
    params: LoopParams = LoopParams()  # what the candidates were proposed and judged with

    @cached_property
    def _position(self) -> dict[int, int]:
        """Each scan's position in the run, by its record number."""
        return {k: n for n, k in enumerate(self.scans)}

    def ends(self, c: Closure, poses: list[Pose2] | None = None) -> tuple[Pose2, Pose2]:
        """Where ``poses`` (one per scan of the run; default: the optimised run) put a closure's
        old and newer key frame."""
        poses = self.optimised if poses is None else poses
        return poses[self._position[c.old]], poses[self._position[c.key]]

    def decided(self, by_hand: dict[int, bool]) -> LoopRun:
        """The run solved again with closures accepted (True) or rejected (False) by hand
        (``by_hand``: positions in ``closures``), the others as their match was judged; graduated
        non-convexity judges again which of those agree, from this run's optimised poses."""
        if unknown := sorted(set(by_hand) - set(range(len(self.closures)))):
            raise ValueError(f"by_hand: no closure {unknown[0]} (the run has {len(self.closures)})")
        key_of = {self.scans[k]: n for n, k in enumerate(self.keys)}
        graph = PoseGraph()
        for n, (motion, cov) in enumerate(self.edges, start=1):
            graph.add_step(motion, cov, self.optimised[self.keys[n]])
        for k, c in enumerate(self.closures):
            if by_hand.get(k, c.judged is Verdict.ACCEPTED):
                graph.add_closure(key_of[c.old], key_of[c.key], c, certain=k in by_hand)
        t0 = time.perf_counter()
        graph.optimise()
        took = time.perf_counter() - t0
        dropped = {id(c) for c in graph.turned_off()}
        closures = [
            _settled(c, by_hand.get(k), id(c) in dropped) for k, c in enumerate(self.closures)
        ]
        key_poses = [graph.pose(n) for n in range(len(self.keys))]
        return replace(
            self,
            closures=closures,
            optimised=place_scans(self.chained, self.keys, key_poses),
            optimise_s=[*self.optimise_s[:-1], took],
        )

    def moved(self, other: LoopRun) -> np.ndarray:
        """How far each scan lies from where ``other`` puts it [m]."""
        a = np.array([[q.x, q.y] for q in self.optimised])
        b = np.array([[q.x, q.y] for q in other.optimised])
        return np.hypot(*(a - b).T)

    @cached_property
    def _path(self) -> np.ndarray:
        """Each key frame's distance along the run from the first [m]."""
        return np.concatenate([[0.0], np.cumsum([m.translation_norm() for m, _ in self.edges])])

    def around(self, n: int) -> str:
        """What closing loops did at the key frame at or before the run's scan ``n`` (a position
        in the run), in words: its candidates and their verdicts, or that it had none and where the
        nearest old key frame lies with the loops closed (why a loop did not close there)."""
        k = bisect.bisect_right(self.keys, n) - 1
        key, gap = self.scans[self.keys[k]], self.params.min_path_m
        mine = [c for c in self.closures if c.key == key]
        head = f"key frame scan {key}"
        if mine:
            return f"{head}: " + "; ".join(f"candidate scan {c.old}: {c.says()}" for c in mine)
        old = np.flatnonzero(self._path[k] - self._path[:k] >= gap)
        if not len(old):
            return f"{head}: no loop candidate (no key frame {gap:g} m or more back along the run)"
        here = self.optimised[self.keys[k]]
        apart = [
            math.hypot(q.x - here.x, q.y - here.y)
            for q in (self.optimised[self.keys[j]] for j in old)
        ]
        j = int(np.argmin(apart))
        return (
            f"{head}: no loop candidate; the nearest old key frame ({gap:g} m or more back along "
            f"the run) is scan {self.scans[self.keys[old[j]]]}, {apart[j]:.2f} m away with the "
            f"loops closed (candidates are looked for within the chain's 99 % uncertainty of "
            f"where it predicts them, plus {self.params.reach_m:g} m)"
        )

    def key_points(self, log: ScanLog) -> np.ndarray:
        """The key frames' points at their optimised poses (the run's world frame)."""
        scans = log.scans_of([self.scans[k] for k in self.keys], odometry=False)
        at = [self.optimised[k] for k in self.keys]
        return np.concatenate([q.apply(s.points()) for q, s in zip(at, scans)])

    def counts(self) -> dict[str, int]:
        return {r: sum(c.verdict is r for c in self.closures) for r in Verdict}

    def summary(self) -> list[str]:
        """What closing the loops did, in words: candidates, verdicts, the optimisations' time."""
        counts, n = self.counts(), len(self.closures)
        rejected = "; ".join(
            f"{r} {k}" for r, k in counts.items() if r is not Verdict.ACCEPTED and k
        )
        lines = [
            f"loops: {len(self.keys)} key frames, {n} candidates matched, "
            f"{counts[Verdict.ACCEPTED]} accepted" + (f"; rejected: {rejected}" if rejected else "")
        ]
        if not counts[Verdict.ACCEPTED]:
            lines.append("no loop closed: the optimised run is the chained one")
        *during, last = self.optimise_s
        if during:
            lines.append(
                f"pose graph (GTSAM): {len(during)} optimisations as loops closed, median "
                f"{1000 * float(np.median(during)):.0f} ms, longest {1000 * max(during):.0f} ms; "
                f"graduated non-convexity over the closures at the end {1000 * last:.0f} ms"
            )
        return lines


def plan(rows: list[PairMatch], p: LoopParams) -> tuple[list[Pose2], list[int]]:
    """A run's chained poses and its key frames' positions among them."""
    chained = accumulate(rows)
    return chained, key_frames(chained, p.keyframes)


def key_frames(poses: list[Pose2], rule: KeyFrames) -> list[int]:
    """Positions of the key frames along a chain: the first scan, then each scan the chain has moved
    or turned ``rule``'s distance from the last key frame."""
    keys = [0]
    for k in range(1, len(poses)):
        if rule.moved(relative(poses[keys[-1]], poses[k])):
            keys.append(k)
    if keys[-1] != len(poses) - 1:
        keys.append(len(poses) - 1)
    return keys


def edge_covariances(rows: list[PairMatch], keys: list[int]) -> list[np.ndarray]:
    """Each chain edge's covariance (key frame n-1 -> n, in n-1's frame): the covariances of the
    rows its motion composes (the rows from key frame n back along their references), summed to
    first order, with ``EDGE_FLOOR``."""
    scans = scan_indices(rows)
    row_of = {r.obj: r for r in rows}
    floor = np.diag(np.square(EDGE_FLOOR))
    out = []
    for a, b in zip(keys, keys[1:]):
        cov, k = floor.copy(), scans[b]
        while k in row_of and k > scans[a]:
            r = row_of[k]
            if r.result.covariance is not None:
                cov += r.result.covariance
            k = r.ref
        out.append(cov)
    return out


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


class ChainUncertainty:
    """How far the chain may have drifted between two key frames, from the edges' covariances, to
    first order: the translation noise of each edge (turned into the world frame) plus each edge's
    heading noise swinging everything after it about its end. Prefix sums make a query O(1)."""

    def __init__(self, poses: list[Pose2], covariances: list[np.ndarray]):
        p = np.array([[q.x, q.y] for q in poses])
        a = np.zeros((len(poses), 2, 2))
        s0, s1, s2 = np.zeros(len(poses)), np.zeros((len(poses), 2)), np.zeros((len(poses), 2, 2))
        for n, cov in enumerate(covariances, start=1):
            r = _rot(poses[n - 1].theta)
            a[n] = r @ cov[:2, :2] @ r.T
            s0[n] = cov[2, 2]
            s1[n] = cov[2, 2] * p[n]
            s2[n] = cov[2, 2] * np.outer(p[n], p[n])
        self.p = p
        self.a, self.s0, self.s1, self.s2 = (np.cumsum(x, axis=0) for x in (a, s0, s1, s2))

    def position_covariances(self, n: int) -> np.ndarray:
        """(n, 2, 2): the covariance of key frame n's position relative to each earlier key frame,
        in the world frame."""
        pn = self.p[n]
        da = self.a[n] - self.a[:n]
        d0 = self.s0[n] - self.s0[:n]
        d1 = self.s1[n] - self.s1[:n]
        d2 = self.s2[n] - self.s2[:n]
        m = (
            d0[:, None, None] * np.outer(pn, pn)
            - np.einsum("i,kj->kij", pn, d1)
            - np.einsum("ki,j->kij", d1, pn)
            + d2
        )
        j = np.array([[0.0, -1.0], [1.0, 0.0]])  # a turn moves a point perpendicular to its arm
        return da + j @ m @ j.T


def candidates(
    estimate: list[Pose2], n: int, path: np.ndarray, chain: ChainUncertainty, p: LoopParams
) -> list[int]:
    """The old key frames key frame ``n`` may see again, the most likely first: at least
    ``min_path_m`` back along the run, within the chi-squared gate of the chain's uncertainty
    (plus ``reach_m``) of where the estimate puts them."""
    old = np.flatnonzero(path[n] - path[:n] >= p.min_path_m)
    if len(old) == 0:
        return []
    xy = np.array([[estimate[k].x, estimate[k].y] for k in old])
    d = xy - np.array([estimate[n].x, estimate[n].y])
    cov = chain.position_covariances(n)[old] + p.reach_m**2 * np.eye(2)
    m2 = np.einsum("ki,kij,kj->k", d, np.linalg.inv(cov), d)
    inside = np.flatnonzero(m2 <= p.chi2)
    return [int(old[k]) for k in inside[np.argsort(m2[inside], kind="stable")][: p.per_key]]


def second_peak(profile: np.ndarray, angles: np.ndarray, apart: float) -> float:
    """The highest score of the search's rotations at least ``apart`` from its best, over the best
    (the response surface's second peak; 0 when the window holds no such rotation)."""
    best = int(np.argmax(profile))
    far = np.abs(angles - angles[best]) >= apart
    if not far.any() or profile[best] <= 0:
        return 0.0
    return float(profile[far].max() / profile[best])


def search_window(spread_m: float, points: int, p: LoopParams) -> SearchParams:
    """The correlative search for a candidate: +/- the estimate's spread (within 0.3 m and
    ``window_max_m``) and ``window_theta``, its grid coarsened (and its likelihood widened with it)
    where a wide window of many points would score more placements than ``MAX_WORK`` allows."""
    d = SearchParams()
    window = float(np.clip(spread_m, 0.3, p.window_max_m))
    angles = 2 * round(p.window_theta / d.angle_step) + 1
    cells = int((math.sqrt(MAX_WORK / (angles * max(points, 1))) - 1) // 2)  # a half window
    cell = min(max(d.cell, window / max(cells, 1)), 1.0)  # 1 m: the grid's coarsest
    window = min(window, max(cells, 1) * cell)
    return d.replace(
        window_xy=window,
        window_theta=p.window_theta,
        cell=cell,
        sigma=d.sigma * cell / d.cell,
    )


def verify(
    log: ScanLog,
    old: int,
    key: int,
    predicted: Pose2,
    spread_m: float,
    params: Params,
    p: LoopParams,
    base: bool,
) -> Closure:
    """Match key frame ``key`` against the old one from the correlative search's best peak around
    the predicted motion (the run's frame), and judge it."""
    frames = log.frames
    ref, obj = log.scan(old), log.scan(key)
    laser = frames.laser_motion(predicted, base)
    found = correlative_search(ref, obj, laser, search_window(spread_m, len(obj.points()), p))
    ratio = second_peak(found.best_per_angle, found.angles, p.peak_apart)
    m = match_pair(
        ref,
        obj,
        params,
        Setup(found.pose, "searched around the chain's prediction"),
        frames,
        base,
        indices=(old, key),
        stream=log.topic,
    )
    if not m.result.converged:
        verdict = Verdict.NOT_CONVERGED
    elif ratio >= p.peak_ratio:
        verdict = Verdict.AMBIGUOUS
    elif m.overlap is not None and m.overlap < p.min_overlap:
        verdict = Verdict.LOW_OVERLAP
    elif Suspicion.WEAK_DIRECTION in m.flags:
        verdict = Verdict.WEAK
    else:
        verdict = Verdict.ACCEPTED
    return Closure(old, key, m, verdict, verdict, ratio, found, laser)


def _settled(c: Closure, hand: bool | None, dropped: bool) -> Closure:
    """A closure's verdict after an optimisation: set by ``hand`` (None: not), or its match's, the
    graph turning off (``dropped``) an accepted one as inconsistent with the others."""
    if hand is not None:
        return replace(c, verdict=Verdict.ACCEPTED if hand else Verdict.SET_ASIDE, by_hand=True)
    verdict = Verdict.INCONSISTENT if dropped and c.judged is Verdict.ACCEPTED else c.judged
    return replace(c, verdict=verdict, by_hand=False)


class PoseGraph:
    """The key frames' pose graph on GTSAM: the first fixed, one edge per chain step, one per
    accepted closure."""

    def __init__(self):
        import gtsam  # 0.2 s to import: only when loops are closed

        self.gtsam = gtsam
        self.steps: list[tuple[Pose2, np.ndarray]] = []  # key frame n-1 -> n
        self.closures: list[tuple[int, int, Closure, np.ndarray]] = []
        self.certain: set[int] = set()  # positions in ``closures`` known right (set by hand)
        self.dropped: set[int] = set()  # positions in ``closures`` that GNC turned off
        self.values = gtsam.Values()
        self.values.insert(0, gtsam.Pose2())

    def _pose(self, q: Pose2):
        return self.gtsam.Pose2(q.x, q.y, q.theta)

    def _graph(self, skip: set[int] = frozenset()):
        g = self.gtsam
        graph = g.NonlinearFactorGraph()
        graph.add(g.PriorFactorPose2(0, g.Pose2(), g.noiseModel.Isotropic.Sigma(3, 1e-6)))
        edges = [(n - 1, n, m, cov) for n, (m, cov) in enumerate(self.steps, start=1)]
        edges += [
            (a, b, c.match.result.pose, cov)
            for k, (a, b, c, cov) in enumerate(self.closures)
            if k not in skip
        ]
        for a, b, m, cov in edges:
            graph.add(
                g.BetweenFactorPose2(a, b, self._pose(m), g.noiseModel.Gaussian.Covariance(cov))
            )
        return graph

    def add_step(self, motion: Pose2, cov: np.ndarray, at: Pose2) -> None:
        self.steps.append((motion, cov))
        self.values.insert(len(self.steps), self._pose(at))

    def add_closure(self, a: int, b: int, c: Closure, certain: bool = False) -> None:
        """A closure between key frames a and b; ``certain``: a known inlier, never turned off."""
        cov = c.match.result.covariance
        cov = (cov if cov is not None else np.zeros((3, 3))) + np.diag(np.square(CLOSURE_FLOOR))
        if certain:
            self.certain.add(len(self.closures))
        self.closures.append((a, b, c, cov))

    def optimise(self) -> None:
        """Graduated non-convexity (TLS) over the closures, the chain's edges known inliers, then
        least squares on the closures it keeps (``dropped``: those it turned off)."""
        g = self.gtsam
        self.dropped = set()
        if len(self.certain) < len(self.closures):
            plain = self._graph()
            first = 1 + len(self.steps)  # the prior and the steps come before the closures
            params = g.GncLMParams()
            params.setKnownInliers([*range(first), *(first + k for k in sorted(self.certain))])
            gnc = g.GncLMOptimizer(plain, self.values, params)
            # a closure is an inlier while its residual is within chi-squared (3 dof) at 99 %:
            # GTSAM's default (whitened cost 1) would take a right closure a little off for wrong
            gnc.setInlierCostThresholdsAtProbability(0.99)
            self.values = gnc.optimize()
            weights = gnc.getWeights()
            self.dropped = {k for k in range(len(self.closures)) if weights[first + k] < 0.5}
        self.values = g.LevenbergMarquardtOptimizer(
            self._graph(self.dropped), self.values, g.LevenbergMarquardtParams()
        ).optimize()

    def turned_off(self) -> list[Closure]:
        """The closures the last optimisation turned off, in the order they were added."""
        return [self.closures[k][2] for k in sorted(self.dropped)]

    def pose(self, n: int) -> Pose2:
        q = self.values.atPose2(n)
        return Pose2(q.x(), q.y(), q.theta())


@dataclass(frozen=True)
class Found:
    """What looking for a run's loops found: every candidate as its match judged it, the key
    frames' poses as the last optimisation during the run left them, each optimisation's time."""

    closures: list[Closure]
    estimate: list[Pose2]
    optimise_s: list[float]


def chain_edges(rows: list[PairMatch], p: LoopParams):
    """A run's chained poses, its key frames and the chain's edges between them (motion from
    key frame n-1 to n, its covariance)."""
    chained, keys = plan(rows, p)
    steps = [relative(chained[a], chained[b]) for a, b in zip(keys, keys[1:])]
    return chained, keys, list(zip(steps, edge_covariances(rows, keys)))


def close_loops(
    log: ScanLog, rows: list[PairMatch], params: Params, p: LoopParams = LoopParams(), on_key=None
) -> LoopRun:
    """Close the loops of a run (the rows of ``eval sequence``). ``on_key()`` is called after each
    key frame (progress)."""
    return solved(rows, p, find_closures(log, rows, params, p, on_key))


def find_closures(
    log: ScanLog, rows: list[PairMatch], params: Params, p: LoopParams, on_key=None
) -> Found:
    """Key frames along the run's chain, each matched against the old key frames it may see
    again, the graph optimised after each key frame that closed a loop (so the next predictions
    start from the corrected estimate)."""
    base = rows[0].frame != "laser"
    chained, keys, edges = chain_edges(rows, p)
    scans = scan_indices(rows)
    path = np.concatenate([[0.0], np.cumsum([m.translation_norm() for m, _ in edges])])
    graph, estimate = PoseGraph(), [Pose2()]
    chain = ChainUncertainty([chained[k] for k in keys], [cov for _, cov in edges])
    closures: list[Closure] = []
    times: list[float] = []
    anchor = 0  # the last key frame that closed a loop: the estimate is held there since
    for n in range(1, len(keys)):
        step, cov = edges[n - 1]
        estimate.append(estimate[-1] @ step)
        graph.add_step(step, cov, estimate[-1])
        closed = False
        spreads = chain.position_covariances(n)
        for j in candidates(estimate, n, path, chain, p):
            # how far the estimate may be off: the chain's drift since the later of the old key
            # frame and the last closure (the graph holds the map up to there)
            drift = spreads[max(j, anchor)] if max(j, anchor) < n else np.zeros((2, 2))
            spread = 3.0 * math.sqrt(float(np.linalg.eigvalsh(drift).max())) + p.reach_m
            c = verify(
                log,
                scans[keys[j]],
                scans[keys[n]],
                relative(estimate[j], estimate[n]),
                spread,
                params,
                p,
                base,
            )
            closures.append(c)
            if c.accepted:
                graph.add_closure(j, n, c)
                closed = True
        if closed:
            anchor = n
            t0 = time.perf_counter()
            graph.optimise()
            times.append(time.perf_counter() - t0)
            estimate = [graph.pose(k) for k in range(n + 1)]
        if on_key is not None:
            on_key()
    return Found(closures, estimate, times)


def solved(rows: list[PairMatch], p: LoopParams, found: Found) -> LoopRun:
    """The run with the closures found, its graph solved once more over all of them in one batch
    (a later closure may show an earlier one wrong)."""
    chained, keys, edges = chain_edges(rows, p)
    placed = place_scans(chained, keys, found.estimate)
    times = [*found.optimise_s, 0.0]
    return LoopRun(
        scan_indices(rows), keys, edges, found.closures, chained, placed, times, p
    ).decided({})


def place_scans(chained: list[Pose2], keys: list[int], key_poses: list[Pose2]) -> list[Pose2]:
    """Every scan of the run at its optimised pose: its chained pose relative to the key frame
    before it, set on that key frame's optimised pose."""
    out, n = [], 0
    for k, q in enumerate(chained):
        while n + 1 < len(keys) and keys[n + 1] <= k:
            n += 1
        out.append(key_poses[n] @ relative(chained[keys[n]], q))
    return out
