"""Match every consecutive pair of your own log and score the run on a relations file, the SLAM
benchmark's own measure (Kümmerle et al. 2009): the matches chained, their Kalman fusion with the
odometry, and the raw odometry, beside each other.

    python examples/score_run.py intel.log intel.relations --offset 976052857.337 --rows run.jsonl

A relations file has one relation a line: t1 t2 x y z roll pitch yaw (the Freiburg format).
``--offset`` [s] is added to the log's stamps to meet the relations' clock. The rows it writes open
in the debugger: mbicp-viz serve LOG --rows ROWS.
"""

import argparse
import math
import sys

import mbicp_viz as mv


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("log", help="a recording with time stamps")
    ap.add_argument("relations", help="its relations file")
    ap.add_argument("--offset", type=float, default=0.0, help="[s] added to the log's stamps")
    ap.add_argument("--matcher", default="improved", choices=mv.matchers())
    ap.add_argument("--params", help="a preset (e.g. poor-guess) or a TOML file")
    ap.add_argument("--guess", default="odometry", help="stored, odometry, identity or search")
    ap.add_argument("--rows", help="write the run's rows here (JSON lines)")
    ap.add_argument("--workers", type=int, default=None, help="processes (default: every core)")
    args = ap.parse_args()
    try:
        log = mv.read_log(args.log)
        params = mv.params(args.matcher, args.params)
        rows = mv.run(log, params, guess=args.guess, workers=args.workers)
        scores = mv.score_run(log, rows, args.relations, offset=args.offset)
        if args.rows:
            mv.write_rows(rows, args.rows)
    except mv.InputError as e:  # one line naming the file, line and field
        sys.exit(f"error: {e}")

    print(f"{len(rows)} pairs matched with {args.matcher}")
    for score in scores:
        print(score.line())
    chained = scores[0]
    if chained.relations:
        print("the relations the chained run misses most:")
        for k, et, er in chained.worst:
            print(f"  relation {k + 1}: {et:.3f} m, {math.degrees(er):.2f} deg")
    if args.rows:
        print(f"open the run: mbicp-viz serve {args.log} --rows {args.rows}")


if __name__ == "__main__":
    main()
