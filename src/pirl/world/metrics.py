"""Episode metrics (docs/design.md: metrics) read off a world's bookkeeping.

- VCR = covered / coverable (on a site: over its seeable cells; ``vcr_all`` over all of its
  coverable cells).
- BE = VCR / (2 - b_end / b_start), battery normalized so b_start = 1.
- RVC = |C_redundant| / |C_covered|: covered cells that lay in the view of a redundant step (a
  step whose view added no new cell), over covered cells. This is our reading of the paper.
- overlap (literal) = cells seen in two or more steps / covered.
- views_per_cell = total coverable-cell views / covered.
"""

from __future__ import annotations

import numpy as np

from pirl.world.state import WorldBatch

LOOP_WINDOW = 60
"""Steps at the end of an episode whose cells ``tail_cells`` counts."""
LOOP_CELLS = 10
"""An episode whose last :data:`LOOP_WINDOW` steps visit fewer cells than this ended in a loop."""


class PathTail:
    """The cells each world of a batch visited in its last :data:`LOOP_WINDOW` steps.

    A policy caught between two cells (a wall it cannot pass, a target it cannot reach) flies
    on until its battery ends; its episode's VCR looks merely low. Its tail shows the loop:
    ``tail_cells`` of an episode is the number of distinct cells of its last 60 steps.
    """

    def __init__(self, n: int) -> None:
        self.cells = np.full((n, LOOP_WINDOW), -1, dtype=np.int64)

    def record(self, world: WorldBatch, live: np.ndarray | None = None) -> None:
        """Note the cell where each world of ``live`` (default: every world) is after its step."""
        if live is None:
            live = np.arange(len(self.cells))
        st = world.status[live]
        _, ny, nz = world.cfg.size
        code = (st["x"] * ny + st["y"]) * nz + st["z"]
        self.cells[live, st["steps"] % LOOP_WINDOW] = code

    def distinct(self, e: int) -> int:
        """Distinct cells of world ``e``'s last :data:`LOOP_WINDOW` steps."""
        row = self.cells[e]
        return int(np.unique(row[row >= 0]).size)


NEAR_COMPLETE = 0.99
"""The share of coverable cells at which an episode counts as nearly complete: its step there
(``steps_to_99``) compares a method's pace with the planner's whatever their endings."""


class Milestone:
    """The step at which each world of a batch first covered :data:`NEAR_COMPLETE` of its
    coverable cells (-1 while it has not)."""

    def __init__(self, n: int, share: float = NEAR_COMPLETE) -> None:
        self.share = share
        self.first = np.full(n, -1, dtype=np.int64)

    def record(self, world: WorldBatch, live: np.ndarray | None = None) -> None:
        """After a step of the worlds of ``live`` (default: every world)."""
        if live is None:
            live = np.arange(len(self.first))
        st = world.status[live]
        reached = st["covered"] >= self.share * np.maximum(st["coverable"], 1)
        new = reached & (self.first[live] < 0)
        self.first[live[new]] = st["steps"][new]

    def steps(self, e: int) -> int | None:
        """World ``e``'s step at the milestone, or None when it never got there."""
        return int(self.first[e]) if self.first[e] >= 0 else None


def episode_metrics(batch: WorldBatch, e: int) -> dict[str, float]:
    """Metrics of world ``e``'s episode so far (docs/design.md: metrics)."""
    r = dict(zip(batch.status.dtype.names, batch.status[e].tolist(), strict=True))
    covered = r["covered"]
    coverable = r["coverable"]
    steps = r["steps"]
    battery_left = batch.battery(e)
    vcr = covered / coverable if coverable else 0.0
    everything = int(batch.coverable_all[batch.world_of(e)])
    return {
        "vcr": vcr,
        # On a site: the share of all its coverable cells, seeable or not (= vcr elsewhere).
        "vcr_all": covered / everything if everything else 0.0,
        "be": vcr / (2.0 - battery_left),
        "rvc": r["redundant_cells"] / covered if covered else 0.0,
        "overlap": r["multi_cells"] / covered if covered else 0.0,
        "views_per_cell": r["cell_views"] / covered if covered else 0.0,
        "steps": steps,
        "collisions": r["collisions"],
        "battery_left": battery_left,
        "covered": covered,
        "coverable": coverable,
        "redundant_steps": r["redundant_steps"],
        "camera_share": r["camera_actions"] / steps if steps else 0.0,
        # The first view at reset is included: one footprint per step plus the initial one.
        "mean_footprint": r["footprint_sum"] / (steps + 1),
        "final_tilt": r["tilt"],
        "final_zoom": r["zoom10"] / 10.0,
        "wind_pushes": r["wind_pushes"],
        # The env's stall guard (env.stall_guard) chose these steps' actions, not the policy.
        "guarded_steps": int(batch.guarded[e]),
        "guarded_share": int(batch.guarded[e]) / steps if steps else 0.0,
    }


def fleet_metrics(batch: WorldBatch, g: int) -> dict[str, float]:
    """Metrics of world ``g``'s fleet so far: coverage (VCR), UAVs, the episode's steps (the
    fleet's clock), energy used by all UAVs (battery units, 1 = one full battery), overlap
    (ground cells seen by more than one UAV, over cells seen), near misses (pairs of UAVs in
    face-adjacent cells, summed over steps), yields and each UAV's credited cells."""
    k = batch.uavs
    rows = slice(g * k, g * k + k)
    st = batch.status[rows]
    covered, coverable = int(st["covered"][0]), int(st["coverable"][0])
    seen_by = batch.seen_by[g]
    seen = int((seen_by != 0).sum()) if k > 1 else covered
    shared = int((_bit_count(seen_by) >= 2).sum()) if k > 1 else 0
    return {
        "uavs": k,
        "vcr": covered / coverable if coverable else 0.0,
        "covered": covered,
        "coverable": coverable,
        "fleet_steps": int(batch.clock[g]) if k > 1 else int(st["steps"][0]),
        "energy_used": float((batch.capacity - batch.energy[rows]).clip(0).sum() / batch.capacity),
        "uav_overlap": shared / seen if seen else 0.0,
        "near_misses": int(batch.near[g]),
        "yields": int(batch.yields[rows].sum()),
        "collisions": int(st["collisions"].sum()),
        "credit": [int(c) for c in batch.credit[rows]],
    }


def _bit_count(a: np.ndarray) -> np.ndarray:
    """Set bits of each int64 (the UAVs that saw a cell)."""
    count = np.zeros(a.shape, dtype=np.int64)
    v = a.copy()
    while v.any():
        count += v & 1
        v >>= 1
    return count
