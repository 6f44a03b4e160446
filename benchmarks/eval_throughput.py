"""Evaluation throughput: episodes per second at 30x30x3 and 60x60x3, 1 vs 2 workers.

Evaluates the same plan (a trained run if given, else the boustrophedon planner and a random
policy) with 1 and with 2 worker processes and prints episodes/s and the scaling ratio. Worker
start-up (spawned processes import torch) is included, as a user sees it.

Usage: ``python benchmarks/eval_throughput.py [--run runs/ppo-ewri-s0] [--episodes 8]``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from pirl.evaluate.runner import (
    EvalPlan,
    evaluate,
    process_pool,
    spec_for_builtin,
    spec_for_run,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, default=None, help="a finished run folder")
    parser.add_argument("--episodes", type=int, default=8, help="episodes per size and method")
    args = parser.parse_args()
    specs = [spec_for_run(args.run)] if args.run else []
    specs += [spec_for_builtin("boustrophedon"), spec_for_builtin("random")]
    print(f"methods: {', '.join(s.label for s in specs)}; {args.episodes} episodes each")
    print(f"{'size':>9} {'1 worker ep/s':>14} {'2 workers ep/s':>15} {'scaling':>8}")
    for size in ((30, 30, 3), (60, 60, 3)):
        rates = []
        for workers in (1, 2):
            plan = EvalPlan(specs=specs, sizes=[size], episodes=args.episodes)
            with tempfile.TemporaryDirectory() as tmp:
                start = time.perf_counter()
                # workers=1 still uses a process pool here, so both rows pay the same start-up.
                evaluate(plan, Path(tmp), workers, executor_factory=process_pool)
                rates.append(len(specs) * args.episodes / (time.perf_counter() - start))
        name = "x".join(map(str, size))
        print(f"{name:>9} {rates[0]:>14.2f} {rates[1]:>15.2f} {rates[1] / rates[0]:>8.2f}")


if __name__ == "__main__":
    main()
