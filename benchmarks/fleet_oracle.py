"""The oracle's advice in a fleet: what each UAV's advice is worth when the oracle knows its
teammates, against the same oracle blind to them.

Every UAV of a fleet carries out its own oracle answer (LLM-only with the oracle, one policy
per UAV, as ``pirl evaluate --methods llm-only --advisor oracle --uavs K`` plays it). The
fleet-aware oracle leads each UAV to useful ground it is the nearest UAV to (docs/fleets.md);
the blind one is asked with the teammates left out of its view, as if each UAV flew alone.
Prints, per world and K, the fleet's VCR, makespan to 0.99 of the seeable cells, speed-up
over one UAV (same scenarios) and the overlap between UAVs (cells seen by more than one UAV,
over cells seen): the advice PIRL's reward is shaped with.

Usage: ``python benchmarks/fleet_oracle.py --size 30x30x3 --site examples/sites/campus
--seeds 1000,1001,1002 --uavs 2,4``.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from fleet_planner import fleet_args  # the same command line (benchmarks/ is on the path)
from pirl.advice.oracle import OracleAdvisor
from pirl.agents.llm_only import LLMOnlyPolicy
from pirl.evaluate.fleet import fleet_records, speed_ups


class BlindOracle(OracleAdvisor):
    """The oracle asked about each UAV as if it flew alone (its teammates left out)."""

    def advise(self, prompts, views=None):
        if views is not None:
            views = [dataclasses.replace(v, teammates=np.zeros((0, 4)), rank=0) for v in views]
        return super().advise(prompts, views)


def main() -> None:
    worlds, seeds, ks = fleet_args(__doc__, "2,4")
    for name, cfg in worlds.items():
        began = time.perf_counter()
        for oracle in (OracleAdvisor(), BlindOracle()):
            kind = "blind" if isinstance(oracle, BlindOracle) else "fleet-aware"
            policy = LLMOnlyPolicy(oracle)
            rows = {k: fleet_records(cfg.replace(uavs=k), policy, seeds, {}, {}) for k in ks}
            gains = speed_ups(rows)
            for k in ks:
                eps = rows[k]
                gain = "never" if gains[k] is None else f"{gains[k]:.3f}"
                print(
                    f"{name:<10} {kind:<11} K={k:<2} VCR {np.mean([r['vcr'] for r in eps]):.3f} "
                    f"(mean of {len(seeds)}), makespan 0.99 {[r['makespan_99'] for r in eps]}, "
                    f"speed-up {gain}, overlap {np.mean([r['uav_overlap'] for r in eps]):.2f}",
                    flush=True,
                )
        print(f"{name}: {time.perf_counter() - began:.0f} s", flush=True)


if __name__ == "__main__":
    main()
