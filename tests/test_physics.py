"""Physics evaluation: the shared mission logic, real PyFlyt flights, the Webots world.

The PyFlyt tests fly a real QuadX (PyBullet, headless) in small worlds; the first flight in the
process pays PyFlyt's numba compilation (a few seconds).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from conftest import scenario
from pirl.agents.policy import Policy, RandomPolicy
from pirl.cli import app
from pirl.config.errors import ConfigError
from pirl.config.physics import PhysicsConfig
from pirl.config.world import VCPPConfig
from pirl.env.vcpp_env import VCPPEnv
from pirl.evaluate.rollout import run_episode
from pirl.physics import Mission, Pose, run_physics_episode
from pirl.physics.coverage import view_angles
from pirl.physics.flight import CAMERA, ENERGY_CAUSES, MOVE, REFUSED, normalized_power, touching
from pirl.physics.pyflyt_backend import PyFlytFlight
from pirl.physics.webots.controller import mission_from_args, parse_args
from pirl.physics.webots.pilot import MavicPilot
from pirl.physics.webots.world import world_text, write_world
from pirl.world.state import WorldBatch

CALM = PhysicsConfig(wind_mean=(0.0, 0.0, 0.0), wind_gust=0.0)
# Plenty of battery and no step scaling: the flight tests choose their own length.
ROOMY = {"scale_by_alpha": False, "battery_capacity": 1000.0, "wind_prob": 0.0}


def _cells(rows: np.ndarray) -> set[tuple[int, int]]:
    return {(int(i), int(j)) for i, j in rows}


class Scripted(Policy):
    """Plays a fixed list of actions, then holds (tilt down at its limit)."""

    def __init__(self, actions: list[int]) -> None:
        self.actions = actions

    def reset(self, world: WorldBatch, index: int = 0, seed: int | None = None) -> None:
        self.k = 0

    def act(self, obs: np.ndarray, info: dict) -> int:
        self.k += 1
        return self.actions[self.k - 1] if self.k <= len(self.actions) else 6


# -- configuration and the shared mission logic (no physics engine) ------------------------


def test_physics_config_validates_fields() -> None:
    with pytest.raises(ConfigError, match="cell_size_m"):
        PhysicsConfig(cell_size_m=0.0)
    with pytest.raises(ConfigError, match="control_hz"):
        PhysicsConfig(physics_hz=240, control_hz=100)
    with pytest.raises(ConfigError, match="wind_mean"):
        PhysicsConfig(wind_mean=(1.0, 2.0))  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="unknown setting"):
        PhysicsConfig.from_dict({"cell_size": 2.0})
    cfg = PhysicsConfig.from_dict({"wind_mean": [1, 0, 0], "tolerance_m": 0.3})
    assert cfg.wind_mean == (1.0, 0.0, 0.0)
    assert PhysicsConfig.from_dict(cfg.to_dict()) == cfg


@pytest.mark.parametrize("footprint", ["paper", "frustum"])
def test_mission_reset_is_the_grid_envs_scenario_and_observation(footprint: str) -> None:
    cfg = VCPPConfig(size=(12, 10, 3), footprint=footprint)
    for seed in (0, 7):
        env = VCPPEnv(cfg)
        grid_obs, _ = env.reset(seed=seed)
        mission = Mission(cfg)
        obs, info = mission.reset(seed)
        np.testing.assert_array_equal(mission.scenario.obstacles, env.world.obstacle_list(0))
        assert mission.start == env.world.position(0)
        np.testing.assert_array_equal(obs, grid_obs)
        assert info["covered"] == env.world.status[0]["covered"]


@pytest.mark.parametrize("footprint", ["paper", "frustum"])
def test_coverage_from_pose_matches_grid_footprint_at_cell_centres(footprint: str) -> None:
    obstacles = [[6.0, 9.0, 0.5, 1.5]]
    cfg = VCPPConfig(size=(15, 13, 3), footprint=footprint, occlusion=footprint == "frustum")
    mission = Mission(cfg, CALM)
    mission.reset(scenario=scenario((3, 3, 0), obstacles))
    grid = mission.world
    rng = np.random.default_rng(0)
    for _ in range(150):
        cell = (int(rng.integers(15)), int(rng.integers(13)), int(rng.integers(3)))
        tilt, pan = int(rng.integers(19)) * 5, int(rng.integers(-6, 7)) * 15
        camera = (tilt, pan, int(rng.integers(5, 21)))
        expected = _cells(grid.footprint(0, pose=cell, camera=camera))
        hover = Pose.level(mission.cell_position(cell))
        assert _cells(mission.footprint(hover, camera)) == expected, (cell, camera)


def test_paper_footprint_follows_the_nearest_cell_and_ignores_attitude() -> None:
    mission = Mission(VCPPConfig(size=(15, 15, 3)), CALM)
    mission.reset(scenario=scenario((7, 7, 1)))
    camera = (75, 0, 15)
    centre = _cells(mission.world.footprint(0, pose=(7, 7, 1), camera=camera))
    near = Pose(mission.cell_position((7, 7, 1)) + [0.45, -0.3, 0.2], np.array([0.2, -0.1, 0.3]))
    assert _cells(mission.footprint(near, camera)) == centre
    beyond = Pose.level(mission.cell_position((7, 7, 1)) + [0.55, 0.0, 0.0])
    assert _cells(mission.footprint(beyond, camera)) == _cells(
        mission.world.footprint(0, pose=(8, 7, 1), camera=camera)
    )


def test_view_angles_follow_gimbal_and_body_attitude() -> None:
    level = np.zeros(3)
    for tilt, pan in ((90, 0), (45, 30), (0, -90), (75, 90)):
        t, p = view_angles(tilt, pan, level, stabilized=False)
        assert t == pytest.approx(tilt, abs=1e-9) and p == pytest.approx(pan, abs=1e-9)
        # The gimbal's yaw compensates the body's heading: pan stays in the world frame.
        t, p = view_angles(tilt, pan, np.array([0.0, 0.0, 0.7]), stabilized=False)
        assert t == pytest.approx(tilt, abs=1e-9) and p == pytest.approx(pan, abs=1e-9)
    # Pitching nose down by 10 degrees tilts a forward-looking camera 10 degrees further down.
    t, p = view_angles(30, 0, np.array([0.0, math.radians(10), 0.0]), stabilized=False)
    assert t == pytest.approx(40.0) and p == pytest.approx(0.0, abs=1e-9)
    # Looking straight down, the same pitch points the camera 10 degrees backwards (tilt 100).
    t, p = view_angles(90, 0, np.array([0.0, math.radians(10), 0.0]), stabilized=False)
    assert t == pytest.approx(100.0) and p == pytest.approx(0.0, abs=1e-9)
    assert view_angles(90, 0, np.array([0.3, 0.2, 0.1]), stabilized=True) == (90.0, 0.0)


def test_frustum_footprint_moves_with_body_attitude() -> None:
    mission = Mission(VCPPConfig(size=(21, 21, 3), footprint="frustum"), CALM)
    mission.reset(scenario=scenario((10, 10, 2)))
    camera = (45, 0, 10)
    position = mission.cell_position((10, 10, 2))
    level = _cells(mission.footprint(Pose.level(position), camera))
    pitched = _cells(mission.footprint(Pose(position, np.array([0, math.radians(15), 0])), camera))
    assert pitched != level
    # Nose down: the view comes closer (smaller mean x offset ahead of the drone).
    assert np.mean([i for i, _ in pitched]) < np.mean([i for i, _ in level])


def fly_kinematic(mission: Mission) -> Pose:
    """A perfect drone: it is wherever the waypoint is, bouncing off obstacle cells."""
    plan = mission.plan
    contact = plan.kind == MOVE and bool(mission.world.blocked[0][plan.target])
    while True:
        pose = Pose.level(mission.target_position())
        if mission.update(0.05, pose, 1.0, contact):
            return pose
        contact = False


@pytest.mark.parametrize("footprint", ["paper", "frustum"])
def test_mission_with_a_perfect_drone_books_coverage_like_the_grid(footprint: str) -> None:
    cfg = VCPPConfig(size=(8, 8, 3), footprint=footprint, max_steps=150, **ROOMY)
    keys = (
        "vcr", "covered", "coverable", "rvc", "overlap", "views_per_cell", "steps", "collisions",
        "redundant_steps", "camera_share", "mean_footprint", "final_tilt", "final_zoom",
    )  # fmt: skip
    for seed in (1, 2):
        grid = run_episode(VCPPEnv(cfg), RandomPolicy(seed), seed).metrics
        mission = Mission(cfg, CALM)
        obs, info = mission.reset(seed)
        policy = RandomPolicy(seed)
        policy.reset(mission.world, 0, seed=seed)
        done = False
        while not done:
            mission.begin_step(policy.act(obs, info))
            obs, terminated, truncated, info = mission.end_step(fly_kinematic(mission))
            done = terminated or truncated
        physics = mission.metrics()
        assert grid["collisions"] > 0
        assert {k: physics[k] for k in keys} == pytest.approx({k: grid[k] for k in keys})
        assert info["episode_metrics"]["vcr"] == physics["vcr"]


def test_begin_step_applies_camera_rules_geofence_and_targets() -> None:
    cfg = VCPPConfig(size=(5, 5, 3), **ROOMY)
    mission = Mission(cfg, CALM)
    mission.reset(scenario=scenario((0, 2, 0)))
    plan = mission.begin_step(1)  # x- out of the grid
    assert plan.kind == REFUSED and plan.target == (0, 2, 0)
    mission.end_step(fly_kinematic(mission))
    assert mission.world.status[0]["collisions"] == 1 and mission.geofence == 1  # one collision
    plan = mission.begin_step(6)  # tilt+5 at its limit of 90: unchanged, like the grid
    assert plan.kind == CAMERA and plan.camera == (90, 0, 10)
    mission.end_step(fly_kinematic(mission))
    plan = mission.begin_step(10)
    assert plan.camera == (90, 0, 11) and mission.camera() == (90, 0, 11)
    mission.end_step(fly_kinematic(mission))
    plan = mission.begin_step(0)
    assert plan.kind == MOVE and plan.target == (1, 2, 0)
    np.testing.assert_allclose(mission.target_position(), [1.0, 2.0, 1.0])
    mission.end_step(fly_kinematic(mission))
    assert mission.world.position(0) == (1, 2, 0)


def test_timeout_and_drift_are_recorded() -> None:
    mission = Mission(VCPPConfig(size=(5, 5, 3), **ROOMY), CALM)
    mission.reset(scenario=scenario((1, 1, 1)))
    mission.begin_step(0)
    stuck = Pose.level(mission.cell_position((1, 1, 1)) + [0.1, 0.0, 0.0])
    t = 0.0
    while not mission.update(0.1, stuck):
        t += 0.1
    assert t == pytest.approx(CALM.step_timeout_s - 0.1, abs=0.11)
    mission.end_step(stuck)
    m = mission.metrics()
    assert m["timeouts"] == 1 and m["wind_pushes"] == 1  # ended off its waypoint's cell
    assert m["tracking_error_m"] == pytest.approx(0.9)
    assert m["sim_seconds"] == pytest.approx(CALM.step_timeout_s, abs=1e-6)


def test_energy_model_and_contact_helpers() -> None:
    assert normalized_power(np.ones(4)) == pytest.approx(1.0)
    assert normalized_power(np.full(4, 1.1)) == pytest.approx(1.331)
    # Rotors beyond the real drone's top speed are charged at it.
    capped = normalized_power(np.array([3.4, 3.4, 1.0, 1.0]), 1.5)
    assert capped == pytest.approx((2 * 1.5**3 + 2) / 4)
    spheres = np.array([[2.0, 0.0, 1.0, 1.0]])
    assert touching(np.array([0.95, 0.0, 1.0]), spheres, 0.1)
    assert not touching(np.array([0.8, 0.0, 1.0]), spheres, 0.1)
    mission = Mission(VCPPConfig(size=(5, 5, 3), **ROOMY), PhysicsConfig(energy_per_hover_s=2.0))
    mission.reset(scenario=scenario((1, 1, 1)))
    mission.begin_step(10)  # a camera action: hover for camera_hold_s plus the gimbal's cost
    while not mission.update(0.01, Pose.level(mission.target_position()), power=1.5):
        pass
    mission.end_step(Pose.level(mission.target_position()))
    hold = mission.physics.camera_hold_s
    assert mission.energy_used == pytest.approx(2.0 * 1.5 * hold + 0.2, abs=0.04)


# -- real PyFlyt flights -------------------------------------------------------------------


def _flight(size=(7, 7, 3), start=(3, 3, 1), obstacles=None, physics=CALM, **settings):
    cfg = VCPPConfig(size=size, **{**ROOMY, **settings})
    mission = Mission(cfg, physics)
    mission.reset(scenario=scenario(start, obstacles, wind_seed=11))
    return mission, PyFlytFlight(mission)


def _step(mission: Mission, flight: PyFlytFlight, action: int) -> Pose:
    mission.begin_step(action)
    pose = flight.fly(mission)
    mission.end_step(pose)
    return pose


def test_short_physics_episode_runs_and_replays_exactly() -> None:
    cfg = VCPPConfig(size=(6, 6, 3), max_steps=12, scale_by_alpha=False)
    first = run_physics_episode(cfg, RandomPolicy(3), seed=3, physics=PhysicsConfig())
    grid_keys = set(run_episode(VCPPEnv(cfg), RandomPolicy(3), 3).metrics)
    extras = {"timeouts", "tracking_error_m", "sim_seconds", "contacts", "recoveries"}
    assert grid_keys | extras <= set(first)
    assert 1 <= first["steps"] <= 12 and 0.0 < first["vcr"] <= 1.0
    assert first["sim_seconds"] > 0 and first["battery_left"] < 1.0
    again = run_physics_episode(cfg, RandomPolicy(3), seed=3, physics=PhysicsConfig())
    assert again == first  # same seed: same wind, same motor noise, same flight


def test_drone_reaches_waypoints_in_calm_air() -> None:
    mission, flight = _flight()
    with flight:
        plan = [0, 2, 4, 1, 1, 3, 5]  # x+, y+, z+, x-, x-, y-, z-
        expected = [(4, 3, 1), (4, 4, 1), (4, 4, 2), (3, 4, 2), (2, 4, 2), (2, 3, 2), (2, 3, 1)]
        for action, cell in zip(plan, expected, strict=True):
            pose = _step(mission, flight, action)
            assert mission.world.position(0) == cell
            dist = np.linalg.norm(pose.position - mission.cell_position(cell))
            assert dist <= CALM.tolerance_m
            # Paper model: the view from the real pose is the grid's view from the cell.
            assert _cells(mission.footprint(pose)) == _cells(mission.world.footprint(0))
    m = mission.metrics()
    assert m["timeouts"] == 0 and m["collisions"] == 0 and m["recoveries"] == 0
    # A one-cell hop of a 1 m cell takes a second or two, not the 5 s timeout.
    assert 0.5 < m["sim_seconds"] / len(plan) < 2.5


def _hover_drift(physics: PhysicsConfig) -> float:
    """Mean distance from the cell centre over 40 hover steps (camera actions), metres."""
    mission, flight = _flight(physics=physics)
    centre = mission.cell_position((3, 3, 1))
    with flight:
        poses = [_step(mission, flight, 6 + k % 2) for k in range(40)]
    drift = [np.linalg.norm(p.position - centre) for p in poses]
    return float(np.mean(drift))


def test_strong_wind_increases_drift() -> None:
    calm = _hover_drift(CALM)
    storm = _hover_drift(PhysicsConfig(wind_mean=(8.0, 3.0, 0.0), wind_gust=4.0))
    assert storm > 1.5 * calm and storm - calm > 0.02, (calm, storm)


def test_collision_with_a_sphere_is_detected_and_the_drone_bounces_back() -> None:
    # Cell (2, 2, 1) lies inside the sphere, (1, 2, 1) outside it: x+ from (1, 2, 1) hits it.
    mission, flight = _flight(start=(1, 2, 1), obstacles=[[3.2, 2.0, 1.0, 1.5]])
    assert mission.world.blocked[0, 2, 2, 1] and not mission.world.blocked[0, 1, 2, 1]
    with flight:
        _step(mission, flight, 0)
        m = mission.metrics()
        assert m["collisions"] == 1 and m["contacts"] == 1 and m["timeouts"] == 0
        assert mission.world.position(0) == (1, 2, 1)
        _step(mission, flight, 2)  # y+ away from the sphere: no new collision
    assert mission.metrics()["collisions"] == 1


def _causes(m: dict) -> dict[str, float]:
    return {c: m[f"energy_{c}"] for c in ENERGY_CAUSES}


def test_energy_by_cause_adds_up_and_follows_the_flight() -> None:
    # x+, z+, z-, a camera action, x+ into the sphere, then x- out of the grid twice.
    mission, flight = _flight(start=(1, 2, 1), obstacles=[[4.2, 2.0, 1.0, 1.5]])
    with flight:
        costs = {}
        for action, cause in ((0, "move"), (4, "climb"), (5, "descend"), (10, "camera")):
            before = mission.metrics()
            _step(mission, flight, action)
            after = mission.metrics()
            costs[cause] = after[f"energy_{cause}"] - before[f"energy_{cause}"]
            # Each step's energy lands in its own causes only.
            changed = {c for c in ENERGY_CAUSES if after[f"energy_{c}"] != before[f"energy_{c}"]}
            assert changed == ({"hover", "camera"} if cause == "camera" else {cause})
        _step(mission, flight, 0)  # (2, 2, 1) -> (3, 2, 1) lies inside the sphere
        for _ in range(3):
            _step(mission, flight, 1)
    m = mission.metrics()
    assert m["contacts"] == 1 and m["geofence"] == 1
    assert sum(_causes(m).values()) == pytest.approx(m["energy_used"], rel=1e-12)
    assert m["energy_contact"] > 0 and m["energy_geofence"] > 0 and m["energy_timeout"] == 0
    assert m["energy_camera"] == pytest.approx(0.2)  # the grid's energy_camera
    # Calibrated near the grid's table: a one-cell flight costs about 1.1 units.
    assert all(0.7 < costs[c] < 1.8 for c in ("move", "climb", "descend")), costs
    assert m["end"] is None  # the episode goes on


@pytest.mark.parametrize(
    ("settings", "end"),
    [
        ({"battery_capacity": 1000.0}, "coverage"),
        ({"battery_capacity": 3.0}, "battery"),
        ({"battery_capacity": 1000.0, "max_steps": 4}, "step_limit"),
    ],
)
def test_physics_episode_says_why_it_ended(settings: dict, end: str) -> None:
    from pirl.agents.boustrophedon import BoustrophedonPolicy

    cfg = VCPPConfig(size=(5, 5, 3), scale_by_alpha=False, **{"max_steps": 200, **settings})
    m = run_physics_episode(cfg, BoustrophedonPolicy(), seed=2, physics=CALM)
    assert m["end"] == end
    assert sum(_causes(m).values()) == pytest.approx(m["energy_used"], rel=1e-12)
    if end == "coverage":
        assert m["vcr"] == 1.0
    elif end == "battery":
        assert m["battery_left"] == 0.0 and m["vcr"] < 1.0
    else:
        assert m["steps"] == 4 and m["battery_left"] > 0


def test_a_drone_wedged_under_a_sphere_is_put_back_and_charged_a_real_drones_power() -> None:
    # The geometry of the PPO-EWRI episode (30x30x3, scenario 0, step 55), moved into
    # a small world: x+ into an obstacle cell wedges the QuadX under the sphere at full
    # thrust. It used to stay there for every later step, 128 units per 5 s timeout.
    mission, flight = _flight(
        size=(8, 8, 3), start=(2, 4, 1), obstacles=[[3.81, 3.75, 1.95, 1.576]]
    )
    with flight:
        _step(mission, flight, 0)
        m = mission.metrics()
        assert m["timeouts"] == 1 and m["contacts"] == 1 and m["recoveries"] == 1
        assert mission.world.position(0) == (2, 4, 1)  # back where it came from
        # At most the real drone's top power (thrust-to-weight 2.2: 3.3x hover) for 5 s.
        top = CALM.energy_per_hover_s * CALM.max_thrust_to_weight**1.5 * CALM.step_timeout_s
        assert 1.0 < m["energy_contact"] + m["energy_timeout"] <= top
        _step(mission, flight, 1)  # and it flies on
    m = mission.metrics()
    assert m["timeouts"] == 1 and mission.world.position(0) == (1, 4, 1)
    assert sum(_causes(m).values()) == pytest.approx(m["energy_used"], rel=1e-12)


def test_runner_evaluates_the_physics_simulator() -> None:
    from pirl.evaluate.runner import SIMS, run_chunk, spec_for_builtin

    assert "physics" in SIMS
    env = VCPPConfig(max_steps=10, scale_by_alpha=False).to_dict()
    records = run_chunk(spec_for_builtin("boustrophedon"), env, {}, (6, 6, 3), "physics", [0])
    assert len(records) == 1 and records[0]["sim"] == "physics"
    assert records[0]["steps"] <= 10 and "sim_seconds" in records[0]


def test_report_puts_physics_beside_grid_and_explains_a_gap_by_counted_events() -> None:
    from pirl.evaluate.runner import run_chunk, spec_for_builtin
    from pirl.report.physics import physics_gap_table

    spec = spec_for_builtin("boustrophedon")
    env = VCPPConfig(max_steps=5, scale_by_alpha=False).to_dict()
    grid = run_chunk(spec, env, {}, (10, 10, 3), "grid", [0, 1])
    flights = run_chunk(spec, env, {}, (10, 10, 3), "physics", [0, 1])
    assert [f["end"] for f in flights] == ["step_limit"] * 2  # 5 steps do not cover 10x10
    table = physics_gap_table(grid + flights)
    cells = next(row for row in table.rows if row[0].startswith("boustrophedon"))
    vcr_grid = np.mean([g["vcr"] for g in grid])
    vcr_physics = np.mean([f["vcr"] for f in flights])
    assert cells[5:7] == [f"{vcr_grid:.2f}", f"{vcr_physics:.2f}"]
    assert cells[8] == "step_limit 2"
    # The episode: an empty battery after 59 steps, 4 timeouts taking most of it.
    bad = [
        {**f, "vcr": f["vcr"] - 0.3, "end": "battery", "timeouts": 4, "energy_timeout": 300.0}
        for f in flights
    ]
    why = physics_gap_table(grid + bad).rows[-1][-1]
    assert "battery 2 in physics against step_limit 2 on the grid" in why
    assert "4.0 timeouts" in why and "of the battery" in why
    assert physics_gap_table(grid) is None  # no physics episodes, no section


# -- Webots: world generator, controller arguments, pilot (no Webots needed) ----------------


def test_webots_world_has_mavic_camera_zoom_floor_and_the_scenarios_spheres(tmp_path) -> None:
    cfg = VCPPConfig(size=(30, 30, 3))
    mission = Mission(cfg, PhysicsConfig(cell_size_m=2.0, level_height_m=2.0))
    mission.reset(0)
    spheres = mission.obstacle_spheres_m()
    text = world_text(cfg, 0)
    assert text.startswith("#VRML_SIM R2023b utf8")
    assert "Mavic2Pro {" in text and "zoom CameraZoom {" in text
    assert "size 60 60" in text  # 30 cells of 2 m
    assert text.count("Solid {") == len(spheres) >= 2
    for cx, cy, cz, r in spheres:
        assert f"translation {cx:.6g} {cy:.6g} {cz:.6g}" in text
        assert text.count(f"radius {r:.6g}") >= 2  # shape and bounding object

    runner = CliRunner()
    out = tmp_path / "project" / "worlds" / "world.wbt"
    result = runner.invoke(
        app, ["webots-world", "--size", "30", "30", "3", "--seed", "0", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert out.read_text() == text
    shim = tmp_path / "project" / "controllers" / "pirl_mavic" / "pirl_mavic.py"
    assert "pirl.physics.webots.controller" in shim.read_text()


def test_webots_world_strings_are_json_escaped_not_html_escaped() -> None:
    odd = 'runs/<a & b>/it\'s "q", ü.yaml'
    text = world_text(VCPPConfig(size=(12, 10, 3)), 5, config_path=odd)
    assert f"    {json.dumps(odd)}\n  ]\n" in text  # the last controller argument
    assert text.endswith("}\n") and "\n\n" not in text.split("WorldInfo", 1)[1]


def test_webots_controller_rebuilds_the_worlds_mission(tmp_path) -> None:
    cfg = VCPPConfig(size=(12, 10, 3))
    write_world(tmp_path / "w.wbt", cfg, 5, controller=False)
    text = (tmp_path / "w.wbt").read_text()
    block = text[text.index("controllerArgs [") : text.index("]", text.index("controllerArgs ["))]
    argv = [json.loads(line.strip()) for line in block.splitlines()[1:] if line.strip()]
    mission = mission_from_args(parse_args(argv))
    mission.reset(parse_args(argv).seed)
    reference = Mission(cfg, PhysicsConfig(cell_size_m=2.0, level_height_m=2.0))
    reference.reset(5)
    np.testing.assert_allclose(mission.obstacle_spheres_m(), reference.obstacle_spheres_m())
    assert mission.start == reference.start


def test_mavic_pilot_hovers_level_and_leans_towards_its_waypoint() -> None:
    pilot = MavicPilot()
    here, still, level = np.array([0.0, 0.0, 2.0]), np.zeros(3), np.zeros(3)
    fl, fr, rl, rr = pilot.propeller_speeds(here, still, level, still, here)
    hover = 68.5 + 3.0 * 0.6**3
    assert (fl, -fr, -rl, rr) == pytest.approx((hover,) * 4)
    fl, fr, rl, rr = np.abs(pilot.propeller_speeds(here, still, level, still, here + [2, 0, 0]))
    assert rl > fl and rr > fr  # rear up, nose down: forward (+x)
    fl, fr, rl, rr = np.abs(pilot.propeller_speeds(here, still, level, still, here + [0, 2, 0]))
    assert fr > fl and rr > rl  # right side up: roll left (+y)
    assert normalized_power(pilot.power_ratios([68.5, -68.5, -68.5, 68.5])) == pytest.approx(1.0)
