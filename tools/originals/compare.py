"""This project's MbICP, ICP and PL-ICP against the original implementations, on real pairs.

    tools/originals/build.sh /tmp/originals
    python tools/originals/compare.py /tmp/originals LOG [--limit N] [--perturb XY_M THETA_DEG] [--seed S]
        [--every K] [--params FILE]

Every consecutive pair of LOG (the first N), the guess the log's stored relative pose moved
uniformly within the perturbation (as ``mbicp-viz bench matches --perturb``), each pair matched by
the original and by this project with the same defaults. Prints, per matcher, how many poses
agree within 1 mm and 0.01 deg, the success rates against the stored poses (0.1 m, 3.14 deg) and
the mean time per match (best of three runs; the originals timed around their matching call).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import subprocess
import time
from pathlib import Path

from mbicp_viz.core import MATCHERS, MbicpParams, Pose2, match, pose_error
from mbicp_viz.evaluation.bench import bench_guesses
from mbicp_viz.evaluation.pairs import stored_truth
from mbicp_viz.readers import read_log
from mbicp_viz.readers.params_toml import make_params

# Player's mbicp driver calls its library with MAXLASERPOINTS = 361 rays; unused rays lie beyond range
MAX_RAYS = 361


def mbicp_input(pairs, p: MbicpParams) -> str:
    head = [p.max_range, p.Bw, p.Br, p.L, p.laserStep, p.MaxDistInter, p.filter, int(p.ProjectionFilter),
            p.AsocError, p.MaxIter, p.errorRatio, p.errx_out, p.erry_out, p.errt_out, p.IterSmoothConv]
    lines = [" ".join(str(v) for v in head)]
    for a, b, g in pairs:
        if len(a.bearings) > MAX_RAYS:
            raise SystemExit(f"the C MbICP takes at most {MAX_RAYS} rays, the log has {len(a.bearings)}")
        lines.append(str(len(a.bearings)))
        for s in (a, b):  # the C code reads the reference's bearings from the object scan: the same grid
            lines += [f"{r if v else 1e6:.6f} {t:.9f}" for r, t, v in zip(s.ranges, s.bearings, s.valid)]
        lines.append(f"{float(g.x)!r} {float(g.y)!r} {float(g.theta)!r}")
    return "\n".join(lines) + "\n"


def csm_input(pairs) -> str:
    lines = []
    for a, b, g in pairs:
        lines.append(str(len(a.bearings)))
        for s in (a, b):
            lines += [f"{r if v else 0.0:.6f} {t:.9f} {int(v)}" for r, t, v in zip(s.ranges, s.bearings, s.valid)]
        lines.append(f"{float(g.x)!r} {float(g.y)!r} {float(g.theta)!r}")
    return "\n".join(lines) + "\n"


def run(exe: Path, args: list[str], text: str) -> tuple[list[Pose2], float]:
    """The original's poses and its mean time per match [ms] (printed by the driver)."""
    out = subprocess.run([str(exe), *args], input=text, capture_output=True, text=True, check=True)
    poses = [Pose2(*(float(v) for v in line.split()[1:4])) for line in out.stdout.split("\n") if line]
    total, count = out.stderr.split()
    return poses, 1000.0 * float(total) / int(count)


def ours(name: str, pairs, params=None) -> tuple[list[Pose2], float]:
    params = params if params is not None else MATCHERS[name].params_type()
    for a, b, g in pairs[:3]:  # compiled kernels loaded
        match(a, b, g, params)
    t0 = time.perf_counter()
    poses = [match(a, b, g, params).pose for a, b, g in pairs]
    return poses, 1000.0 * (time.perf_counter() - t0) / len(pairs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("built", type=Path, help="the folder build.sh built in")
    ap.add_argument("log")
    ap.add_argument("--limit", type=int, default=300)
    ap.add_argument("--perturb", type=float, nargs=2, default=(0.3, 15.0), metavar=("XY_M", "THETA_DEG"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--every", type=int, default=1, help="keep every K-th beam (a 681-beam Hokuyo as 341 beams: "
                    "the C MbICP takes at most 361)")
    ap.add_argument("--params", type=Path, help="improved MbICP's parameters (a --params file) for its last line")
    a = ap.parse_args()
    log = read_log(a.log)
    if a.every > 1:  # copies: the kernels take contiguous arrays (a strided view would compile them anew)
        log.scans = [dataclasses.replace(s, ranges=s.ranges[::a.every].copy(), bearings=s.bearings[::a.every].copy(),
                                         valid=s.valid[::a.every].copy(), beam_times=None) for s in log.scans]
    idx = log.consecutive_pairs(a.limit)
    guesses = bench_guesses(log, idx, (a.perturb[0], math.radians(a.perturb[1])), a.seed)
    pairs = [(log.scan(i), log.scan(j), g) for (i, j), g in zip(idx, guesses)]
    truths = [stored_truth(r, o) for r, o, _ in pairs]
    originals = {"mbicp": (a.built / "mbicp_pairs", [], mbicp_input(pairs, MbicpParams())),
                 "icp": (a.built / "csm_pairs", ["0"], csm_input(pairs)),
                 "plicp": (a.built / "csm_pairs", ["1"], csm_input(pairs))}
    print(f"{a.log}: {len(pairs)} pairs, guesses within +/-{a.perturb[0]:g} m, +/-{a.perturb[1]:g} deg (seed {a.seed})")
    timed = {}

    def ok(poses) -> int:
        return sum(t is not None and pose_error(p, t)[0] < 0.1 and pose_error(p, t)[1] < math.radians(3.14)
                   for p, t in zip(poses, truths))

    for name, (exe, args, text) in originals.items():
        runs = [run(exe, args, text) for _ in range(3)]
        mine = [ours(name, pairs) for _ in range(3)]
        theirs, ours_poses = runs[0][0], mine[0][0]
        agree = sum(e < 1e-3 and r < math.radians(0.01) for e, r in (pose_error(x, y) for x, y in zip(ours_poses, theirs)))
        t_orig, t_ours = min(r[1] for r in runs), min(m[1] for m in mine)
        timed[name] = t_orig
        print(f"{name:6s} agree within 1 mm / 0.01 deg: {agree}/{len(pairs)} ({100 * agree / len(pairs):.1f} %); "
              f"successes original {ok(theirs)}, ours {ok(ours_poses)}; mean time per match original "
              f"{t_orig:.3f} ms, ours {t_ours:.3f} ms (ratio {t_ours / t_orig:.2f})")
    params = make_params("improved", a.params)
    mine = [ours("improved", pairs, params) for _ in range(3)]
    improved = min(m[1] for m in mine)
    print(f"improved MbICP{f' ({a.params})' if a.params else ''} {improved:.3f} ms against CSM's PL-ICP "
          f"{timed['plicp']:.3f} ms per match (ratio {improved / timed['plicp']:.2f}); successes {ok(mine[0][0])}")

if __name__ == "__main__":
    main()
