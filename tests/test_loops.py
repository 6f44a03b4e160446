"""Loops: an episode's tail (the cells of its last 60 steps), counted by both runners."""

from __future__ import annotations

import numpy as np

from pirl.agents.loading import LearnedPolicy, load_policy
from pirl.config.world import VCPPConfig
from pirl.env.observation import N_SCALARS
from pirl.env.vcpp_env import VCPPEnv
from pirl.evaluate.rollout import run_batch, run_episode
from pirl.world import dynamics as D
from pirl.world.metrics import LOOP_CELLS, LOOP_WINDOW

OPEN = VCPPConfig(size=(20, 20, 3), obstacles_min=0, obstacles_max=0, wind_prob=0.0, max_steps=150)
X_SCALAR = 2 * OPEN.obs_window**2 + OPEN.obs_global**2  # x / (X - 1), first of the scalars


class Pendulum(LearnedPolicy):
    """x+ from an even column, x- from an odd one: two cells, back and forth, for ever."""

    label = "pendulum"

    def probabilities(self, obs: np.ndarray) -> np.ndarray:
        x = np.rint(obs[:, X_SCALAR] * (OPEN.size[0] - 1)).astype(int)
        probs = np.zeros((len(obs), D.N_ACTIONS))
        probs[np.arange(len(obs)), np.where(x % 2 == 0, D.X_PLUS, D.X_MINUS)] = 1.0
        return probs


def test_a_two_cell_loop_has_a_tail_of_two_cells_in_both_runners():
    assert N_SCALARS == 11 and LOOP_WINDOW == 60
    seeds = [3, 4, 5]
    batched = run_batch(OPEN, Pendulum(), seeds)
    single = [run_episode(VCPPEnv(OPEN), Pendulum(), s).metrics for s in seeds]
    assert batched == single
    assert [m["tail_cells"] for m in batched] == [2, 2, 2]
    assert all(m["steps"] > LOOP_WINDOW for m in batched)


def test_the_planner_never_loops():
    env = VCPPEnv(OPEN.replace(obstacles_min=2, obstacles_max=5))
    for seed in (1, 2):
        m = run_episode(env, load_policy("boustrophedon"), seed).metrics
        assert m["vcr"] == 1.0 and m["tail_cells"] >= LOOP_CELLS


def test_a_loop_flown_in_physics_has_the_same_tail():
    from pirl.config.physics import PhysicsConfig
    from pirl.physics import run_physics_episode

    cfg = OPEN.replace(max_steps=LOOP_WINDOW + 4, scale_by_alpha=False)
    m = run_physics_episode(cfg, Pendulum(), seed=3, physics=PhysicsConfig())
    assert m["steps"] == LOOP_WINDOW + 4 and m["tail_cells"] == 2


def test_the_stall_scalar_climbs_inside_a_loop_and_resumes_exactly():
    from pirl.env.observation import STALL_RANGE, obs_size_for

    cfg = OPEN.replace(obs_stall=True, obs_visits=True)
    env = VCPPEnv(cfg)
    assert obs_size_for(cfg) == obs_size_for(OPEN.replace(obs_visits=True)) + 1
    stall = 2 * cfg.obs_window**2 + cfg.obs_global**2 + N_SCALARS + cfg.obs_window**2
    obs, _ = env.reset(seed=3)
    assert obs[stall] == 0.0
    pendulum, seen, flat = Pendulum(), [], 0
    for _ in range(45):
        action = int(np.argmax(pendulum.probabilities(obs[None])[0]))
        obs, _, _, _, info = env.step(action)
        flat = 0 if info["new_cells"] > 0 else flat + 1
        seen.append(obs[stall])
        assert obs[stall] == min(flat, STALL_RANGE) / STALL_RANGE
        if len(seen) == 30:
            saved = env.state_dict()
    assert seen[-1] == 1.0 and max(seen[:3]) < 0.1  # the loop's first views still find cells
    # A checkpoint taken inside the loop carries the counter; one from before it starts there.
    again = VCPPEnv(cfg)
    again.reset(seed=0)
    again.load_state_dict(saved)
    inside = int(saved["core"]["world"]["progress"][0])
    assert again.world.progress[0] == inside and 0 < inside < 30 - STALL_RANGE / 2
    core = {**saved["core"], "world": dict(saved["core"]["world"])}
    del core["world"]["progress"]
    again.load_state_dict({**saved, "core": core})
    assert again.world.progress[0] == again.world.status[0]["steps"]


