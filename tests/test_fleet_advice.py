"""PIRL in a fleet: advice about each UAV that knows its teammates, PARE over a fleet's
slots (parked UAVs neither shaped nor counted), and PIRL trained on mixed fleet sizes."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from pirl.advice.oracle import OracleAdvisor, oracle_recommendation
from pirl.advice.prompt import FLEET_LINE, PromptState, build_prompt
from pirl.advice.state import advice_requests
from pirl.config.world import VCPPConfig
from pirl.env.fleet import FleetVecEnv, MixedFleetVecEnv, parallel_env
from pirl.world.planning import WorldView, claims
from test_pare_wrapper import make_pare  # PARE over an env, as training builds it

OPEN = {"size": (16, 16, 3), "obstacles_min": 0, "obstacles_max": 0, "wind_prob": 0.0}


def _target(rec, view: WorldView) -> tuple[int, int, int]:
    x, y, z = view.position
    return x + rec.dx, y + rec.dy, z + rec.dz


def test_one_uav_sees_no_teammates_and_its_prompt_is_unchanged():
    env = parallel_env(uavs=1, size=(12, 12, 3))
    env.reset(seed=3)
    view = WorldView.of(env.world, 0)
    assert view.teammates.shape == (0, 4) and view.rank == 0
    prompts, _ = advice_requests(env.world, [0], OracleAdvisor(), "paper")
    assert FLEET_LINE not in prompts[0] and "Teammates" not in prompts[0]


def test_a_fleets_prompt_names_the_teammates_still_flying():
    env = parallel_env(uavs=3, **OPEN)
    env.reset(seed=4)
    world = env.world
    for variant, header in (("paper", FLEET_LINE), ("compact", "Teammates [x,y,z,battery]")):
        prompts, _ = advice_requests(world, [1], OracleAdvisor(), variant)
        line = prompts[0].splitlines()[-1]
        assert line.startswith(header)
        for u in (0, 2):
            x, y, z = world.position(u)
            cell = f"[{x}, {y}, {z}]" if variant == "paper" else f"[{x},{y},{z},"
            assert cell in line
    world.left[2] = True  # a UAV that has left is no teammate
    view = WorldView.of(world, 1)
    assert view.teammates.shape == (1, 4) and view.rank == 1
    state = PromptState((1, 2, 0), 90, 0, 1.0, 0.5, 0.1, (16, 16, 3), teammates=((3, 4, 1, 0.5),))
    assert build_prompt(state).endswith(f"{FLEET_LINE}: [3, 4, 1] battery 0.50")


def test_claims_split_the_free_cells_by_moves_and_agree_between_teammates():
    env = parallel_env(uavs=2, **OPEN)
    env.reset(seed=5)
    world = env.world
    a, b = (WorldView.of(world, e) for e in (0, 1))
    own_a, own_b = claims(a), claims(b)
    assert np.array_equal(own_a, own_b)  # both draw the same borders (slot order)
    free = ~a.blocked
    assert (own_a[free] >= 0).all() and set(np.unique(own_a[free])) == {0, 1}
    x, y, z = a.position
    assert own_a[x, y, z] == 0 and own_b[b.position] == 1


def test_the_fleet_oracle_sends_two_uavs_to_different_ground():
    """Two UAVs side by side in an open world: the single-UAV oracle sends both the same way;
    the fleet's leads each into its own half."""
    env = parallel_env(uavs=2, **OPEN)
    env.reset(seed=6)
    world = env.world
    apart = 0
    for _ in range(30):
        views = [WorldView.of(world, e, copy=True) for e in (0, 1)]
        recs = [oracle_recommendation(v) for v in views]
        owner = claims(views[0])
        for u, (rec, view) in enumerate(zip(recs, views, strict=True)):
            step = _target(rec, view)
            assert step not in view.teammate_cells  # never into a teammate
            if step != view.position and step[2] == view.position[2]:
                assert owner[step] == u or not (owner == u).any()
        apart += recs[0].to_text() != recs[1].to_text()
        masks = env.action_masks()
        actions = {}
        for u, rec in enumerate(recs):
            move = (rec.dx, rec.dy, rec.dz)
            deltas = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
            a = deltas.index(move) if move in deltas else int(np.flatnonzero(masks[f"uav_{u}"])[0])
            actions[f"uav_{u}"] = a if masks[f"uav_{u}"][a] else 11
        env.step(actions)
    assert apart > 0


