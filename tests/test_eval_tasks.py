"""Which worlds each simulator plays: a reproduction judges its sites in the grid only."""

from __future__ import annotations

from pathlib import Path

from pirl.agents.methods import PLAYED_ALONE
from pirl.evaluate.runner import EvalPlan, _tasks, spec_for_builtin

CAMPUS = str(Path(__file__).resolve().parents[1] / "examples" / "sites" / "campus")


def _worlds(plan: EvalPlan) -> dict[str, set]:
    found: dict[str, set] = {}
    for _spec, world, sim, _seeds, _act, _uavs in _tasks(plan, workers=2):
        found.setdefault(sim, set()).add(world if isinstance(world, str) else tuple(world))
    return found


def test_sites_follow_their_simulator() -> None:
    specs = [spec_for_builtin(PLAYED_ALONE[0])]
    both = {"sims": ["grid", "physics"], "sim_sizes": {"physics": [(15, 15, 3)]}}
    plan = EvalPlan(specs, [(15, 15, 3), (30, 30, 3)], 2, sites=[CAMPUS], **both)
    # pirl evaluate --sim grid,physics --site: the site is flown too (docs/sites.md)
    assert _worlds(plan) == {
        "grid": {(15, 15, 3), (30, 30, 3), CAMPUS},
        "physics": {(15, 15, 3), CAMPUS},
    }
    grid_only = EvalPlan(specs, [(30, 30, 3)], 2, sites=[CAMPUS], sim_sites={"physics": []}, **both)
    assert _worlds(grid_only) == {"grid": {(30, 30, 3), CAMPUS}, "physics": {(15, 15, 3)}}
