"""What a waypoint timeout costs against a move in PyFlyt: battery units and seconds per step.

Flies a policy (a run folder or a built-in: boustrophedon, random) on the evaluation
scenarios of a size with the PyFlyt backend and classifies every step by what happened:
``move``/``climb``/``descend`` (reached its waypoint), ``camera`` (a camera action's hold),
``geofence`` (a refused move), ``contact`` (a move with a collision contact that still ended
in time) and ``timeout`` (a move that ran out ``step_timeout_s``). ``--probe N`` adds N
deliberate collisions per scenario: from free cells next to an obstacle cell, a move into it
and one back. Each step kind is printed with its count, battery units and simulated seconds
per step, and its cost relative to an ordinary x/y move; the same flights are charged again
with the rotor power uncapped (``max_thrust_to_weight`` 1e6, the energy model before the
cap). Usage::

    python benchmarks/physics_energy.py --policy boustrophedon --episodes 2 --probe 6
    python benchmarks/physics_energy.py --policy runs/ppo-ewri --act stochastic --episodes 2
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict

import numpy as np

from pirl.agents.loading import load_policy
from pirl.config.physics import PhysicsConfig
from pirl.config.world import VCPPConfig
from pirl.evaluate.scenarios import scenario_seeds
from pirl.physics import Mission
from pirl.physics.flight import MOVE, normalized_power
from pirl.physics.pyflyt_backend import PyFlytFlight
from pirl.world import dynamics as D
from pirl.world.scenario import Scenario

UNCAPPED = 1e6  # max_thrust_to_weight that never caps: the energy model before the cap


class Recorder:
    """Per step kind: count, battery units (capped and uncapped) and simulated seconds."""

    def __init__(self) -> None:
        self.rows: dict[str, list[float]] = defaultdict(lambda: [0, 0.0, 0.0, 0.0])

    def fly(self, mission: Mission, flight: PyFlytFlight, action: int) -> tuple:
        """Fly one step and record it; returns what ``Mission.end_step`` returns."""
        uncapped_s = 0.0
        update = mission.update

        def spy(dt: float, pose, power: float = 1.0, contact: bool = False) -> bool:
            nonlocal uncapped_s
            ratios = flight.drone.motors.throttle / flight.hover_throttle
            uncapped_s += normalized_power(ratios) * dt
            return update(dt, pose, power, contact)

        before = mission.energy_used
        plan = mission.begin_step(action)
        mission.update = spy  # type: ignore[method-assign]
        try:
            pose = flight.fly(mission)
        finally:
            del mission.update
        seconds, timed_out, hit = mission._t, mission.timed_out, mission._contact_hit
        out = mission.end_step(pose)
        used = mission.energy_used - before
        camera = used - mission.physics.energy_per_hover_s * (
            mission._power_s + mission._power_after_contact_s
        )
        kind = mission._cause
        if plan.kind == MOVE and timed_out:
            kind = "timeout"
        elif plan.kind == MOVE and hit:
            kind = "contact"
        row = self.rows[kind]
        row[0] += 1
        row[1] += used
        row[2] += mission.physics.energy_per_hover_s * uncapped_s + camera
        row[3] += seconds
        return out

    def table(self) -> str:
        ref = self.rows.get("move")
        base = ref[1] / ref[0] if ref else float("nan")
        base_u = ref[2] / ref[0] if ref else float("nan")
        lines = [
            f"{'step kind':>9} {'steps':>6} {'units/step':>10} {'x move':>7} {'s/step':>7}"
            f" {'units/s':>8} | {'uncapped units/step':>19} {'x move':>7}"
        ]
        order = ("move", "climb", "descend", "hover", "geofence", "contact", "timeout")
        for kind in sorted(self.rows, key=lambda k: order.index(k) if k in order else 99):
            n, used, uncapped, seconds = self.rows[kind]
            lines.append(
                f"{kind:>9} {n:>6.0f} {used / n:>10.2f} {used / n / base:>7.1f} {seconds / n:>7.2f}"
                f" {used / max(seconds, 1e-9):>8.2f} | {uncapped / n:>19.2f}"
                f" {uncapped / n / base_u:>7.1f}"
            )
        return "\n".join(lines)


def probe_cells(mission: Mission, count: int, rng: np.random.Generator) -> list[tuple]:
    """Up to ``count`` (free cell, action into an adjacent obstacle cell) pairs, x/y moves."""
    blocked = mission.world.blocked[0]
    pairs = []
    for cell in np.argwhere(~blocked):
        for action in (D.X_PLUS, D.X_MINUS, D.Y_PLUS, D.Y_MINUS):
            d = D.MOVE_DELTAS[action]
            n = (cell[0] + d[0], cell[1] + d[1], cell[2] + d[2])
            if all(0 <= c < s for c, s in zip(n, blocked.shape, strict=True)) and blocked[n]:
                pairs.append((tuple(int(v) for v in cell), action))
    rng.shuffle(pairs)
    return pairs[:count]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="boustrophedon", help="run folder or built-in")
    parser.add_argument("--act", default="stochastic", help="how a trained policy acts")
    parser.add_argument("--episodes", type=int, default=2, help="evaluation scenarios flown")
    parser.add_argument("--size", type=int, nargs=3, default=(30, 30, 3))
    parser.add_argument("--probe", type=int, default=0, help="collision probes per scenario")
    args = parser.parse_args()
    size = tuple(args.size)
    cfg = VCPPConfig(size=size)
    physics = PhysicsConfig()
    rec = Recorder()
    start = time.perf_counter()
    for seed in scenario_seeds(size, args.episodes):
        policy = load_policy(args.policy, seed=seed, act=args.act)
        mission = Mission(cfg, physics)
        obs, info = mission.reset(seed)
        policy.reset(mission.world, 0, seed=seed)
        with PyFlytFlight(mission) as flight:
            done = False
            while not done:
                obs, terminated, truncated, info = rec.fly(
                    mission, flight, int(policy.act(obs, info))
                )
                done = terminated or truncated
        m = mission.metrics()
        print(
            f"{args.policy} scenario {seed}: {m['steps']} steps, VCR {m['vcr']:.3f},"
            f" end {m['end']}, {m['timeouts']} timeouts, {m['contacts']} contacts,"
            f" {m['recoveries']} recoveries,"
            f" {m['energy_used'] / m['sim_seconds']:.2f} units per simulated s"
        )
        for cell, action in probe_cells(mission, args.probe, np.random.default_rng(seed)):
            probe = Mission(cfg.replace(scale_by_alpha=False, battery_capacity=1e6), physics)
            scenario = mission.scenario
            probe.reset(scenario=Scenario(scenario.obstacles, cell, scenario.wind_seed))
            with PyFlytFlight(probe) as flight:
                rec.fly(probe, flight, action)  # into the obstacle cell
                rec.fly(probe, flight, action ^ 1)  # and away (x+ <-> x-, y+ <-> y-)
    print(
        f"\nPyFlyt QuadX, {'x'.join(map(str, size))}, default wind, {physics.step_timeout_s} s"
        f" timeout; max_thrust_to_weight {physics.max_thrust_to_weight} vs uncapped"
    )
    print(rec.table())
    print(f"wall {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
