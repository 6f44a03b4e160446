"""The planner's fleets: makespan and speed-up of the area split + boustrophedon per part.

For each world (``--size`` and/or ``--site``, repeatable) and each scenario seed, one UAV and
fleets of K UAVs cover the same scenario (UAV 1 starts where the single UAV starts); prints
the fleet's VCR, its makespan to 0.99 of the seeable cells, the speed-up (makespan with K over
one UAV's, mean over seeds), the overlap between UAVs and the near misses. The same episodes
as ``pirl evaluate --methods boustrophedon --uavs ...`` plays, on the seeds given.

Usage: ``python benchmarks/fleet_planner.py --size 60x60x3 --site examples/sites/campus
--seeds 1000,1001,1002 --uavs 1,2,4,8``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pirl.config.world import VCPPConfig
from pirl.evaluate.fleet import run_fleet_episode, speed_ups
from pirl.world.seeable import with_site


def fleet_args(doc: str, uavs: str) -> tuple[dict[str, VCPPConfig], list[int], list[int]]:
    """The fleet benchmarks' command line: the worlds by name, the scenario seeds and the
    fleet sizes (K = 1 always among them, for the speed-ups)."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--size", action="append", default=[], help="XxYxZ, repeatable")
    parser.add_argument("--site", action="append", default=[], help="site folder, repeatable")
    parser.add_argument("--seeds", default="1000,1001,1002")
    parser.add_argument("--uavs", default=uavs)
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    ks = sorted({1, *(int(k) for k in args.uavs.split(","))})
    worlds = {s: VCPPConfig(size=tuple(int(v) for v in s.split("x"))) for s in args.size}
    worlds |= {site.rstrip("/").split("/")[-1]: with_site(VCPPConfig(), site) for site in args.site}
    return worlds, seeds, ks


def main() -> None:
    worlds, seeds, ks = fleet_args(__doc__, "1,2,4,8")
    for name, cfg in worlds.items():
        began = time.perf_counter()
        rows = {k: [run_fleet_episode(cfg.replace(uavs=k), s).row for s in seeds] for k in ks}
        gains = speed_ups(rows)
        for k in ks:
            eps = rows[k]
            gain = "never" if gains[k] is None else f"{gains[k]:.3f}"
            print(
                f"{name:<10} K={k:<2} VCR {min(r['vcr'] for r in eps):.3f} (lowest of "
                f"{len(seeds)}), makespan 0.99 {[r['makespan_99'] for r in eps]}, speed-up "
                f"{gain}, overlap {np.mean([r['uav_overlap'] for r in eps]):.2f}, near misses "
                f"{np.mean([r['near_misses'] for r in eps]):.0f}",
                flush=True,
            )
        print(f"{name}: {time.perf_counter() - began:.0f} s", flush=True)


if __name__ == "__main__":
    main()
