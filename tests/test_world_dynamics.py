"""World rules: actions, collisions and bounds, camera limits, wind, battery, episode end."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import scenario
from pirl.config.world import VCPPConfig
from pirl.world import dynamics as D
from pirl.world.metrics import episode_metrics
from pirl.world.scenario import blocked_grid, draw_scenario

MOVE_DELTAS = {
    0: (1, 0, 0),
    1: (-1, 0, 0),
    2: (0, 1, 0),
    3: (0, -1, 0),
    4: (0, 0, 1),
    5: (0, 0, -1),
}
# (tilt, pan, zoom) change of each camera action.
CAMERA_DELTAS = {
    6: (5, 0, 0.0),
    7: (-5, 0, 0.0),
    8: (0, 15, 0.0),
    9: (0, -15, 0.0),
    10: (0, 0, 0.1),
    11: (0, 0, -0.1),
}


def test_action_names_follow_the_paper_order():
    assert D.ACTION_NAMES == (
        "x+", "x-", "y+", "y-", "z+", "z-", "tilt+5", "tilt-5", "pan+15", "pan-15",
        "zoom+0.1", "zoom-0.1",
    )  # fmt: skip


@pytest.mark.parametrize("action", sorted(MOVE_DELTAS))
def test_moves(open_env, action):
    env, _, info = open_env((3, 3, 1), size=(7, 7, 3))
    assert info["position"] == (3, 3, 1)
    _, _, _, _, info = env.step(action)
    expected = tuple(p + d for p, d in zip((3, 3, 1), MOVE_DELTAS[action], strict=True))
    assert info["position"] == expected
    assert env.unwrapped.world.position(0) == expected
    assert not info["collision"] and not info["idle"]
    assert info["camera"] == (90, 0, 1.0)


@pytest.mark.parametrize("action", sorted(CAMERA_DELTAS))
def test_camera_actions(open_env, action):
    env, _, info = open_env((3, 3, 1), size=(7, 7, 3), start_tilt=45, start_zoom=1.2)
    assert info["camera"] == (45, 0, 1.2)
    _, _, _, _, info = env.step(action)
    dt, dp, dz = CAMERA_DELTAS[action]
    tilt, pan, zoom = info["camera"]
    assert (tilt, pan) == (45 + dt, dp)
    assert zoom == pytest.approx(1.2 + dz)
    assert info["position"] == (3, 3, 1)
    assert not info["collision"] and not info["idle"]


def test_zoom_has_no_float_drift(open_env):
    env, _, _ = open_env((2, 2, 1), start_zoom=0.5)
    for _ in range(20):
        _, _, _, _, info = env.step(10)
    assert info["camera"][2] == 2.0
    assert env.unwrapped.world.status[0]["zoom10"] == 20
    for _ in range(15):
        _, _, _, _, info = env.step(11)
    assert info["camera"][2] == 0.5
    assert env.unwrapped.world.status[0]["zoom10"] == 5


@pytest.mark.parametrize(
    ("start", "action"),
    [
        ((0, 2, 1), 1),
        ((4, 2, 1), 0),
        ((2, 0, 1), 3),
        ((2, 4, 1), 2),
        ((2, 2, 0), 5),
        ((2, 2, 2), 4),
        ((0, 0, 0), 1),
    ],
)
def test_move_out_of_the_grid_is_a_collision(open_env, start, action):
    env, _, _ = open_env(start, size=(5, 5, 3))
    _, reward, terminated, truncated, info = env.step(action)
    assert info["position"] == start
    assert info["collision"] is True
    assert info["reward_terms"]["collision"] == 1.0
    assert info["idle"] is False
    assert info["reward_terms"]["curiosity"] == 0.0
    assert not terminated and not truncated
    assert env.unwrapped.world.status[0]["collisions"] == 1
    assert episode_metrics(env.unwrapped.world, 0)["collisions"] == 1


def test_move_into_a_sphere_is_a_collision_and_counted(open_env):
    # Sphere at (3, 2, 1), radius 1: blocks (2, 2, 1), (4, 2, 1), (3, 1, 1), (3, 3, 1),
    # (3, 2, 0), (3, 2, 2) and its centre.
    env, _, _ = open_env((1, 2, 1), size=(6, 5, 3), obstacles=[[3.0, 2.0, 1.0, 1.0]])
    world = env.unwrapped.world
    assert world.blocked[0, 2, 2, 1] and world.blocked[0, 3, 2, 0]
    assert not world.blocked[0, 2, 1, 1] and not world.blocked[0, 2, 3, 1]
    _, _, _, _, info = env.step(0)
    assert info["position"] == (1, 2, 1)
    assert info["collision"] and info["reward_terms"]["collision"] == 1.0
    # Around it is free.
    _, _, _, _, info = env.step(3)
    assert info["position"] == (1, 1, 1) and not info["collision"]
    _, _, _, _, info = env.step(0)
    assert info["position"] == (2, 1, 1) and not info["collision"]
    _, _, _, _, info = env.step(2)
    assert info["position"] == (2, 1, 1) and info["collision"]
    # From above: descending into the sphere's top cell.
    env, _, _ = open_env((3, 2, 2), size=(6, 5, 3), obstacles=[[3.0, 2.0, 0.0, 1.0]])
    _, _, _, _, info = env.step(5)
    assert info["position"] == (3, 2, 2) and info["collision"]
    for _ in range(3):
        env.step(1)  # x- : (2, 2, 2), (1, 2, 2), (0, 2, 2)
    _, _, _, _, info = env.step(1)  # out of the grid
    m = episode_metrics(env.unwrapped.world, 0)
    assert m["collisions"] == 2
    assert info["collision"]


@pytest.mark.parametrize(
    ("settings", "action"),
    [
        ({"start_tilt": 90}, 6),
        ({"start_tilt": 0}, 7),
        ({"start_pan": 90}, 8),
        ({"start_pan": -90}, 9),
        ({"start_zoom": 2.0}, 10),
        ({"start_zoom": 0.5}, 11),
    ],
)
def test_camera_action_at_its_limit_changes_nothing_and_is_idle(open_env, settings, action):
    env, _, first = open_env((2, 2, 1), **settings)
    _, _, _, _, info = env.step(action)
    assert info["camera"] == first["camera"]
    assert info["idle"] is True
    assert info["reward_terms"]["idle"] == 1.0
    assert info["collision"] is False
    assert info["redundant"] is True
    assert info["reward_terms"]["battery"] == pytest.approx(0.3)
    assert env.unwrapped.world.status[0]["collisions"] == 0


def test_idle_only_when_nothing_changed(open_env):
    env, _, _ = open_env((2, 2, 1), start_tilt=85)
    _, _, _, _, info = env.step(6)  # 85 -> 90: a change, though the view is the same
    assert info["camera"][0] == 90
    assert info["idle"] is False and info["redundant"] is True
    _, _, _, _, info = env.step(6)  # at the limit
    assert info["idle"] is True


# -- wind ------------------------------------------------------------------------------------


def _rollout(env, actions, seed=None, options=None):
    obs, info = env.reset(seed=seed, options=options)
    out = {"pos": [info["position"]], "wind": [], "obs": [obs], "rew": []}
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(int(a))
        out["pos"].append(info["position"])
        out["wind"].append(info["wind"])
        out["obs"].append(obs)
        out["rew"].append(reward)
        if terminated or truncated:
            obs, info = env.reset()
            out["pos"].append(info["position"])
            out["obs"].append(obs)
    return out


def test_wind_is_deterministic_under_a_seed(make_env):
    actions = np.random.default_rng(1).integers(0, 12, size=300)
    settings = {"size": (12, 10, 3), "wind_prob": 0.4, "max_steps": 60, "scale_by_alpha": False}
    a = _rollout(make_env(**settings), actions, seed=7)
    b = _rollout(make_env(**settings), actions, seed=7)
    assert a["pos"] == b["pos"]
    assert a["wind"] == b["wind"]
    assert a["rew"] == b["rew"]
    assert all(np.array_equal(x, y) for x, y in zip(a["obs"], b["obs"], strict=True))
    assert 40 < sum(a["wind"]) < 140
    c = _rollout(make_env(**settings), actions, seed=8)
    assert c["wind"] != a["wind"]


def test_wind_follows_the_scenario_wind_seed(make_env):
    actions = np.full(150, 8)  # pan+15: the camera only, so only the wind moves the UAV
    actions[1::2] = 9
    settings = {"size": (15, 15, 3), "wind_prob": 0.3}
    first = _rollout(
        make_env(**settings), actions, seed=1, options={"scenario": scenario((7, 7, 1), None, 5)}
    )
    again = _rollout(
        make_env(**settings), actions, seed=2, options={"scenario": scenario((7, 7, 1), None, 5)}
    )
    other = _rollout(
        make_env(**settings), actions, seed=1, options={"scenario": scenario((7, 7, 1), None, 6)}
    )
    assert first["wind"] == again["wind"] and first["pos"] == again["pos"]
    assert first["wind"] != other["wind"]


def test_no_wind_never_pushes(open_env):
    env, _, info = open_env(
        (3, 3, 1), size=(7, 7, 3), obstacles=[[5.0, 5.0, 1.0, 1.2]], wind_prob=0.0,
        max_steps=10_000, battery_capacity=1e6,
    )  # fmt: skip
    world = env.unwrapped.world
    pos = info["position"]
    for a in np.random.default_rng(3).integers(0, 12, size=400):
        _, _, _, _, info = env.step(int(a))
        assert info["wind"] is False
        if a < 6:
            target = tuple(p + d for p, d in zip(pos, MOVE_DELTAS[int(a)], strict=True))
            inside = all(0 <= t < s for t, s in zip(target, (7, 7, 3), strict=True))
            free = inside and not world.blocked[0][target]
            assert info["position"] == (target if free else pos)
            assert info["collision"] is (not free)
        else:
            assert info["position"] == pos
        pos = info["position"]
    assert world.status[0]["wind_pushes"] == 0


def _neighbours_blocked(world, pos):
    x, y, z = pos
    sx, sy, _ = world.cfg.size
    out = 0
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        nx, ny = x + dx, y + dy
        if not (0 <= nx < sx and 0 <= ny < sy) or world.blocked[0, nx, ny, z]:
            out += 1
    return out


@pytest.mark.parametrize("obstacles", [None, [[4.0, 4.0, 1.0, 1.5], [1.0, 7.0, 0.0, 1.0]]])
def test_full_wind_pushes_every_step_unless_blocked_and_never_collides(open_env, obstacles):
    env, _, info = open_env(
        (4, 1, 1), size=(9, 9, 3), obstacles=obstacles, wind_prob=1.0, wind_seed=11,
        max_steps=10_000, battery_capacity=1e6,
    )  # fmt: skip
    world = env.unwrapped.world
    pos = info["position"]
    directions = set()
    for k in range(300):
        _, _, _, _, info = env.step(8 + k % 2)  # camera only
        new = info["position"]
        assert info["collision"] is False
        assert not world.blocked[0][new]
        if info["wind"]:
            delta = tuple(n - p for n, p in zip(new, pos, strict=True))
            assert delta in {(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)}
            directions.add(delta)
        else:
            # A gust into an obstacle or out of the grid does nothing.
            assert new == pos
            assert _neighbours_blocked(world, pos) > 0
        pos = new
    assert len(directions) == 4
    assert world.status[0]["collisions"] == 0
    assert episode_metrics(world, 0)["wind_pushes"] == world.status[0]["wind_pushes"] > 200


def test_wind_rate_matches_wind_prob(open_env):
    env, _, _ = open_env(
        (15, 15, 1), size=(31, 31, 3), wind_prob=0.3, wind_seed=2, max_steps=10_000,
        battery_capacity=1e6,
    )  # fmt: skip
    pushes = 0
    for k in range(500):
        _, _, _, _, info = env.step(8 + k % 2)
        pushes += info["wind"]
    assert 110 < pushes < 190


def test_wind_moves_after_a_blocked_move_are_not_collisions(open_env):
    env, _, _ = open_env(
        (0, 4, 1), size=(9, 9, 3), wind_prob=1.0, wind_seed=4, max_steps=10_000,
        battery_capacity=1e6,
    )  # fmt: skip
    collisions = 0
    for _ in range(50):
        _, _, _, _, info = env.step(4)  # climb until the ceiling, then collide every step
        collisions += info["collision"]
    assert collisions == env.unwrapped.world.status[0]["collisions"] >= 48


# -- battery, step limit ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("action", "cost"),
    [(0, 1.1), (1, 1.1), (2, 1.1), (3, 1.1), (4, 1.6), (5, 0.8)] + [(a, 0.3) for a in range(6, 12)],
)
def test_energy_per_action(open_env, action, cost):
    env, _, first = open_env((3, 3, 1), size=(7, 7, 3), start_tilt=45)
    world = env.unwrapped.world
    capacity = world.capacity
    assert capacity == pytest.approx(100 * 147 / 675)
    assert first["battery"] == 1.0
    _, _, _, _, info = env.step(action)
    assert not info["collision"]
    assert info["reward_terms"]["battery"] == pytest.approx(cost)
    assert world.energy[0] == pytest.approx(capacity - cost)
    assert info["battery"] == pytest.approx((capacity - cost) / capacity)


def test_energy_table_is_configurable(open_env):
    env, _, _ = open_env(
        (3, 3, 1), size=(7, 7, 3), energy_move=2.0, energy_climb=3.0, energy_hover=0.0,
        energy_camera=0.5, scale_by_alpha=False,
    )  # fmt: skip
    _, _, _, _, info = env.step(0)
    assert info["reward_terms"]["battery"] == pytest.approx(1.0)  # 2.0 / energy_move
    _, _, _, _, info = env.step(4)
    assert info["reward_terms"]["battery"] == pytest.approx(1.5)
    _, _, _, _, info = env.step(9)
    assert info["reward_terms"]["battery"] == pytest.approx(0.25)
    assert info["battery"] == pytest.approx((100 - 5.5) / 100)


def test_episode_terminates_when_the_battery_is_empty(open_env):
    env, _, _ = open_env((2, 2, 1), battery_capacity=2.0, scale_by_alpha=False, max_steps=50)
    for step in range(1, 7):  # 6 camera actions: 6 * 0.3 = 1.8 < 2.0
        _, _, terminated, truncated, info = env.step(8 if step % 2 else 9)
        assert not terminated and not truncated, step
    assert info["battery"] == pytest.approx(0.1)
    _, _, terminated, truncated, info = env.step(8)
    assert terminated is True and truncated is False
    assert info["battery"] == 0.0
    assert info["episode_metrics"]["battery_left"] == 0.0
    assert info["steps"] == 7


def test_episode_is_truncated_at_the_step_limit(open_env):
    env, _, _ = open_env((2, 2, 1), max_steps=5, scale_by_alpha=False)
    for step in range(1, 5):
        _, _, terminated, truncated, info = env.step(8 if step % 2 else 9)
        assert not terminated and not truncated
        assert "episode_metrics" not in info
    _, _, terminated, truncated, info = env.step(8)
    assert terminated is False and truncated is True
    assert info["steps"] == 5
    assert info["episode_metrics"]["steps"] == 5


def test_step_limit_scales_with_alpha(open_env):
    # 6x5x3: alpha = 90 / 675, step limit round(200 * 0.1333) = 27.
    env, _, _ = open_env((2, 2, 1), size=(6, 5, 3), battery_capacity=1e6)
    assert env.unwrapped.world.step_limit == 27
    ends = []
    for k in range(27):
        _, _, terminated, truncated, _ = env.step(8 + k % 2)
        ends.append((terminated, truncated))
    assert ends[:-1] == [(False, False)] * 26
    assert ends[-1] == (False, True)


def test_episode_terminates_when_everything_is_covered(open_env):
    # 5x5 ground, tilt 75 / zoom 1.0: a 5x5 square. From (1, 2) it sees x 0..3; x+ sees all.
    env, _, info = open_env((1, 2, 0), start_tilt=75)
    assert info["covered"] == 20 and info["coverable"] == 25
    _, _, terminated, truncated, info = env.step(0)
    assert info["new_cells"] == 5
    assert terminated is True and truncated is False
    assert info["episode_metrics"]["vcr"] == 1.0


def test_termination_wins_over_truncation_on_the_same_step(open_env):
    env, _, _ = open_env((1, 2, 0), start_tilt=75, max_steps=1, scale_by_alpha=False)
    _, _, terminated, truncated, _ = env.step(0)
    assert (terminated, truncated) == (True, False)


# -- scenarios and reset ---------------------------------------------------------------------


def test_reset_state(make_env):
    env = make_env(size=(15, 15, 3))
    _, info = env.reset(seed=3)
    world = env.unwrapped.world
    assert info["camera"] == (90, 0, 1.0)
    assert info["battery"] == 1.0
    assert info["steps"] == 0
    assert not world.blocked[0][info["position"]]
    assert info["covered"] == int(world.covered(0).sum()) > 0
    assert info["new_cells"] == 0
    assert all(v == 0.0 for v in info["reward_terms"].values())


def test_scenarios_follow_the_design():
    cfg = VCPPConfig(size=(15, 15, 3))
    counts = set()
    for seed in range(40):
        sc = draw_scenario(cfg, np.random.default_rng(seed))
        n = len(sc.obstacles)
        counts.add(n)
        assert 2 <= n <= 5
        assert ((sc.obstacles[:, 3] >= 1.0) & (sc.obstacles[:, 3] <= 2.0)).all()
        assert (sc.obstacles[:, :3] >= 0).all()
        assert (sc.obstacles[:, :3] <= np.array([14, 14, 2])).all()
        blocked = blocked_grid(cfg.size, sc.obstacles)
        assert not blocked[sc.start]
        assert (~blocked[:, :, 0]).any()
        # A cell is blocked exactly when its centre is within a radius of a sphere's centre.
        for cell in [(0, 0, 0), sc.start, (7, 7, 1), (14, 3, 2)]:
            d = np.linalg.norm(sc.obstacles[:, :3] - np.array(cell), axis=1)
            assert blocked[cell] == bool((d <= sc.obstacles[:, 3]).any())
    assert counts == {2, 3, 4, 5}


def test_obstacle_count_can_scale_with_area():
    assert VCPPConfig(size=(30, 30, 3)).obstacle_count_range == (2, 5)
    scaled = VCPPConfig(size=(30, 30, 3), obstacles_scale_with_area=True)
    assert scaled.obstacle_count_range == (8, 20)
    sc = draw_scenario(scaled, np.random.default_rng(0))
    assert 8 <= len(sc.obstacles) <= 20


def test_reset_with_a_seed_is_reproducible(make_env):
    env = make_env(size=(15, 15, 3))
    env.reset(seed=5)
    world = env.unwrapped.world
    obstacles, start = world.obstacle_list(0), world.position(0)
    env.reset(seed=6)
    assert world.position(0) != start or not np.array_equal(world.obstacle_list(0), obstacles)
    env.reset()  # continues the stream
    env.reset(seed=5)
    assert np.array_equal(world.obstacle_list(0), obstacles)
    assert world.position(0) == start


def test_replaying_a_scenario(make_env):
    env = make_env(size=(15, 15, 3))
    env.reset(seed=9)
    world = env.unwrapped.world
    sc = scenario(world.position(0), world.obstacle_list(0), 77)
    blocked = world.blocked[0].copy()
    env.reset(seed=123, options={"scenario": sc})
    assert world.position(0) == sc.start
    assert np.array_equal(world.blocked[0], blocked)
    assert np.array_equal(world.coverable[0], ~blocked[:, :, 0])


def test_scenario_with_too_many_obstacles_is_refused(make_env):
    env = make_env(size=(15, 15, 3))
    with pytest.raises(ValueError, match="obstacles"):
        env.reset(options={"scenario": scenario((0, 0, 0), [[9.0, 9.0, 1.0, 1.0]] * 6)})


def test_scenario_start_inside_an_obstacle_is_refused(make_env):
    """A replayed scenario must start the UAV in a free cell, as drawn scenarios do."""
    env = make_env(size=(5, 5, 3))
    with pytest.raises(ValueError, match="start"):
        env.reset(options={"scenario": scenario((2, 2, 0), [[2.0, 2.0, 0.0, 1.0]])})


@pytest.mark.parametrize("start", [(-1, 1, 0), (1, 5, 0), (1, 1, 3)])
def test_scenario_start_outside_the_grid_is_refused(make_env, start):
    """A start outside the grid must be refused, not used to index the state arrays.

    (These starts, with a 3-cell observation window, keep every unchecked access inside the
    arrays' memory, so the test is safe to run before the fix.)
    """
    env = make_env(size=(5, 5, 3), obs_window=3)
    with pytest.raises(ValueError, match="start"):
        env.reset(options={"scenario": scenario(start)})
