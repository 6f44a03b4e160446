"""Physics backend throughput: simulated seconds per wall second and episodes per minute.

Flies whole episodes of the PyFlyt backend (``pirl evaluate --sim physics``) at 30x30x3 with a
planner (boustrophedon), random actions and/or trained runs (a run folder, acting
stochastic), one process, and prints per policy the steps,
simulated seconds and wall seconds per episode, the real-time factor (simulated seconds per
wall second) and episodes per minute. PyFlyt's one-off numba compilation is paid by a warm-up
flight first and reported apart. CPU time is printed too: on a shared machine the wall time
depends on the neighbours. Usage::

    python benchmarks/physics_throughput.py [--episodes 3] [--policy boustrophedon random RUN]
        [--rates 240:120 240:80]

``--rates`` flies the same episodes at several PyBullet physics : controller rates and prints
each one's CPU-time rate as a ratio against the first pair's, measured in the same run, with
the flight figures (VCR, battery, timeouts, tracking error) that a cheaper rate may change.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from pirl.agents.loading import load_policy
from pirl.agents.policy import Policy, RandomPolicy
from pirl.config.physics import PhysicsConfig
from pirl.config.world import VCPPConfig
from pirl.evaluate.scenarios import scenario_seeds
from pirl.physics import run_physics_episode


def make_policy(name: str, seed: int) -> Policy:
    """A built-in by name or a trained run folder (acting stochastic, as the demo does)."""
    return load_policy(name, seed=seed, act="stochastic")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3, help="episodes per policy")
    parser.add_argument("--size", type=int, nargs=3, default=(30, 30, 3))
    parser.add_argument(
        "--policy",
        nargs="+",
        default=["boustrophedon", "random"],
        help="boustrophedon, random or a run folder",
    )
    parser.add_argument(
        "--rates", nargs="+", default=["240:120"], help="physics_hz:control_hz pairs to compare"
    )
    args = parser.parse_args()
    pairs = [tuple(int(v) for v in r.split(":")) for r in args.rates]
    physics = PhysicsConfig(physics_hz=pairs[0][0], control_hz=pairs[0][1])
    size = tuple(args.size)
    cfg = VCPPConfig(size=size)

    start = time.perf_counter()
    run_physics_episode(
        VCPPConfig(size=(5, 5, 3), max_steps=3, scale_by_alpha=False), RandomPolicy(0), 0, physics
    )
    warm = time.perf_counter() - start
    print(f"warm-up (PyFlyt's numba compilation, once per process): {warm:.1f} s")
    print(
        f"{'x'.join(map(str, size))}, physics {physics.physics_hz} Hz, control "
        f"{physics.control_hz} Hz, wind {physics.wind_mean} m/s + gusts {physics.wind_gust} m/s"
    )
    print(
        f"{'policy':>13} {'steps':>6} {'sim s':>7} {'wall s':>7} {'cpu s':>6} {'sim s/wall s':>12}"
        f" {'episodes/min':>12} {'VCR':>5} {'battery':>7} {'timeouts':>8}"
    )
    base: dict[str, float] = {}
    for hz, ctrl in pairs:
        physics = physics.replace(physics_hz=hz, control_hz=ctrl)
        print(f"physics {hz} Hz, control {ctrl} Hz")
        for name in args.policy:
            steps = sim = wall = cpu = vcr = battery = timeouts = track = 0.0
            for seed in scenario_seeds(size, args.episodes):  # the evaluation's scenarios
                policy = make_policy(name, seed)
                w0, c0 = time.perf_counter(), time.process_time()
                m = run_physics_episode(cfg, policy, seed, physics)
                wall += time.perf_counter() - w0
                cpu += time.process_time() - c0
                steps += m["steps"]
                sim += m["sim_seconds"]
                vcr += m["vcr"]
                battery += m["battery_left"]
                timeouts += m["timeouts"]
                track += m["tracking_error_m"]
            n = args.episodes
            base.setdefault(name, sim / cpu)
            print(
                f"{Path(name).name[:13]:>13} {steps / n:>6.0f} {sim / n:>7.1f} {wall / n:>7.1f}"
                f" {cpu / n:>6.1f}"
                f" {sim / wall:>12.1f} {60 * n / wall:>12.2f} {vcr / n:>5.3f} {battery / n:>7.3f}"
                f" {timeouts / n:>8.1f}  sim s per CPU s {sim / cpu:.1f} "
                f"({sim / cpu / base[name]:.2f}x the first rates), tracking {track / n:.3f} m"
            )


if __name__ == "__main__":
    main()