def test_the_stall_guard_ends_a_loop_in_both_runners_and_in_physics():
    from pirl.config.physics import PhysicsConfig
    from pirl.physics import run_physics_episode

    seeds = [3, 4]
    free_run = run_batch(OPEN, Pendulum(), seeds)
    cfg = OPEN.replace(stall_guard=8)
    batched = run_batch(cfg, Pendulum(), seeds)
    assert batched == [run_episode(VCPPEnv(cfg), Pendulum(), s).metrics for s in seeds]
    for loose, guarded in zip(free_run, batched, strict=True):
        assert loose["tail_cells"] == 2 and loose["guarded_steps"] == 0
        assert guarded["tail_cells"] >= LOOP_CELLS and guarded["vcr"] > 2 * loose["vcr"]
        assert 0 < guarded["guarded_steps"] < guarded["steps"]
    # While it is on, the mask leaves one action; off, the env is the paper's.
    env = VCPPEnv(cfg)
    obs, info = env.reset(seed=3)
    for _ in range(40):
        on = env.world.status[0]["steps"] - env.world.progress[0] >= 8
        assert (sum(info["action_mask"]) == 1) == on
        obs, _, _, _, info = env.step(int(np.argmax(Pendulum().probabilities(obs[None])[0])))
    m = run_physics_episode(
        cfg.replace(max_steps=LOOP_WINDOW + 4, scale_by_alpha=False), Pendulum(), 3, PhysicsConfig()
    )
    assert m["guarded_steps"] > 0 and m["tail_cells"] > 2


def test_the_stall_guard_finds_ground_seen_only_from_beside_it(tmp_path):
    """A courtyard closed at every level: its ground is seen over the walls (the paper camera's
    square reaches 4 cells at zoom 2.0), never stood over. The guard widens the camera, then
    leads to a cell whose footprint holds it."""
    import yaml

    from pirl.world.seeable import with_site

    heights = np.zeros((20, 12))  # (x, y)
    heights[2:9, 2] = heights[2:9, 8] = heights[2, 2:9] = heights[8, 2:9] = 30.0
    np.savetxt(tmp_path / "h.csv", heights.T[::-1], delimiter=",", fmt="%g")
    site = {"heights": "h.csv", "cell_size_m": 10.0, "levels": 3, "start": [15, 6]}
    (tmp_path / "site.yaml").write_text(yaml.safe_dump(site))
    cfg = with_site(VCPPConfig(wind_prob=0.0, stall_guard=4), str(tmp_path))
    env = VCPPEnv(cfg)
    env.reset(seed=0)
    w = env.world
    assert w.coverable[0, 5, 5] and all(w.blocked[0, 2, 5, :])
    w.views[0][...] = 1
    w.views[0, 5, 5] = 0  # the only ground left: the courtyard's centre
    w.progress[0] = -10
    out = np.zeros((1, D.N_ACTIONS), dtype=bool)
    chosen = []
    for _ in range(40):
        D.action_mask(w.arrays, w.params, 0, out)
        assert out[0].sum() == 1
        chosen.append(int(np.flatnonzero(out[0])[0]))
        env.step(chosen[-1])
        if w.views[0, 5, 5]:
            break
    assert w.views[0, 5, 5] > 0 and D.ZOOM_PLUS in chosen and D.X_MINUS in chosen
    assert w.guarded[0] == len(chosen)
    # A checkpoint from before the guard resumes with its counter at zero.
    saved = env.state_dict()
    core = {**saved["core"], "world": dict(saved["core"]["world"])}
    del core["world"]["guarded"]
    env.load_state_dict({**saved, "core": core})
    assert w.guarded[0] == 0