def _parked_rollout(venv, steps: int = 120):
    pare = make_pare(venv, OracleAdvisor(), mode="sync")
    pare.reset()
    rng = np.random.default_rng(0)
    flown = parked_seen = 0
    for _ in range(steps):
        masks = pare.venv.action_masks()
        actions = [rng.choice(np.flatnonzero(m)) for m in masks]
        _, rewards, _, infos = pare.step(np.array(actions))
        for e, info in enumerate(infos):
            if info.get("fleet_active", True):
                flown += 1
            else:
                parked_seen += 1
                assert info["pare"]["f_llm"] == 0.0 and rewards[e] == 0.0
    return pare, flown, parked_seen


def test_pare_shapes_each_flying_uav_and_leaves_parked_ones_alone():
    """Batteries for about 20 moves: UAVs leave at different steps and wait, parked, while
    their teammates fly; PARE neither shapes nor counts a parked UAV's steps."""
    cfg = VCPPConfig(**OPEN, uavs=3, reward="ewri", llm_weight=True, battery_capacity=22.0)
    pare, flown, parked = _parked_rollout(FleetVecEnv(2, cfg))
    assert parked > 0
    assert pare.stats.steps == flown  # UAV steps, not slots


def test_pare_runs_over_fleets_of_several_sizes_side_by_side():
    cfg = VCPPConfig(**OPEN, reward="ewri", llm_weight=True, battery_capacity=22.0)
    venv = MixedFleetVecEnv(6, cfg, [1, 2])
    pare, flown, parked = _parked_rollout(venv, 80)
    assert venv.num_envs == 3 * 1 + 2 * 2 and pare.stats.steps == flown and parked > 0
    views = venv.world_views(range(venv.num_envs))
    assert [v.cfg.uavs for v in views] == [1, 1, 1, 2, 2, 2, 2]
    assert all(len(v.teammates) <= v.cfg.uavs - 1 for v in views)


def test_pirl_trains_on_fleets_of_one_and_two(tmp_path):
    """``pirl train --method pirl --uavs 1,2`` with the oracle: advice about every UAV, its
    teammates named, one shared policy."""
    run = tmp_path / "pirl"
    cmd = [
        sys.executable, "-m", "pirl", "train", "--config", "test", "--method", "pirl",
        "--advisor", "oracle", "--uavs", "1,2", "--steps", "1024", "--out", str(run),
    ]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    meta = json.loads((run / "meta.json").read_text())
    assert meta["complete"] and "uavs:\n  - 1\n  - 2" in (run / "config.yaml").read_text()
    assert meta["label"].endswith(" [fleets of 1, 2 UAVs]")  # its rows say how it trained
    stats = json.loads((run / "advisor_stats.json").read_text())
    assert stats["steps"] > 0 and stats["advisor"] == "oracle (not an LLM)"


def test_llm_only_flies_a_fleet_each_uav_asking_about_itself():
    """LLM-only in a fleet (here with the oracle): one policy per UAV, every call counted,
    no two UAVs in one cell."""
    from pirl.agents.llm_only import LLMOnlyPolicy
    from pirl.evaluate.fleet import fleet_records

    policy = LLMOnlyPolicy(OracleAdvisor(), max_calls=40)
    cfg = VCPPConfig(**OPEN)
    one = fleet_records(cfg, policy, [1000], {}, {})[0]
    two = fleet_records(cfg.replace(uavs=2), policy, [1000], {}, {})[0]
    assert one["uavs"] == 1 and two["uavs"] == 2 and two["collisions"] == 0
    assert 0 < one["llm_calls"] <= 40 and 40 < two["llm_calls"] <= 80  # 40 per UAV
    assert policy.calls == one["llm_calls"] + two["llm_calls"]
    assert two["vcr"] >= one["vcr"]
