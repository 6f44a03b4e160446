"""pirl plan: missions written with pymavlink's numbers, read back by pymavlink's own loader,
split into sorties, placed on the Earth, and refused in one line when they cannot be flown."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavwp
from pymavlink.dialects.v20 import common as mav

from cli_checks import one_error_line, upload_with_mavsdk

ROOT = Path(__file__).resolve().parents[1]
CAMPUS = ROOT / "examples" / "sites" / "campus"


@pytest.fixture(scope="module")
def ewri_runs(tmp_path_factory) -> dict[int, Path]:
    """PPO-EWRI runs of test.yaml at 256 steps, seeds 0 and 1, trained once for this module
    (in process: `pirl train` itself is tested elsewhere); tests copy them before use."""
    from pirl.agents.train import train
    from pirl.config.run import RunConfig

    root = tmp_path_factory.mktemp("ewri")
    cfg = RunConfig.from_yaml(ROOT / "configs" / "test.yaml").with_overrides(
        train={"total_steps": 256}
    )
    runs = {}
    for seed in (0, 1):
        runs[seed] = root / f"ppo-ewri-s{seed}"
        train("ppo-ewri", cfg, runs[seed], seed=seed, show_progress=False)
    return runs


def pirl(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pirl", *args], capture_output=True, text=True, timeout=300
    )


def plan(out: Path, *extra: str) -> subprocess.CompletedProcess:
    proc = pirl("plan", "--method", "boustrophedon", "--out", str(out), *extra)
    assert proc.returncode == 0, proc.stderr
    return proc


def same(a: float | None, b: float) -> bool:
    if a is None:
        return math.isnan(b)
    return abs(a - b) < 1e-5 * max(1.0, abs(a))


def check_plan_against_waypoints(folder: Path, name: str) -> list[dict]:
    data = json.loads((folder / f"{name}.plan").read_text())
    assert data["fileType"] == "Plan" and data["mission"]["firmwareType"] == mav.MAV_AUTOPILOT_PX4
    items = data["mission"]["items"]
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(folder / f"{name}.waypoints")) == len(items) + 1  # home first
    home = loader.wp(0)
    assert same(data["mission"]["plannedHomePosition"][0], home.x)
    for n, item in enumerate(items, start=1):
        wp = loader.wp(n)
        assert (wp.command, wp.frame) == (item["command"], item["frame"])
        got = [wp.param1, wp.param2, wp.param3, wp.param4, wp.x, wp.y, wp.z]
        assert all(same(a, b) for a, b in zip(item["params"], got, strict=True)), (n, item, got)
    return items


def test_a_generated_world_plan_reads_back_with_pymavlink(tmp_path: Path) -> None:
    out = tmp_path / "m"
    plan(out, "--size", "30", "30", "3", "--seed", "2")
    items = check_plan_against_waypoints(out, "mission")
    commands = [i["command"] for i in items]
    assert (
        commands[0] == mav.MAV_CMD_NAV_TAKEOFF and commands[-1] == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH
    )
    assert mav.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW in commands
    assert mav.MAV_CMD_SET_CAMERA_ZOOM in commands and mav.MAV_CMD_IMAGE_START_CAPTURE in commands
    assert all(
        i["frame"] == mav.MAV_FRAME_GLOBAL_RELATIVE_ALT
        for i in items if i["command"] == mav.MAV_CMD_NAV_WAYPOINT
    )  # fmt: skip
    summary = json.loads((out / "summary.json").read_text())
    assert summary["vcr"] >= 0.99 and not summary["real_place"]
    assert summary["items_after_merging"] < summary["items_before_merging"] / 3
    assert "NOT A REAL PLACE" in (out / "path.kml").read_text()
    kinds = {
        f["properties"]["kind"] for f in json.loads((out / "path.geojson").read_text())["features"]
    }
    assert kinds == {"flight", "waypoint", "footprint"}


def test_gimbal_v1_uses_mount_control(tmp_path: Path) -> None:
    out = tmp_path / "m"
    plan(out, "--size", "15", "15", "3", "--gimbal", "v1")
    items = check_plan_against_waypoints(out, "mission")
    commands = {i["command"] for i in items}
    assert mav.MAV_CMD_DO_MOUNT_CONTROL in commands
    assert mav.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW not in commands


def test_a_long_mission_splits_into_sorties_that_cover_the_same(tmp_path: Path) -> None:
    one, split = tmp_path / "one", tmp_path / "split"
    plan(one, "--size", "30", "30", "3", "--seed", "1")
    preset = tmp_path / "short.yaml"
    preset.write_text("mission:\n  battery_s: 150\n  reserve: 0.1\n")
    plan(split, "--size", "30", "30", "3", "--seed", "1", "--config", str(preset))
    summary = json.loads((split / "summary.json").read_text())
    assert summary["sorties"] >= 2 and not (split / "mission.plan").exists()

    def stops(items: list[dict]) -> set[tuple]:
        return {tuple(round(v, 7) for v in i["params"][4:7]) for i in items
                if i["command"] == mav.MAV_CMD_NAV_WAYPOINT}  # fmt: skip

    union = set()
    for n in range(1, summary["sorties"] + 1):
        items = check_plan_against_waypoints(split, f"sortie-{n}")
        assert items[0]["command"] == mav.MAV_CMD_NAV_TAKEOFF
        assert items[-1]["command"] == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH
        union |= stops(items)
    assert union == stops(check_plan_against_waypoints(one, "mission"))
    assert summary["photos"] == json.loads((one / "summary.json").read_text())["photos"]


def test_a_site_plan_is_on_the_earth_with_its_fences(tmp_path: Path) -> None:
    out = tmp_path / "campus"
    plan(out, "--site", str(CAMPUS))
    data = json.loads((out / "mission.plan").read_text())
    lat, lon, _ = data["mission"]["plannedHomePosition"]
    assert 48.1 < lat < 48.2 and 11.5 < lon < 11.6
    fences = data["geoFence"]["polygons"]
    assert {f["inclusion"] for f in fences} == {True, False}
    assert json.loads((out / "summary.json").read_text())["real_place"]


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--size", "15", "15", "3", "--policy", "nowhere"], "not a finished run"),
        (["--size", "15", "15", "3"], "--policy runs/NAME or --method"),
        (["--method", "boustrophedon"], "--site SITE or --size"),
    ],
)
def test_bad_plans_are_one_line(tmp_path: Path, args: list[str], needle: str) -> None:
    out = tmp_path / "m"
    one_error_line(pirl("plan", *args, "--out", str(out)), needle)
    assert not out.exists()


def test_altitude_limits_and_an_existing_folder_refuse(tmp_path: Path) -> None:
    preset = tmp_path / "low.yaml"
    preset.write_text("mission:\n  max_alt_m: 15\n")
    out = tmp_path / "m"
    proc = pirl("plan", "--size", "15", "15", "3", "--method", "boustrophedon",
                "--config", str(preset), "--out", str(out))  # fmt: skip
    one_error_line(proc, "mission.max_alt_m=15")
    assert not out.exists() and not list(tmp_path.glob(".m.*"))
    out.mkdir()
    proc = pirl("plan", "--size", "15", "15", "3", "--method", "boustrophedon", "--out", str(out))
    one_error_line(proc, "already exists")


def test_mavsdk_imports_the_plan_and_an_autopilot_receives_every_item(tmp_path: Path) -> None:
    out = tmp_path / "m"
    plan(out, "--size", "15", "15", "3", "--seed", "3")
    data, got = upload_with_mavsdk(out / "mission.plan")
    for item, recv in zip(data, got["items"], strict=True):
        assert (recv["command"], recv["frame"]) == (item["command"], item["frame"])
        p = item["params"]
        if item["frame"] == mav.MAV_FRAME_GLOBAL_RELATIVE_ALT:  # a position: degrees * 1e7
            assert (
                abs(recv["x"] - round(p[4] * 1e7)) <= 1 and abs(recv["y"] - round(p[5] * 1e7)) <= 1
            )
            assert same(p[6], recv["z"])
        assert all(same(a, b) for a, b in zip(p[:4], recv["params"], strict=True))


def test_a_trained_policy_plans_with_its_own_label(tmp_path: Path, ewri_runs) -> None:
    run = tmp_path / "run"
    shutil.copytree(ewri_runs[0], run)
    out = tmp_path / "m"
    proc = pirl("plan", "--size", "15", "15", "3", "--policy", str(run), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"].startswith("PPO-EWRI") and "act greedy" in summary["method"]
    check_plan_against_waypoints(out, "mission")


# -- flying the written files back ------------------------------------------------------------
def test_camera_commands_invert_exactly_over_the_whole_grid() -> None:
    from pirl.config.grid import pan_steps, tilt_steps, zoom_steps
    from pirl.missions import formats as M

    assert all(M.tilt_from_pitch(M.gimbal_pitch(t)) == t for t in tilt_steps())
    assert all(M.pan_from_yaw(M.gimbal_yaw(p)) == p for p in pan_steps())
    assert all(
        M.zoom10_from_percent(M.zoom_percent(round(z * 10))) == round(z * 10) for z in zoom_steps()
    )


def test_a_mission_flies_back_from_its_files_with_the_grid_episodes_coverage(
    tmp_path: Path,
) -> None:
    out = tmp_path / "m"
    proc = pirl("plan", "--method", "boustrophedon", "--size", "10", "10", "3", "--seed", "3",
                "--out", str(out), "--fly", "physics")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "flown: VCR" in proc.stdout
    flown = json.loads((out / "flown.json").read_text())
    for key in ("vcr", "vcr_grid", "energy_used", "energy_used_grid", "end"):
        assert key in flown
    assert flown["end"] in ("coverage", "mission_complete")
    assert abs(flown["vcr"] - flown["vcr_grid"]) <= 0.05
    assert abs(flown["energy_used"] - flown["energy_used_grid"]) <= 0.25 * flown["energy_used_grid"]
    assert flown["ops_skipped"] == 0 and flown["wind"]["gust_m_s"] > 0

    # The flight is read from the file, not the episode: a plan cut after its first leg flies
    # only that leg (fewer steps, less coverage).
    from pirl.missions.fly import fly_files, read_flight

    plan_file = out / "mission.plan"
    doc = json.loads(plan_file.read_text())
    items = doc["mission"]["items"]
    first_leg = next(k for k, i in enumerate(items) if i["command"] == mav.MAV_CMD_NAV_WAYPOINT)
    doc["mission"]["items"] = items[: first_leg + 1]
    plan_file.write_text(json.dumps(doc))
    cut = fly_files(read_flight(out))
    assert cut["end"] == "mission_complete" and cut["steps"] < flown["steps"]
    assert cut["vcr"] < flown["vcr"]


def test_sorties_fly_in_order_and_bad_folders_are_one_line(tmp_path: Path) -> None:
    from pirl.missions.fly import read_flight

    preset = tmp_path / "short.yaml"
    preset.write_text("mission:\n  battery_s: 60\n  reserve: 0.1\n")
    one, split = tmp_path / "one", tmp_path / "split"
    plan(one, "--size", "12", "12", "3", "--seed", "1")
    plan(split, "--size", "12", "12", "3", "--seed", "1", "--config", str(preset))
    files, single = read_flight(split), read_flight(one)
    assert len(files.plans) >= 2 and files.plans[:2] == ["sortie-1.plan", "sortie-2.plan"]

    def stops(ops: list) -> list:
        out = []
        for op in ops:
            if op.kind == "goto" and (not out or out[-1] != op.cell):
                out.append(op.cell)
        return out

    # The sorties' waypoints, read back in order, are the single plan's (each later sortie
    # takes off where the last stopped: a repeat, dropped).
    assert files.start == single.start and stops(files.ops) == stops(single.ops)
    one_error_line(pirl("fly", str(tmp_path)), "no summary.json")
    summary = json.loads((one / "summary.json").read_text())
    del summary["env"]  # as an older pirl plan wrote it
    (one / "summary.json").write_text(json.dumps(summary))
    one_error_line(pirl("fly", str(one)), "no grid settings")


def test_a_reproduction_writes_and_flies_the_planner_and_the_best_learned_mission(
    tmp_path: Path, ewri_runs
) -> None:
    import numpy as np

    from pirl.config.run import RunConfig
    from pirl.report.missions import reproduction_missions
    from pirl.report.tables import render_markdown
    from test_sites import write_site

    h = np.zeros((10, 12))
    h[3:6, 4:7] = 12.0  # one building, 2 levels of 10 m
    site = write_site(tmp_path / "block", h, cell_size_m=10.0, start=[0, 0])
    runs = []
    for seed in (0, 1):
        run = tmp_path / f"ppo-ewri-s{seed}"
        shutil.copytree(ewri_runs[seed], run)
        runs.append(run)
    # The evaluation's records name the better run on the site: it is the one flown.
    records = [
        {"train_seed": k, "act": "stochastic", "site": "block", "sim": "grid",
         "source": str(run), "vcr": vcr, "steps": 100}
        for k, (run, vcr) in enumerate(zip(runs, (0.4, 0.6), strict=True))
    ]  # fmt: skip
    # Two workers, as the demo flies them: each mission in a process of its own.
    cfg = RunConfig.from_yaml(ROOT / "configs" / "test.yaml").with_overrides(
        reproduce={"workers": 2}
    )
    logs: list[str] = []
    title, table, figure = reproduction_missions(
        cfg, tmp_path / "out", [str(site)], records, log=logs.append
    )
    assert "in 2 processes" in logs[0] and any("flying block-learned" in line for line in logs)
    missions = tmp_path / "out" / "missions"
    assert sorted(p.name for p in missions.iterdir()) == ["block-learned", "block-planner"]
    learned = json.loads((missions / "block-learned" / "summary.json").read_text())
    assert "ppo-ewri-s1" in learned["method"]
    # Chosen by its VCR in the headline act mode, written acting in that mode.
    assert f"act {cfg.reproduce.headline_act}" in learned["method"]
    for name in ("block-learned", "block-planner"):
        flown = json.loads((missions / name / "flown.json").read_text())
        assert 0 < flown["vcr"] <= 1 and flown["end"]
        check_plan_against_waypoints(missions / name, "mission")
    planner = json.loads((missions / "block-planner" / "flown.json").read_text())
    assert abs(planner["vcr"] - planner["vcr_grid"]) <= 0.05
    markdown = render_markdown([table])
    assert "](../missions/block-planner/mission.plan)" in markdown
    assert "best mean grid VCR on block" in markdown and figure.is_file()


# -- a fleet's missions ------------------------------------------------------------------------
def test_the_best_learned_run_is_the_one_of_most_coverage_then_fewest_steps() -> None:
    from pirl.report.missions import best_run

    def episode(source: str, vcr: float, steps: int, **kw) -> dict:
        return {"train_seed": 0, "act": "stochastic", "site": "campus", "sim": "grid",
                "source": source, "vcr": vcr, "steps": steps, **kw}  # fmt: skip

    records = [
        episode("a", 1.0, 400),
        episode("a", 1.0, 420),  # the same coverage as b, longer
        episode("b", 1.0, 300),
        episode("b", 1.0, 310),
        episode("c", 0.98, 200),
        episode("c", 0.98, 200),  # shorter, but covers less
        episode("d", 1.0, 100, act="greedy"),  # another act mode
        episode("e", 1.0, 100, site="town"),  # another site
        episode("f", 1.0, 100, sim="physics"),  # not the grid's episode
    ]
    assert best_run(records, "campus", "stochastic") == (Path("b"), 1.0)
    assert best_run(records, "campus", "greedy") == (Path("d"), 1.0)
    assert best_run(records, "village", "stochastic") is None


def test_a_fleet_writes_one_mission_per_uav_kept_apart_in_time(tmp_path: Path) -> None:
    """``pirl plan --uavs 3``: uav-1/ .. uav-3/ each a full mission that pymavlink reads back,
    homes at distinct start cells, and fleet.json's separation holds when every UAV's track is
    sampled again, ten times finer, from the written .plan files' own items."""
    from pirl.agents.boustrophedon import BoustrophedonPolicy
    from pirl.config.mission import MissionSettings
    from pirl.config.world import VCPPConfig
    from pirl.evaluate.fleet import team_for
    from pirl.missions.fleet import record_fleet
    from pirl.missions.separation import _gaps as gaps
    from pirl.missions.separation import track
    from pirl.missions.write import plan_episode

    out = tmp_path / "fleet"
    proc = plan(out, "--size", "20", "20", "3", "--seed", "4", "--uavs", "3")
    assert "3 UAVs: fleet VCR" in proc.stdout and "separation 5 m held" in proc.stdout
    fleet = json.loads((out / "fleet.json").read_text())
    assert fleet["uavs"] == 3 and fleet["vcr"] >= 0.99 and fleet["collisions"] == 0
    assert sorted(p.name for p in out.iterdir()) == ["fleet.json", "uav-1", "uav-2", "uav-3"]
    env = VCPPConfig.from_dict(fleet["env"])
    episodes, _ = record_fleet(env, team_for(BoustrophedonPolicy()), 4)
    homes = set()
    settings = MissionSettings.from_dict({**fleet["mission"], "check_every_s": 0.025})
    positions = []
    for u, member in enumerate(fleet["members"], start=1):
        folder = out / f"uav-{u}"
        summary = json.loads((folder / "summary.json").read_text())
        homes.add(tuple(summary["home"]))
        assert summary["sorties"] == member["sorties"] == 1
        items = check_plan_against_waypoints(folder, "mission")
        assert items[0]["command"] == mav.MAV_CMD_NAV_TAKEOFF
        assert items[-1]["command"] == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH
        # The track again, from the fleet's episode played again from fleet.json's env.
        planned = plan_episode(episodes[u - 1], env, settings)
        assert tuple(summary["home"]) == planned.geo.home
        kinds = [(i.kind, i.cell) for i in planned.parts[0].items]
        tr = track(kinds, planned.ep.start[:2], planned.geo.georef.cell_size_m,
                   planned.geo.level_m, settings)  # fmt: skip
        delay = member["takeoff_delay_s"][0]
        clock = np.arange(0.0, tr.seconds + delay + 1.0, settings.check_every_s)
        positions.append(tr.at(clock - delay))
    assert len(homes) == 3
    n = min(len(p) for p in positions)
    for a in range(3):
        for b in range(a + 1, 3):
            h, v = gaps(positions[a][:n], positions[b][:n])
            parked = (positions[a][:n, 2] <= 0) & (positions[b][:n, 2] <= 0)
            assert ((h >= 5 - 1e-6) | (v >= 5 - 1e-6) | parked).all(), (a, b)


