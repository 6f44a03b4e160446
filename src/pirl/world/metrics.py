"""Episode metrics (DESIGN.md section 9) read off a world's bookkeeping.

- VCR = covered / coverable.
- BE = VCR / (2 - b_end / b_start), battery normalized so b_start = 1.
- RVC = |C_redundant| / |C_covered|: covered cells that lay in the view of a redundant step (a
  step whose view added no new cell), over covered cells. This is our reading of the paper.
- overlap (literal) = cells seen in two or more steps / covered.
- views_per_cell = total coverable-cell views / covered.
"""

from __future__ import annotations

from pirl.world import dynamics as D
from pirl.world.state import WorldBatch


def episode_metrics(batch: WorldBatch, e: int) -> dict[str, float]:
    """Metrics of world ``e``'s episode so far (DESIGN.md section 9)."""
    r = batch.ints[e]
    covered = int(r[D.COVERED])
    coverable = int(r[D.COVERABLE])
    steps = int(r[D.STEPS])
    battery_left = batch.battery(e)
    vcr = covered / coverable if coverable else 0.0
    return {
        "vcr": vcr,
        "be": vcr / (2.0 - battery_left),
        "rvc": int(r[D.RED_CELLS]) / covered if covered else 0.0,
        "overlap": int(r[D.MULTI_CELLS]) / covered if covered else 0.0,
        "views_per_cell": int(r[D.VIEWS]) / covered if covered else 0.0,
        "steps": steps,
        "collisions": int(r[D.COLLISIONS]),
        "battery_left": battery_left,
        "covered": covered,
        "coverable": coverable,
        "redundant_steps": int(r[D.RED_STEPS]),
        "camera_share": int(r[D.CAM_ACTIONS]) / steps if steps else 0.0,
        # The first view at reset is included: one footprint per step plus the initial one.
        "mean_footprint": int(r[D.FOOT_SUM]) / (steps + 1),
        "final_tilt": int(r[D.TILT]),
        "final_zoom": r[D.ZOOM] / 10.0,
        "wind_pushes": int(r[D.WIND_PUSHES]),
    }
