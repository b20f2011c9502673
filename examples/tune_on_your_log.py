"""Tune improved MbICP's rejection (mad_k) and metric weight (L) on your own log with Optuna.

    python examples/tune_on_your_log.py robot.bag --trials 20 --limit 200
    python examples/tune_on_your_log.py intel.log --relations intel.relations --offset 976052857.337

With a relations file each trial is scored by the run's translational error on it (lower is
better); without one, by the mean share of each pair's object points that land on the reference
(higher is better: no ground truth needed). `mbicp-viz tune` is the full study (every parameter,
resumable, PostgreSQL); this is the idea in a page.
"""

import argparse
import sys

import numpy as np
import optuna

import mbicp_viz as mv


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("log", help="a recording")
    ap.add_argument("--relations", help="score on this relations file instead of the overlap")
    ap.add_argument("--offset", type=float, default=0.0, help="[s] added to the log's stamps")
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--limit", type=int, default=100, help="the first N pairs of the log")
    ap.add_argument("--guess", default="stored", help="stored, odometry, identity or search")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    try:
        log = mv.read_log(args.log)
    except mv.InputError as e:
        sys.exit(f"error: {e}")

    def objective(trial: optuna.Trial) -> float:
        params = mv.params(
            "improved",
            mad_k=trial.suggest_float("mad_k", 1.0, 4.0),
            L=trial.suggest_float("L", 0.3, 5.0, log=True),
        )
        rows = mv.run(log, params, guess=args.guess, limit=args.limit, workers=1)
        if args.relations:
            return mv.score_run(log, rows, args.relations, offset=args.offset)[0].trans[0]
        return float(np.mean([r.on_ref for r in rows if r.on_ref is not None]))

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    direction = "minimize" if args.relations else "maximize"
    study = optuna.create_study(
        direction=direction, sampler=optuna.samplers.TPESampler(seed=args.seed)
    )
    study.enqueue_trial({"mad_k": mv.params("improved").mad_k, "L": mv.params("improved").L})
    try:
        study.optimize(objective, n_trials=args.trials)
    except mv.InputError as e:
        sys.exit(f"error: {e}")
    what = "translational error [m]" if args.relations else "mean share of points on the ref"
    print(f"defaults: {what} {study.trials[0].value:.4f}")
    print(f"best of {args.trials}: {what} {study.best_value:.4f} with {study.best_params}")
    best = "".join(f"\n{k} = {v:.4g}" for k, v in study.best_params.items())
    print(f"as a file for --params:\n[improved]{best}")


if __name__ == "__main__":
    main()
