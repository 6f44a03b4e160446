"""Environment throughput: agent-steps per second with random actions.

Compares a single ``VCPPEnv`` stepped in a Python loop with ``make_vec_env(64)`` on 15x15x3
and 60x60x3, both footprint models, and prints the batched/single ratio measured in the same
run. Usage: ``python benchmarks/env_throughput.py [--seconds 3] [--envs 64]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pirl.env import VCPPEnv, make_vec_env


def single_rate(size: tuple[int, int, int], footprint: str, seconds: float) -> float:
    env = VCPPEnv(size=size, footprint=footprint)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    env.step(0)  # compile outside the timed loop
    actions = rng.integers(0, 12, 100_000).tolist()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for a in actions[steps % 90_000 : steps % 90_000 + 1000]:
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:
                env.reset()
        steps += 1000
    return steps / (time.perf_counter() - start)


def vec_rate(
    size: tuple[int, int, int], footprint: str, envs: int, seconds: float, parallel: bool
) -> float:
    venv = make_vec_env(envs, seed=0, size=size, footprint=footprint, parallel=parallel)
    venv.reset()
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 12, (1000, envs))
    venv.step(actions[0])  # compile outside the timed loop
    batches, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for k in range(100):
            venv.step(actions[(batches + k) % 1000])
        batches += 100
    return batches * envs / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="timing per cell of the table")
    parser.add_argument("--envs", type=int, default=64, help="worlds in the batched env")
    args = parser.parse_args()
    print(f"agent-steps/s, random actions, {args.seconds:.0f} s per measurement")
    head = f"vec{args.envs}"
    print(
        f"{'size':>9} {'footprint':>9} {'single':>10} {head + ' 1 thread':>16} {'ratio':>6}"
        f" {head + ' threads':>16} {'ratio':>6}"
    )
    for size in ((15, 15, 3), (60, 60, 3)):
        for footprint in ("paper", "frustum"):
            single = single_rate(size, footprint, args.seconds)
            serial = vec_rate(size, footprint, args.envs, args.seconds, parallel=False)
            threaded = vec_rate(size, footprint, args.envs, args.seconds, parallel=True)
            name = "x".join(map(str, size))
            print(
                f"{name:>9} {footprint:>9} {single:>10,.0f} {serial:>16,.0f}"
                f" {serial / single:>6.1f} {threaded:>16,.0f} {threaded / single:>6.1f}"
            )


if __name__ == "__main__":
    main()
