"""Match two scans of your own recording and see why the pose ended where it did.

    python examples/match_two_scans.py                         # the bundled hand-held Hokuyo pair
    python examples/match_two_scans.py robot.bag 120 121 --topic /scan --rrd pair.rrd

Any recording the tool reads: ROS 1 and ROS 2 bags, MCAP, CARMEN logs, text scans. The two
numbers are record numbers (the bag's scan messages from 0).
"""

import argparse
import sys
from pathlib import Path

import mbicp_viz as mv

BUNDLED = Path(mv.__file__).parent / "examples" / "hokuyo-125-130.npz"


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("log", nargs="?", default=str(BUNDLED), help="a recording")
    ap.add_argument("pair", nargs="*", type=int, default=[0, 1], help="record numbers I J")
    ap.add_argument("--topic", help="the bag's LaserScan topic, when it has several")
    ap.add_argument("--matcher", default="improved", choices=mv.matchers())
    ap.add_argument("--params", help="a preset (e.g. poor-guess) or a TOML file")
    ap.add_argument("--guess", default="stored", help="stored, odometry, identity or search")
    ap.add_argument("--rrd", help="also write the match for rerun's viewer")
    args = ap.parse_args()
    if len(args.pair) != 2:
        sys.exit("error: give two record numbers, I J")
    try:
        log = mv.read_log(args.log, topic=args.topic)
        params = mv.params(args.matcher, args.params)
        m = mv.match(log, *args.pair, params, guess=args.guess)
        if args.rrd:
            mv.write_rrd(m, args.rrd)
    except mv.InputError as e:  # one line naming the file, line and field, as the CLI says it
        sys.exit(f"error: {e}")

    print(mv.report(m))
    # The record keeps every iteration: here, the pairs each one rejected and at what threshold.
    print("\niteration  kept  rejected  threshold [m]")
    for it in m.iterations:
        kept = int(it.pairs.kept.sum())
        threshold = "-" if it.threshold is None else f"{it.threshold:.4f}"
        print(f"{it.iteration:9d}  {kept:4d}  {len(it.pairs.status) - kept:8d}  {threshold:>13}")
    p = m.result.pose
    print(f"\nmotion of the {m.frame} frame: x {p.x:+.4f} m, y {p.y:+.4f} m, {p.theta:+.5f} rad")
    if args.rrd:
        print(f"written {args.rrd}: open it with `rerun {args.rrd}`")


if __name__ == "__main__":
    main()
