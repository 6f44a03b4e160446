"""A fleet of UAVs in one world: the rules (turns, cells, credit, leaving), the observation's
teammates block, and the two APIs (PettingZoo's ParallelEnv, the SB3 VecEnv of slots)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from pirl.config.errors import ConfigError
from pirl.env.fleet import FleetParallelEnv, make_fleet_vec_env
from pirl.env.observation import N_TEAMMATE, obs_size_for
from pirl.env.sb3_vec import make_vec_env
from pirl.env.vcpp_env import VCPPEnv
from pirl.world import dynamics as D
from pirl.world.metrics import fleet_metrics


def _masked_actions(masks: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return np.array([rng.choice(np.flatnonzero(m)) for m in masks], dtype=np.int64)


def test_parallel_api_test_passes():
    parallel_api_test(FleetParallelEnv(uavs=3, size=(15, 15, 3)), num_cycles=400)


def test_one_uav_fleet_is_the_single_env_step_for_step():
    single = VCPPEnv(size=(15, 15, 3), obs_target=True, reward="ewri")
    fleet = FleetParallelEnv(uavs=1, size=(15, 15, 3), obs_target=True, reward="ewri")
    for seed in range(6):
        obs, _ = single.reset(seed=seed)
        fobs, _ = fleet.reset(seed=seed)
        rng = np.random.default_rng(seed)
        np.testing.assert_array_equal(obs, fobs["uav_0"])
        while fleet.agents:
            a = int(rng.integers(D.N_ACTIONS))
            obs, r, term, trunc, _ = single.step(a)
            fobs, fr, fterm, ftrunc, _ = fleet.step({"uav_0": a})
            np.testing.assert_array_equal(obs, fobs["uav_0"])
            assert (r, term, trunc) == (fr["uav_0"], fterm["uav_0"], ftrunc["uav_0"])
        assert term or trunc


def test_pettingzoo_and_vecenv_agree_step_for_step():
    settings = {"uavs": 3, "size": (18, 18, 3), "obs_teammates": 2, "reward": "ewri"}
    pz = FleetParallelEnv(**settings)
    for seed in (11, 12, 13):
        vec = make_fleet_vec_env(1, seed=seed, **settings)
        vobs = vec.reset()
        obs, infos = pz.reset(seed=seed)
        rng = np.random.default_rng(seed)
        while pz.agents:
            for u, a in enumerate(pz.possible_agents):
                if a in pz.agents:
                    np.testing.assert_array_equal(obs[a], vobs[u])
                    np.testing.assert_array_equal(infos[a]["action_mask"], vec.action_masks()[u])
            actions = _masked_actions(vec.action_masks(), rng)
            live = [a for a in pz.possible_agents if a in pz.agents]
            vobs, vr, vdone, vinfos = vec.step(actions)
            obs, r, term, trunc, infos = pz.step(
                {a: int(actions[pz.possible_agents.index(a)]) for a in live}
            )
            for a in live:
                u = pz.possible_agents.index(a)
                assert r[a] == float(np.float32(vr[u])) or r[a] == pytest.approx(float(vr[u]))
                assert (term[a] or trunc[a]) == bool(vdone[u])
                if term[a] or trunc[a]:
                    np.testing.assert_array_equal(obs[a], vinfos[u]["terminal_observation"])


def test_two_uavs_never_share_a_cell_and_credit_adds_up():
    env = FleetParallelEnv(uavs=4, size=(12, 12, 3), wind_prob=0.3)
    rng = np.random.default_rng(1)
    for seed in range(5):
        obs, infos = env.reset(seed=seed)
        w = env.world
        start_covered = int(w.status[0]["covered"])
        assert int(w.credit.sum()) == start_covered
        while env.agents:
            flying = [u for u in range(4) if not w.left[u]]
            cells = {w.position(u) for u in flying}
            assert len(cells) == len(flying)
            for u in flying:  # the mask never offers a teammate's cell
                x, y, z = w.position(u)
                mask = infos[env.possible_agents[u]]["action_mask"]
                for a in range(D.N_MOVES):
                    dx, dy, dz = D.MOVE_DELTAS[a]
                    if (x + dx, y + dy, z + dz) in cells:
                        assert not mask[a]
            actions = {
                a: int(rng.choice(np.flatnonzero(infos[a]["action_mask"]))) for a in env.agents
            }
            obs, r, term, trunc, infos = env.step(actions)
        covered = int(w.status[0]["covered"])
        assert (w.status["covered"] == covered).all()  # the fleet's coverage, in every slot
        assert int(w.credit.sum()) == covered
        m = fleet_metrics(w, 0)
        assert m["uavs"] == 4 and sum(m["credit"]) == covered
        assert 0.0 <= m["uav_overlap"] <= 1.0


def test_complete_coverage_ends_every_uav_and_a_spent_uav_parks():
    env = make_fleet_vec_env(1, seed=2, uavs=2, size=(6, 6, 3), battery_capacity=400.0)
    env.reset()
    rng = np.random.default_rng(3)
    for _ in range(2000):
        actions = _masked_actions(env.action_masks(), rng)
        before = env.core.world.status["covered"][0]
        obs, r, done, infos = env.step(actions)
        if done.all():
            assert "terminal_observation" in infos[0] and "terminal_observation" in infos[1]
            break
    else:
        pytest.fail("the fleet never finished a small world")
    assert before >= 0
    # A parked slot: one action, reward 0, done at every step until its world ends.
    env = make_fleet_vec_env(1, seed=0, uavs=2, size=(15, 15, 3), energy_hover=0.0)
    env.reset()
    w = env.world
    w.energy[0] = 0.05  # UAV 1 spends its battery on its next move
    obs, r, done, infos = env.step(np.array([D.X_PLUS, D.TILT_MINUS]))
    obs, r, done, infos = env.step(np.array([D.X_PLUS, D.TILT_PLUS]))
    assert w.left[0] and not w.left[1]
    assert env.action_masks()[0].sum() == 1 and env.action_masks()[0][D.PARKED]
    position = w.position(0)
    obs, r, done, infos = env.step(np.array([D.PARKED, D.TILT_MINUS]))
    assert r[0] == 0.0 and done[0] and not done[1]
    assert infos[0]["fleet_active"] is False
    assert w.position(0) == position


def test_teammates_block_is_the_same_size_for_any_fleet():
    sizes = {k: obs_size_for(FleetParallelEnv(uavs=k, obs_teammates=3).cfg) for k in (1, 2, 5)}
    assert len(set(sizes.values())) == 1
    env = FleetParallelEnv(uavs=2, size=(15, 15, 3), obs_teammates=3)
    obs, _ = env.reset(seed=4)
    block = obs["uav_0"][-3 * N_TEAMMATE :]
    assert block[0] == 1.0 and block[N_TEAMMATE:].sum() == 0.0  # one teammate, then zeros
    (x0, y0, _), (x1, y1, _) = env.world.position(0), env.world.position(1)
    assert block[1] == pytest.approx(((x1 - x0) / 14 + 1) / 2)
    assert block[2] == pytest.approx(((y1 - y0) / 14 + 1) / 2)
    single = VCPPEnv(size=(15, 15, 3), obs_teammates=3)
    obs1, _ = single.reset(seed=4)
    assert obs1[-3 * N_TEAMMATE :].sum() == 0.0


def test_bad_fleets_are_one_line():
    with pytest.raises(ConfigError, match=r"env.uavs=0"):
        FleetParallelEnv(uavs=0)
    with pytest.raises(ConfigError, match=r"env.uavs=2: .*flies one UAV"):
        VCPPEnv(uavs=2)
    with pytest.raises(ConfigError, match=r"flies one UAV"):
        make_vec_env(2, uavs=3)
    # Three free cells, five UAVs: refused at reset, in one line.
    env = FleetParallelEnv(uavs=5, size=(3, 3, 3), obstacles_min=0, obstacles_max=0)
    env.reset(seed=0)  # 27 free cells: fine
    crowded = FleetParallelEnv(uavs=40, size=(3, 3, 3), obstacles_min=0, obstacles_max=0)
    with pytest.raises(ConfigError, match=r"free cells can be reached"):
        crowded.reset(seed=0)


def test_the_sweep_is_cut_into_consecutive_pieces_that_finish_together():
    from pirl.world.split import cut_sweep

    # One lane of 40 points along x, the launch at its start: transit grows along the lane.
    points = np.array([(x, 0) for x in range(40)])
    transit = np.arange(40)
    pieces = cut_sweep(points, transit, 4)
    assert pieces[0].start == 0 and pieces[-1].stop == 40 and len(pieces) <= 4
    assert all(a.stop == b.start for a, b in zip(pieces, pieces[1:], strict=False))
    for p in pieces:  # a piece's moves: the way to its nearer end, then through it
        ways = (transit[p.start], transit[p.stop - 1])
        assert p.moves == min(ways) + (p.stop - p.start - 1)
        assert p.backwards == (ways[1] < ways[0])
    assert max(p.moves for p in pieces) == 39  # the last point is 39 moves out: no cut helps
    assert [p.stop - p.start for p in cut_sweep(points, np.zeros(40), 4)] == [10, 10, 10, 10]
    # Four lanes of a serpentine, 3 apart, launched from a corner: one UAV needs 48 moves;
    # four finish by 18, the moves to the far lane's nearer end and along it.
    lanes = [[(x, y) for x in (range(10) if y % 2 == 0 else range(9, -1, -1))] for y in range(4)]
    points = np.array([(x, 3 * y) for lane in lanes for x, y in lane])
    pieces = cut_sweep(points, points.sum(axis=1), 4)
    assert len(pieces) == 4 and max(p.moves for p in pieces) <= 18
    assert len(cut_sweep(points[:2], np.zeros(2), 4)) <= 2  # too short to share: fewer pieces


def test_planner_fleet_parts_cover_the_ground_round_walls():
    from pirl.agents.boustrophedon import fleet_planners
    from pirl.config.world import VCPPConfig
    from pirl.env.core import EnvCore
    from pirl.world.planning import WorldView
    from pirl.world.split import UNREACHABLE, geodesic

    cfg = VCPPConfig(size=(30, 20, 3), uavs=4)
    core = EnvCore(cfg, 1)
    core.reset_world(0, np.random.default_rng(3))
    world = core.world
    view = WorldView.of(world, 0)
    team = fleet_planners(world, 0)
    parts = np.stack([p.part for p in team])
    assert (parts.sum(axis=0) == view.coverable).all()  # every ground cell, one owner
    z = team[0].lanes[0][2]
    launch = geodesic(~view.blocked[:, :, z], world.position(0)[:2])
    for p in team:  # every lane point free and reachable round walls from the launch site
        assert all(c[2] == z and launch[c[:2]] < UNREACHABLE for c in p.lanes)
    flown = [c for p in team for c in p.lanes]
    assert len(set(flown)) == len(flown)  # pieces of one sweep: no lane point flown twice


def test_planner_fleet_covers_a_world_and_is_faster_than_one_uav():
    from pirl.config.world import VCPPConfig
    from pirl.evaluate.fleet import run_fleet_episode, speed_ups

    cfg = VCPPConfig(size=(30, 30, 3))
    rows = {k: [run_fleet_episode(cfg.replace(uavs=k), s).row for s in (0, 1)] for k in (1, 2, 4)}
    for k, episodes in rows.items():
        for row in episodes:
            assert row["vcr"] >= 0.99 and row["uavs"] == k and row["makespan_99"] is not None
            assert sum(row["credit"]) == row["covered"]
    ups = speed_ups(rows)
    assert ups[1] == 1.0 and ups[4] < ups[2] < 1.0


def test_report_has_a_fleets_table_and_figure_and_keeps_fleets_out_of_the_paper_tables(tmp_path):
    from pirl.evaluate.runner import EvalPlan, evaluate, spec_for_builtin
    from pirl.report.document import write_report

    plan = EvalPlan([spec_for_builtin("boustrophedon")], [(12, 12, 3)], 2, uavs=[1, 2])
    summary = evaluate(plan, tmp_path / "eval")
    write_report(tmp_path / "report", summary)
    table = (tmp_path / "report" / "table.md").read_text()
    fleets = table.split("### Fleets")[1].split("###")[0]
    lines = [line for line in fleets.splitlines() if line.startswith("| 12x12x3")]
    assert [line.split("|")[4].strip() for line in lines] == ["1", "2"]
    assert (tmp_path / "report" / "fleet_coverage.png").stat().st_size > 0
    camera = table.split("### Camera use")[1].split("###")[0]
    assert len([line for line in camera.splitlines() if line.startswith("| ")]) == 2  # head, K=1


def test_a_ppo_method_trains_on_mixed_fleet_sizes_and_flies_any_of_them(tmp_path):
    """train.uavs [1, 2]: worlds of one and of two UAVs side by side under one masked policy
    (MixedFleetVecEnv); the episode log has only flown episodes (not a parked UAV's steps);
    the run is then evaluated at K = 1 and 3, a size it never saw."""
    from pathlib import Path

    from pirl.agents.train import train
    from pirl.config.run import RunConfig
    from pirl.evaluate.runner import EvalPlan, evaluate, spec_for_run

    root = Path(__file__).resolve().parents[1]
    cfg = RunConfig.from_yaml(root / "configs" / "test.yaml").with_overrides(
        train={"total_steps": 1024, "uavs": [1, 2]}
    )
    run = tmp_path / "run"
    train("ppo-ewri", cfg, run, seed=0, show_progress=False)
    rows = [line.split(",") for line in (run / "episodes.csv").read_text().splitlines()[1:]]
    slot_episodes = [(r[1], r[6], r[2]) for r in rows]  # world (slot), steps, vcr
    assert rows and len(set(slot_episodes)) == len(slot_episodes)  # a parked UAV logs nothing
    plan = EvalPlan([spec_for_run(run)], [(12, 12, 3)], 2, env=cfg.env, config=cfg, uavs=[1, 3])
    evaluate(plan, tmp_path / "eval")
    rows = [json.loads(line) for line in (tmp_path / "eval" / "episodes.jsonl").open()]
    assert sorted({r["uavs"] for r in rows}) == [1, 3] and all(r["collisions"] == 0 for r in rows)


def test_imitation_refuses_fleet_training_in_one_line():
    from pirl.agents.settings import check_fleet_training
    from pirl.config.run import RunConfig

    cfg = RunConfig().with_overrides(train={"uavs": [1, 2]})
    with pytest.raises(ConfigError, match=r"train.uavs=\[1, 2\]: imitation learns"):
        check_fleet_training(cfg, imitation=True)
    check_fleet_training(cfg, imitation=False)
    with pytest.raises(ConfigError, match="train.uavs"):
        RunConfig().with_overrides(train={"uavs": [0]})


def test_pirl_train_takes_uavs_and_refuses_them_for_imitation_without_a_folder(tmp_path):
    """``pirl train --uavs 1,2`` sets train.uavs of a PPO method's run; imitation is refused
    in one line before any folder is made."""
    import subprocess
    import sys

    def pirl(*args: str) -> subprocess.CompletedProcess:
        cmd = [sys.executable, "-m", "pirl", "train", "--config", "test", *args]
        return subprocess.run(cmd, capture_output=True, text=True, timeout=600)

    proc = pirl("--method", "il", "--uavs", "2", "--out", str(tmp_path / "p"))
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert "train.uavs=[2]: imitation learns" in " ".join(proc.stderr.split())
    assert not (tmp_path / "p").exists()
    run = tmp_path / "e"
    proc = pirl("--method", "ppo-ewri", "--uavs", "1,2", "--steps", "1024", "--out", str(run))
    assert proc.returncode == 0, proc.stderr
    meta = json.loads((run / "meta.json").read_text())
    assert meta["complete"] and "uavs:\n  - 1\n  - 2" in (run / "config.yaml").read_text()


def test_a_fleets_gif_draws_every_step(tmp_path):
    from pirl.agents.boustrophedon import BoustrophedonPolicy
    from pirl.config.world import VCPPConfig
    from pirl.evaluate.rollout import record_gif

    cfg = VCPPConfig(size=(12, 12, 3), uavs=2)
    result, path = record_gif(cfg, BoustrophedonPolicy(), 3, tmp_path / "fleet.gif")
    assert result.metrics["uavs"] == 2 and result.metrics["vcr"] >= 0.99
    assert len(result.frames) == result.metrics["steps"] + 1 and path.stat().st_size > 0