def test_a_fleet_that_cannot_keep_apart_is_refused_in_one_line_and_writes_nothing(
    tmp_path: Path,
) -> None:
    config = tmp_path / "tight.yaml"
    config.write_text("mission:\n  separation_m: 60\n  max_delay_s: 0\n")
    out = tmp_path / "fleet"
    proc = pirl("plan", "--method", "boustrophedon", "--size", "20", "20", "3", "--uavs", "3",
                "--config", str(config), "--out", str(out))  # fmt: skip
    one_error_line(proc, "separation_m=60", "UAV 2")
    assert not out.exists() and not list(tmp_path.glob(".fleet*"))
    proc = pirl("plan", "--method", "boustrophedon", "--size", "20", "20", "3", "--uavs", "0",
                "--out", str(out))  # fmt: skip
    one_error_line(proc, "uavs")


def test_a_fleet_flies_back_from_its_files_with_the_grid_fleets_coverage(tmp_path: Path) -> None:
    out = tmp_path / "fleet"
    proc = plan(out, "--size", "10", "10", "3", "--seed", "3", "--uavs", "2", "--fly", "physics")
    assert "fleet flown: VCR" in proc.stdout
    flown = json.loads((out / "flown.json").read_text())
    assert flown["uavs"] == 2 and abs(flown["vcr"] - flown["vcr_grid"]) <= 0.03
    # Flown together in one Aviary: the grid kept them in different cells, and so does PyFlyt.
    assert len(flown["members"]) == 2 and flown["flown"].startswith("together")
    assert flown["contacts_between_drones"] == 0 and flown["closest_approach_m"] > 0.3
    assert "closest_to_waiting_m" in flown  # beside it: to a drone still waiting at home
    assert "0 contacts between drones" in " ".join(proc.stdout.split())
    for u in (1, 2):  # each UAV's own flight, beside its credited cells in the grid
        own = json.loads((out / f"uav-{u}" / "flown.json").read_text())
        assert own["vcr"] >= own["vcr_grid"] - 0.03
        assert own["end"] in ("coverage", "mission_complete")
