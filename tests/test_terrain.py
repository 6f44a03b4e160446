"""Ground models: a DTM and a DSM in metres above sea level read onto a site's grid, levels
that follow the terrain, and every bad ground model refused in one line."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import rasterio

from cli_checks import one_error_line, upload_with_mavsdk
from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig
from pirl.missions.site_check import check_site
from pirl.world.seeable import with_site
from pirl.world.site import load_site

ROOT = Path(__file__).resolve().parents[1]
HILLS = ROOT / "examples" / "sites" / "hills"


def pirl(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pirl", *args], capture_output=True, text=True, timeout=300
    )


def band(path: Path) -> np.ndarray:
    """A raster's first band as (x east, y north), the grid's axes."""
    with rasterio.open(path) as src:
        return src.read(1).astype(np.float64)[::-1, :].T


def copy_hills(folder: Path, **changes: object) -> Path:
    """The hills example in ``folder`` with ``changes`` to its site.yaml (None drops a key)."""
    import yaml

    shutil.copytree(HILLS, folder)
    settings = yaml.safe_load((folder / "site.yaml").read_text())
    for key, value in changes.items():
        if value is None:
            settings.pop(key, None)
        else:
            settings[key] = value
    (folder / "site.yaml").write_text(yaml.safe_dump(settings))
    return folder


def test_hills_terrain_and_obstacles_come_from_the_rasters() -> None:
    site = load_site(HILLS)
    dtm, dsm = band(HILLS / "dtm.tif"), band(HILLS / "dsm.tif")
    assert site.has_terrain and site.size == (48, 40, 4)
    # Same grid as the rasters: the terrain is the DTM's posts, obstacles DSM - DTM >= 1 m.
    np.testing.assert_allclose(site.terrain, dtm, atol=1e-3)
    expected = np.where(dsm - dtm >= 1.0, dsm - dtm, 0.0)
    np.testing.assert_allclose(site.heights, expected, atol=1e-3)
    # A hill is ground to fly over: every area cell without an obstacle is coverable ground,
    # and level 0 is free wherever no obstacle stands and no no-fly zone lies.
    assert site.terrain.max() - site.terrain.min() > 40
    assert np.array_equal(site.coverable, site.area & (site.heights == 0))
    assert np.array_equal(site.blocked[:, :, 0], (site.heights > 0) | site.no_fly)


def test_flat_sites_have_zero_terrain() -> None:
    for name in ("campus", "village", "town"):
        site = load_site(ROOT / "examples" / "sites" / name)
        assert not site.has_terrain and not site.terrain.any(), name


def test_site_check_accounts_for_every_cell_and_reports_the_ground() -> None:
    _, seen, report = check_site(HILLS)
    assert report["seeable"] + sum(report["unseeable"].values()) == report["coverable"]
    lo, hi = report["elevation_m"]
    assert 299 < lo < hi < 346
    assert 5 < report["slope_deg"]["mean"] < report["slope_deg"]["max"] < 45
    g0, g1 = report["gsd_cm_per_px"]
    assert 0 < g0 < g1 < 5
    assert "terrain dtm.tif" in report["ground"]
    proc = pirl("site", "check", str(HILLS))
    assert proc.returncode == 0, proc.stderr
    assert "m above sea level, slope" in proc.stdout
    assert "ground sample distance" in proc.stdout


def test_a_dtm_in_another_crs_is_reprojected(tmp_path: Path) -> None:
    """The DTM written in UTM zone 32N (the site's grid is zone 33N's): read back onto the grid
    within a few centimetres of the same ground (bilinear between reprojected posts)."""
    from rasterio.warp import Resampling, calculate_default_transform, reproject

    folder = copy_hills(tmp_path / "hills")
    with rasterio.open(HILLS / "dtm.tif") as src, warnings.catch_warnings():
        # rasterio 1.4 multiplies affine matrices with `*` inside this helper.
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        transform, width, height = calculate_default_transform(
            src.crs, "EPSG:32632", src.width, src.height, *src.bounds, resolution=2.5
        )
        data = np.full((height, width), np.nan, dtype=np.float32)
        reproject(
            src.read(1), data, src_transform=src.transform, src_crs=src.crs,
            dst_transform=transform, dst_crs="EPSG:32632", resampling=Resampling.bilinear,
            dst_nodata=np.nan,
        )  # fmt: skip
        profile = src.profile | {
            "crs": "EPSG:32632", "transform": transform, "width": width, "height": height,
            "nodata": np.nan,
        }  # fmt: skip
    with rasterio.open(folder / "dtm.tif", "w", **profile) as dst:
        dst.write(data, 1)
    site = load_site(folder)
    assert "terrain dtm.tif (bilinear, reprojected from EPSG:32632)" in site.ground
    original = load_site(HILLS)
    inner = np.s_[2:-2, 2:-2]
    assert np.abs(site.terrain - original.terrain)[inner].max() < 0.6
    assert np.abs(site.terrain - original.terrain)[inner].mean() < 0.1


def test_a_dsm_alone_estimates_the_terrain(tmp_path: Path) -> None:
    folder = copy_hills(tmp_path / "hills", terrain=None)
    site = load_site(folder)
    dtm = band(HILLS / "dtm.tif")
    assert "estimated from the surface dsm.tif" in site.ground
    # The three buildings stand out as obstacles; the open ground is within 1.5 m of the DTM.
    original = load_site(HILLS)
    buildings = original.heights >= 8.0
    assert (site.heights[buildings] > 0).mean() > 0.9
    open_ground = original.heights == 0
    assert np.abs(site.terrain - dtm)[open_ground].mean() < 1.5
    report = check_site(folder)[2]
    assert "estimated" in report["ground"]


def _write(path: Path, values: np.ndarray, **profile: object) -> None:
    with rasterio.open(HILLS / "dtm.tif") as src:
        base = src.profile
    with rasterio.open(path, "w", **(base | profile)) as dst:
        dst.write(values.astype(np.float32), 1)
        for key, value in profile.items():
            if key == "units":
                dst.units = (value,)


def _broken_dtm(folder: Path, kind: str) -> None:
    dtm = band(HILLS / "dtm.tif").T[::-1].copy()  # rows north to south again
    if kind == "nan":
        dtm[5:8, 5:8] = np.nan
        _write(folder / "dtm.tif", dtm)
    elif kind == "nodata":
        dtm[0, 0:4] = -9999.0
        _write(folder / "dtm.tif", dtm, nodata=-9999.0)
    elif kind == "feet":
        _write(folder / "dtm.tif", dtm * 3.28084)
        with rasterio.open(folder / "dtm.tif", "r+") as dst:
            dst.units = ("ft",)
    elif kind == "degrees":
        from affine import Affine

        _write(
            folder / "dtm.tif", dtm, crs="EPSG:4326", transform=Affine(1e-4, 0, 15, 0, -1e-4, 47)
        )


GROUND_MISTAKES = {
    "nan": ("site.terrain", "9 of the grid's 1,920 cells are no-data, NaN"),
    "nodata": ("site.terrain", "no-data, NaN or outside dtm.tif"),
    "feet": ("site.terrain", "states heights in 'ft'"),
    "degrees": ("site.terrain", "is in degrees"),
    "heights-and-surface": ("site.surface", "not both"),
    "not-a-tif": ("site.terrain", "expected a GeoTIFF"),
    "missing": ("site.terrain", "does not exist"),
}


@pytest.mark.parametrize("name", sorted(GROUND_MISTAKES))
def test_bad_ground_models_are_refused_in_one_line(tmp_path: Path, name: str) -> None:
    changes: dict[str, object] = {}
    if name == "heights-and-surface":
        changes = {"heights": "dtm.tif"}
    elif name == "not-a-tif":
        changes = {"terrain": "dtm.png"}
    elif name == "missing":
        changes = {"terrain": "none.tif"}
    folder = copy_hills(tmp_path / "hills", **changes)
    if name in ("nan", "nodata", "feet", "degrees"):
        _broken_dtm(folder, name)
    with pytest.raises(ConfigError) as caught:
        with_site(VCPPConfig(), str(folder))
    for needle in GROUND_MISTAKES[name]:
        assert needle in str(caught.value), str(caught.value)
    if name in ("nan", "feet"):  # the same line from the CLI, and no folder
        out = tmp_path / "plan"
        proc = pirl("plan", "--site", str(folder), "--method", "boustrophedon", "--out", str(out))
        one_error_line(proc, *GROUND_MISTAKES[name])
        assert not out.exists()


def test_pyflyt_stands_the_terrain_where_the_grid_has_it() -> None:
    """The heightfield's surface, found by PyBullet's own ray test, is the site's terrain at
    each cell centre (in the physics' metres, its lowest point at 0)."""
    from pirl.config.physics import PhysicsConfig
    from pirl.physics.flight import Mission
    from pirl.physics.pyflyt_backend import PyFlytFlight

    cfg = with_site(VCPPConfig(), str(HILLS)).replace(wind_prob=0.0)
    mission = Mission(cfg, PhysicsConfig())
    mission.reset(seed=0)
    flight = PyFlytFlight(mission)
    site = load_site(HILLS)
    expected = (site.terrain - site.terrain.min()) / site.level_height_m  # 1 m levels here
    for i, j in ((1, 1), (30, 8), (20, 5), (35, 30), (44, 12)):
        hit = flight.aviary.rayTest([i + 0.01, j + 0.01, 500.0], [i + 0.01, j + 0.01, -50.0])[0]
        assert hit[0] == flight.sphere_ids[0], (i, j, hit)
        assert hit[3][2] == pytest.approx(expected[i, j], abs=0.05), (i, j)
    start = mission.cell_position(mission.start)
    assert start[2] == pytest.approx(expected[10, 20] + 1.0)  # level 0: one level above it


def test_the_terrain_mission_flies_back_in_pyflyt(hills_plan: Path, tmp_path: Path) -> None:
    folder = tmp_path / "hills"
    shutil.copytree(hills_plan, folder)
    proc = pirl("fly", str(folder))
    assert proc.returncode == 0, proc.stderr
    flown = json.loads((folder / "flown.json").read_text())
    assert abs(flown["vcr"] - flown["vcr_grid"]) <= 0.03, flown
    assert flown["contacts"] == 0 and flown["recoveries"] == 0, flown


def test_example_sites_file_is_current() -> None:
    """The hills' GeoJSON polygons are in longitude/latitude (the site's CRS is UTM 33N)."""
    area = json.loads((HILLS / "area.geojson").read_text())
    lon, lat = area["features"][0]["geometry"]["coordinates"][0][0]
    assert 14 < lon < 16 and 46 < lat < 48


# -- missions over the terrain ----------------------------------------------------------------
def _flown_legs(plan: Path) -> list[tuple[float, float, float]]:
    """(lat, lon, height) of every take-off and waypoint of a .plan, in order."""
    from pymavlink.dialects.v20 import common as mav

    items = json.loads(plan.read_text())["mission"]["items"]
    nav = (mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_NAV_WAYPOINT)
    return [tuple(it["params"][4:7]) for it in items if it["command"] in nav]


def _own_profile(points: list[tuple[float, float, float]], frame: str):
    """Sample every metre of every leg against the source rasters, read here with rasterio
    and pyproj (not through pirl): (heights above the DTM, clearances above the DSM, wanted
    height above ground per sample)."""
    from pyproj import Transformer
    from scipy.interpolate import RegularGridInterpolator

    with rasterio.open(HILLS / "dtm.tif") as src:
        dtm, crs, t = src.read(1).astype(float), src.crs, src.transform
    with rasterio.open(HILLS / "dsm.tif") as src:
        dsm = src.read(1).astype(float)
    rows, cols = dtm.shape
    # Pixel centres: x = c + (col + 0.5) a, y = f + (row + 0.5) e (e < 0: rows run south).
    xs = t.c + (np.arange(cols) + 0.5) * t.a
    ys = t.f + (np.arange(rows) + 0.5) * t.e
    ground = RegularGridInterpolator((ys[::-1], xs), dtm[::-1], bounds_error=False, fill_value=None)
    to = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    e, n = to.transform([p[1] for p in points], [p[0] for p in points])
    alt = [p[2] for p in points]
    agl_err, clearance = [], []
    for k in range(1, len(points)):
        (e0, n0, a0), (e1, n1, a1) = (e[k - 1], n[k - 1], alt[k - 1]), (e[k], n[k], alt[k])
        steps = max(1, int(np.ceil(np.hypot(e1 - e0, n1 - n0))))
        s = np.linspace(0, 1, steps + 1)
        pe, pn = e0 + s * (e1 - e0), n0 + s * (n1 - n0)
        g = ground(np.stack([pn, pe], axis=1))
        height = a0 + s * (a1 - a0) if frame == "amsl" else g + a0  # terrain: held above ground
        col = np.clip(((pe - t.c) / t.a).astype(int), 0, cols - 1)
        row = np.clip(((pn - t.f) / t.e).astype(int), 0, rows - 1)
        clearance.append(height - dsm[row, col])
        g0, g1 = ground([[n0, e0]])[0], ground([[n1, e1]])[0]
        agl0, agl1 = a0 - g0, a1 - g1
        if frame == "amsl" and abs(agl0 - agl1) < 0.01 and steps > 1:  # a level leg
            agl_err.append(np.abs(height - g - agl0))
    return np.concatenate(agl_err or [np.zeros(0)]), np.concatenate(clearance)


@pytest.fixture(scope="module")
def hills_plan(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("plans") / "hills"
    proc = pirl("plan", "--site", str(HILLS), "--method", "boustrophedon", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    return out


def test_the_planner_mission_follows_the_terrain_with_clearance(hills_plan: Path) -> None:
    from pymavlink.dialects.v20 import common as mav

    summary = json.loads((hills_plan / "summary.json").read_text())
    assert summary["vcr"] >= 0.99 and summary["altitude_frame"] == "amsl"
    items = json.loads((hills_plan / "mission.plan").read_text())["mission"]["items"]
    frames = {it["frame"] for it in items if it["command"] == mav.MAV_CMD_NAV_WAYPOINT}
    assert frames == {mav.MAV_FRAME_GLOBAL}
    assert len(items) <= summary["mission"]["max_items"]
    errors, clearance = _own_profile(_flown_legs(hills_plan / "mission.plan"), "amsl")
    tol = summary["mission"]["terrain_tolerance_m"]
    assert errors.max() <= tol + 0.05, errors.max()  # bilinear ground here and there
    assert clearance.min() >= summary["mission"]["min_clearance_m"] - 0.05, clearance.min()
    assert summary["terrain"]["max_height_error_m"] <= tol
    # The home the ground station shows is on the ground, above sea level.
    home = json.loads((hills_plan / "mission.plan").read_text())["mission"]["plannedHomePosition"]
    assert 300 < home[2] < 345


def test_mavsdk_uploads_the_terrain_mission(hills_plan: Path) -> None:
    items, got = upload_with_mavsdk(hills_plan / "mission.plan")
    for item, recv in zip(items, got["items"], strict=True):
        assert (recv["command"], recv["frame"]) == (item["command"], item["frame"])
        if item["params"][6] is not None and item["frame"] == 0:  # MAV_FRAME_GLOBAL
            assert abs(recv["z"] - item["params"][6]) < 1e-3


def test_the_terrain_frame_leaves_the_following_to_the_autopilot(tmp_path: Path) -> None:
    from pymavlink.dialects.v20 import common as mav

    config = tmp_path / "terrain.yaml"
    config.write_text("mission:\n  altitude_frame: terrain\n")
    out = tmp_path / "plan"
    proc = pirl("plan", "--site", str(HILLS), "--method", "boustrophedon", "--config",
                str(config), "--out", str(out))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    items = json.loads((out / "mission.plan").read_text())["mission"]["items"]
    nav = [it for it in items if it["command"] == mav.MAV_CMD_NAV_WAYPOINT]
    assert {it["frame"] for it in nav} == {mav.MAV_FRAME_GLOBAL_TERRAIN_ALT}
    assert {it["params"][6] for it in nav} <= {5.0, 10.0, 15.0, 20.0}  # heights above ground
    _, clearance = _own_profile(_flown_legs(out / "mission.plan"), "terrain")
    assert clearance.min() >= 2.0 - 0.05


def test_too_little_clearance_and_a_flat_amsl_frame_are_refused(tmp_path: Path) -> None:
    config = tmp_path / "close.yaml"
    config.write_text("mission:\n  min_clearance_m: 6\n")
    out = tmp_path / "plan"
    proc = pirl("plan", "--site", str(HILLS), "--method", "boustrophedon", "--config",
                str(config), "--out", str(out))  # fmt: skip
    one_error_line(proc, "mission.min_clearance_m=6", "above the surface model at lat")
    assert not out.exists()
    config.write_text("mission:\n  altitude_frame: amsl\n")
    campus = ROOT / "examples" / "sites" / "campus"
    proc = pirl("plan", "--site", str(campus), "--method", "boustrophedon", "--config",
                str(config), "--out", str(out))  # fmt: skip
    one_error_line(proc, "mission.altitude_frame=amsl", "flat ground")
    assert not out.exists()


# -- the grid's rules over terrain ------------------------------------------------------------
def test_a_level_move_over_terrain_pays_its_climb_or_descent() -> None:
    from pirl.env.vcpp_env import VCPPEnv
    from pirl.world.dynamics import X_MINUS, X_PLUS

    cfg = with_site(VCPPConfig(), str(HILLS)).replace(wind_prob=0.0, stall_guard=0)
    site = load_site(HILLS)
    ground = site.terrain / site.level_height_m
    env = VCPPEnv(cfg)
    env.reset(seed=0)
    w = env.world
    x, y, z = w.position(0)
    assert (x, y) == (10, 20)
    for action, dx in ((X_PLUS, 1), (X_MINUS, -1)):
        x, y, _ = w.position(0)
        before = float(w.energy[0])
        env.step(action)
        rise = ground[x + dx, y] - ground[x, y]
        climb = rise * cfg.energy_climb if rise > 0 else -rise * cfg.energy_descend
        spent = before - float(w.energy[0])
        assert spent == pytest.approx(cfg.energy_move + climb + cfg.energy_hover, abs=1e-9)
        assert abs(rise) > 0.05  # the start lies on a slope: the terrain's part is real


def _pyramid(pose, ground: np.ndarray, fov: float, max_range: float) -> set:
    """Cells whose centre on the terrain lies in the camera's pyramid (no occlusion)."""
    import math

    t, p = math.radians(pose.tilt), math.radians(pose.pan)
    th = math.tan(math.radians(fov) / 2) / (pose.zoom10 / 10)
    f = np.array([math.cos(t) * math.cos(p), math.cos(t) * math.sin(p), -math.sin(t)])
    r = np.array([math.sin(p), -math.cos(p), 0.0])
    u = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
    cam = np.array([pose.x, pose.y, pose.z + ground[pose.x, pose.y]])
    out = set()
    for i in range(ground.shape[0]):
        for j in range(ground.shape[1]):
            d = np.array([i, j, ground[i, j] - 1.0]) - cam
            a = d @ f
            inside = a > 0 and abs(d @ r) <= th * a and abs(d @ u) <= 0.75 * th * a
            if inside and math.hypot(d[0], d[1]) <= max_range:
                out.add((i, j))
    return out


def test_the_frustum_over_terrain_is_projected_on_the_ground_and_a_ridge_hides() -> None:
    from pirl.world.footprint import NO_VOXELS, CameraPose, footprint_cells, lens_of

    lens = lens_of(1, (30, 9), 90.0, 12.0, True)
    buf = np.zeros((2000, 2), dtype=np.int64)
    no_spheres = np.zeros((0, 4))

    def seen(pose: CameraPose, ground: np.ndarray) -> set:
        n = footprint_cells(lens, pose, no_spheres, NO_VOXELS, ground, buf)
        return {(int(a), int(b)) for a, b in buf[:n]}

    # A uniform slope hides nothing: the footprint is exactly the cells in the pyramid, and
    # looking uphill it is smaller than over flat ground (the ground comes nearer).
    slope = np.repeat(np.arange(30.0)[:, None] * 0.5, 9, axis=1)  # 0.5 levels a cell, east up
    for pose in (CameraPose(3, 4, 1, 40, 0, 10), CameraPose(20, 4, 2, 90, 0, 10),
                 CameraPose(20, 4, 0, 50, 180, 12)):  # fmt: skip
        assert seen(pose, slope) == _pyramid(pose, slope, 90.0, 12.0), pose
    uphill = CameraPose(3, 4, 1, 40, 0, 10)
    flat = np.full((30, 9), 1e-3)  # a ground model that is flat (still projected per cell)
    assert len(seen(uphill, slope)) < len(seen(uphill, flat))
    # A ridge four levels high at x = 8 hides the valley behind it.
    pose = CameraPose(3, 4, 0, 40, 0, 10)
    ridge = np.zeros((30, 9))
    ridge[8, :] = 4.0
    behind = {c for c in _pyramid(pose, ridge, 90.0, 12.0) if c[0] > 9}
    assert behind and not (behind & seen(pose, ridge))
    assert {c for c in _pyramid(pose, ridge, 90.0, 12.0) if c[0] < 8} <= seen(pose, ridge)
