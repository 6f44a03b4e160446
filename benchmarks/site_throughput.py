"""World-steps per second on a site against a generated world, per observation block set.

The batched core (``EnvCore``, random actions) on the site and on ``--size`` in the same run,
interleaved, best of two per row, for the paper's observation and each optional block: the
ratio says whether a step's cost grows with the grid.

Usage: ``python benchmarks/site_throughput.py [--site examples/sites/town] [--size 60x60x3]
[--envs 16] [--seconds 1.5]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from env_throughput import core_rates  # noqa: E402

BLOCKS = (
    ("the paper's", {}),
    ("+ visits", {"obs_visits": True}),
    ("+ target (straight line)", {"obs_target": True}),
    ("+ target by path", {"obs_target": True, "obs_target_path": True}),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", default="examples/sites/town")
    parser.add_argument("--size", default="60x60x3")
    parser.add_argument("--envs", type=int, default=16)
    parser.add_argument("--seconds", type=float, default=1.5)
    args = parser.parse_args()
    size = [int(v) for v in args.size.split("x")]
    print(f"EnvCore({args.envs}) world-steps/s: {args.size} against site {args.site}")
    print(f"{'observation':<26} {args.size:>12} {'site':>12} {'ratio':>7}")
    for name, extra in BLOCKS:
        base = {"size": size, "footprint": "paper", **extra}
        best = {"base": 0.0, "site": 0.0}
        for _ in range(2):
            best["base"] = max(best["base"], core_rates(base, args.envs, args.seconds)["EnvCore"])
            on_site = {**base, "site": args.site}
            best["site"] = max(
                best["site"], core_rates(on_site, args.envs, args.seconds)["EnvCore"]
            )
        ratio = best["site"] / best["base"]
        print(f"{name:<26} {best['base']:>12,.0f} {best['site']:>12,.0f} {ratio:>6.2f}x")


if __name__ == "__main__":
    main()
