"""Candidate views: the places offered, the pilot that flies there, the envs a chooser trains in."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env
from sb3_contrib import MaskablePPO

from pirl.agents import BoustrophedonPolicy
from pirl.agents.loading import load_policy
from pirl.agents.train import train
from pirl.agents.views import ViewsPolicy
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig
from pirl.env import VCPPEnv
from pirl.env.views import (
    K_VIEWS,
    OBS_SIZE,
    VIEW_FEATURES,
    ViewPilot,
    ViewsEnv,
    candidates,
    nearest_view,
    view_gains,
)
from pirl.env.views_sb3 import ViewsVecEnv
from pirl.evaluate import run_episode
from pirl.world.metrics import episode_metrics
from pirl.world.planning import WorldView, bfs_path

TEST_CFG = Path(__file__).resolve().parents[1] / "configs" / "test.yaml"


def _weights(path: Path) -> dict:
    return MaskablePPO.load(path, device="cpu").policy.state_dict()


def _sector(dx: int, dy: int) -> int:
    return int((np.arctan2(dy, dx) + np.pi) / (2 * np.pi) * K_VIEWS) % K_VIEWS


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_each_candidate_is_the_nearest_useful_place_of_its_sector(seed):
    env = VCPPEnv(size=(20, 20, 3), wind_prob=0.0)
    env.reset(seed=seed)
    pilot = ViewPilot(env.world, 0)
    view = WorldView.of(env.world, 0)
    c = candidates(view, pilot.camera, pilot.altitude)
    assert c.obs.shape == (OBS_SIZE,) and c.any
    x0, y0, _ = view.position
    start = (x0, y0, pilot.altitude)
    # Every useful place at the altitude, by its moves from the UAV (the way round obstacles).
    best: dict[int, int] = {}
    for x in range(20):
        for y in range(20):
            cell = (x, y, pilot.altitude)
            if (x, y) == (x0, y0) or not view.free(cell) or not view.useful(cell, pilot.camera):
                continue
            path = bfs_path(view, start, cell)
            if path is not None:
                k = _sector(x - x0, y - y0)
                best[k] = min(best.get(k, 10**9), len(path) - 1)
    feats = c.obs[: K_VIEWS * VIEW_FEATURES].reshape(K_VIEWS, VIEW_FEATURES)
    assert set(best) == {k for k, cell in enumerate(c.cells) if cell is not None}
    for k, cell in enumerate(c.cells):
        if cell is None:
            assert not feats[k].any()
            continue
        assert _sector(cell[0] - x0, cell[1] - y0) == k
        assert len(bfs_path(view, start, cell)) - 1 == best[k]
        assert feats[k, 0] == 1.0 and feats[k, 4] > 0  # present, and its view adds cells
    assert np.array_equal(c.mask, [cell is not None for cell in c.cells])


def _steps_to_99(policy, size, seed, wind=0.0) -> tuple[float, int | None]:
    env = VCPPEnv(size=size, wind_prob=wind)
    metrics = run_episode(env, policy, seed).metrics
    return metrics["vcr"], metrics["steps_to_99"]


@pytest.mark.parametrize("seed", [0, 1])
def test_the_nearest_view_rule_covers_at_the_planners_pace(seed):
    # The rule a learned chooser is measured against: full coverage, within 1.3x the
    # planner's steps to 0.99 on a world larger than training (1.0 and 1.1 here).
    vcr, steps = _steps_to_99(ViewsPolicy(nearest_view), (30, 30, 3), seed)
    _, planner = _steps_to_99(BoustrophedonPolicy(), (30, 30, 3), seed)
    assert vcr == 1.0 and steps is not None and planner is not None
    assert steps <= 1.3 * planner


def test_the_pilot_reaches_its_places_through_gusts():
    vcr, steps = _steps_to_99(ViewsPolicy(nearest_view), (20, 20, 3), 3, wind=0.3)
    assert vcr >= 0.99 and steps is not None


def test_the_env_passes_gymnasiums_checker_and_masks_absent_candidates():
    env = ViewsEnv(VCPPEnv(size=(15, 15, 3)).cfg)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=4)
    mask = env.action_masks()
    assert mask.any() and np.array_equal(mask, obs[: K_VIEWS * VIEW_FEATURES : VIEW_FEATURES] == 1)


def test_a_choice_earns_the_inner_envs_rewards_of_its_flight():
    # Replaying the primitive actions of every choice on a second env from the same seed gives
    # the same rewards, summed per choice, and the same end.
    cfg = VCPPEnv(size=(15, 15, 3), wind_prob=0.2, reward="ewri").cfg
    env, twin = ViewsEnv(cfg), VCPPEnv(cfg)
    obs, _ = env.reset(seed=9)
    twin.reset(seed=9)
    pilot = ViewPilot(twin.world, 0)
    rng = np.random.default_rng(0)
    done, choices = False, 0
    while not done:
        k = int(rng.choice(np.flatnonzero(env.action_masks())))
        cell = env.views.candidates.cells[k]
        obs, reward, terminated, truncated, info = env.step(k)
        pilot.aim(cell)
        total, steps = 0.0, 0
        while steps < info["primitive_steps"]:
            _, r, _, _, _ = twin.step(pilot.action())
            total += r
            steps += 1
        assert reward == pytest.approx(total)
        done = terminated or truncated
        choices += 1
    assert choices > 3 and "episode_metrics" in info
    assert info["episode_metrics"] == episode_metrics(twin.world, 0)


def test_the_batched_env_plays_each_world_as_the_single_env_and_resumes_exactly():
    cfg = VCPPEnv(size=(15, 15, 3), wind_prob=0.2, reward="ewri").cfg
    venv = ViewsVecEnv(3, cfg)
    venv.seed(20)
    obs = venv.reset()
    singles = [ViewsEnv(cfg) for _ in range(3)]
    expected = np.stack([env.reset(seed=20 + i)[0] for i, env in enumerate(singles)])
    assert np.array_equal(obs, expected)
    rng = np.random.default_rng(1)

    def choose(masks):
        return np.array([rng.choice(np.flatnonzero(m)) for m in masks])

    ends = 0
    for step in range(60):
        if step == 30:
            saved, rng_saved = venv.state_dict(), copy.deepcopy(rng)
        actions = choose(venv.action_masks())
        obs, rewards, dones, infos = venv.step(actions)
        for i, env in enumerate(singles):
            o, r, terminated, truncated, info = env.step(int(actions[i]))
            assert rewards[i] == pytest.approx(r)
            assert dones[i] == (terminated or truncated)
            if dones[i]:
                ends += 1
                assert np.array_equal(infos[i]["terminal_observation"], o)
                assert infos[i]["episode_metrics"] == info["episode_metrics"]
                o, _ = env.reset()
            assert np.array_equal(obs[i], o)
        if step == 45:
            tail = (obs.copy(), rewards.copy())
    assert ends >= 3
    # Resumed from the state at step 30, the same choices give the same steps 30-45.
    venv.load_state_dict(saved)
    rng = rng_saved
    for _ in range(16):
        obs, rewards, _, _ = venv.step(choose(venv.action_masks()))
    assert np.array_equal(obs, tail[0]) and np.array_equal(rewards, tail[1])


@pytest.mark.parametrize("seed", [5, 6])
def test_the_policy_flies_the_choices_the_env_trains_on(seed):
    # The same chooser in ViewsEnv (training) and as a ViewsPolicy (evaluation, missions)
    # flies the same primitive steps: the same episode, gusts included.
    cfg = VCPPEnv(size=(15, 15, 3), wind_prob=0.2).cfg
    env = ViewsEnv(cfg)
    env.reset(seed=seed)
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(nearest_view(env.views.candidates))
        done = terminated or truncated
    assert terminated  # every cell seen: the policy's episode ends there too
    played = run_episode(VCPPEnv(cfg), ViewsPolicy(nearest_view), seed).metrics
    assert {k: played[k] for k in info["episode_metrics"]} == info["episode_metrics"]


def test_ppo_views_trains_resumes_exactly_and_plays_in_both_act_modes(tmp_path):
    cfg = RunConfig.from_yaml(TEST_CFG)
    whole = cfg.with_overrides(train={"total_steps": 256})
    straight = train("ppo-views", whole, tmp_path / "a", show_progress=False)
    half = cfg.with_overrides(train={"total_steps": 128})
    train("ppo-views", half, tmp_path / "b", show_progress=False)
    resumed = train("ppo-views", whole, tmp_path / "b", resume=True, show_progress=False)
    a, b = _weights(straight), _weights(resumed)
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    episodes = [(tmp_path / r / "episodes.csv").read_text() for r in "ab"]
    assert episodes[0] == episodes[1] and len(episodes[0].splitlines()) > 2
    meta = json.loads((tmp_path / "a" / "meta.json").read_text())
    assert meta["label"] == "PPO over candidate views (macro actions)"
    own = RunConfig.from_yaml(tmp_path / "a" / "config.yaml").env
    env = VCPPEnv(own.replace(size=(20, 20, 3)))
    for act in ("greedy", "stochastic"):
        runs = [run_episode(env, load_policy(tmp_path / "a", act=act), 3).metrics for _ in range(2)]
        assert runs[0] == runs[1] and runs[0]["vcr"] > 0.5


def test_a_fleet_curriculum_is_refused_before_any_folder(tmp_path):
    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(train={"uavs": [1, 2]})
    with pytest.raises(ConfigError, match=r"train.uavs=\[1, 2\]: --method ppo-views chooses"):
        train("ppo-views", cfg, tmp_path / "run", show_progress=False)
    assert not (tmp_path / "run").exists()


def test_view_gains_count_as_the_footprint_cell_by_cell():
    # A footprint filling its box is counted from a summed-area table, others cell by cell:
    # both equal a direct count, at the grid's edges too.
    rng = np.random.default_rng(0)
    for _ in range(60):
        sx, sy = (int(v) for v in rng.integers(1, 30, 2))
        todo = rng.random((sx, sy)) < rng.random()
        w, h = (int(v) for v in rng.integers(1, 10, 2))
        ox, oy = (int(v) for v in rng.integers(-10, 5, 2))
        box = np.array([(ox + i, oy + j) for i in range(w) for j in range(h)])
        for offsets in (box, box[rng.random(len(box)) < 0.6]):
            direct = np.array([
                [sum(0 <= x + dx < sx and 0 <= y + dy < sy and todo[x + dx, y + dy]
                     for dx, dy in offsets) for y in range(sy)]
                for x in range(sx)
            ])  # fmt: skip
            assert np.array_equal(view_gains(todo, offsets), direct.reshape(sx, sy))
