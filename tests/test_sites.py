"""Sites: real maps into voxel worlds, the check's reasons, every mistake in one line, and the
paper's sphere worlds unchanged."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cli_checks import one_error_line
from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig
from pirl.env.vcpp_env import VCPPEnv
from pirl.world.footprint import NO_GROUND, CameraPose, footprint_cells, lens_of
from pirl.world.seeable import analyse, lens_for, with_site
from pirl.world.site import load_site
from world_hash import CONFIGS, state_hash

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "sites"
UAVSIM = Path(__file__).parent / "data" / "uavsim" / "manhattan32.png"

# Taken on the code before the voxel world (tests/world_hash.py, 200 seeds each).
OLD_HASHES = {
    "paper": "ecd157523b21feeae8d8115ef3c61f33fb2a8035eb15ae1b09da0893238cf298",
    "frustum-occlusion": "6a0e47f5ad10b5784c6151eed194d5281df4f7997397d5e7e75e8eb5e1446aa0",
    "target-line": "74d7c835f50a0abec028d1d17665a1cbd3774f6380a251cb2dca7b5d131e897a",
}


def pirl(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pirl", *args], capture_output=True, text=True, cwd=cwd, timeout=300
    )


def write_site(folder: Path, heights: np.ndarray, **settings: object) -> Path:
    """A site of a CSV raster (row 0 north) and ``settings`` as its site.yaml."""
    import yaml

    folder.mkdir(parents=True, exist_ok=True)
    np.savetxt(folder / "h.csv", heights, delimiter=",", fmt="%g")
    (folder / "site.yaml").write_text(yaml.safe_dump({"heights": "h.csv", **settings}))
    return folder


def square(x0: float, y0: float, x1: float, y1: float) -> dict:
    ring = [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]
    return {"type": "Polygon", "coordinates": [ring]}


def courtyard_site(folder: Path) -> Path:
    """40 x 24 cells: a ring building (every level) round an 18 x 18 courtyard, and an
    11 x 11 no-fly zone; start at (0, 0).

    Paper camera (a square of half-width up to 4, no occlusion): courtyard cells farther than
    4 cells from every reachable cell (x, y in 6..17: 144) are unreachable; no-fly cells
    farther than 4 from every cell outside the zone (x 31..33, y 9..11: 9) are seen only from
    inside it."""
    grid = np.zeros((40, 24))  # (x, y)
    grid[2:22, 2] = grid[2:22, 21] = grid[2, 2:22] = grid[21, 2:22] = 30.0
    (folder).mkdir(parents=True, exist_ok=True)
    (folder / "nfz.geojson").write_text(json.dumps(square(27, 5, 38, 16)))
    raster = grid.T[::-1]  # rows north to south
    return write_site(
        folder, raster, cell_size_m=10.0, levels=3, no_fly="nfz.geojson", start=[0, 0]
    )


# -- the paper's worlds ---------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_sphere_worlds_hash_as_before(name: str) -> None:
    assert state_hash(CONFIGS[name], range(200)) == OLD_HASHES[name]


# -- the check's reasons ----------------------------------------------------------------------
def test_courtyard_and_no_fly_pocket_get_exact_counts(tmp_path: Path) -> None:
    site = load_site(courtyard_site(tmp_path / "yard"))
    assert site.size == (40, 24, 3)
    seen = analyse(site, lens_for(VCPPConfig(size=site.size)))
    assert seen.coverable == 40 * 24 - 76
    assert seen.counts == {"hidden": 0, "no_fly": 9, "unreachable": 144}
    assert int(seen.seeable.sum()) + sum(seen.counts.values()) == seen.coverable
    assert not seen.seeable[6:18, 6:18].any() and seen.seeable[5, 5]
    assert not seen.seeable[31:34, 9:12].any() and seen.seeable[30, 10]


def test_check_cli_json_and_picture(tmp_path: Path) -> None:
    folder = courtyard_site(tmp_path / "yard")
    pic = tmp_path / "yard.png"
    proc = pirl("site", "check", str(folder), "--json", "--picture", str(pic))
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["size"] == [40, 24, 3]
    assert report["seeable"] + sum(report["unseeable"].values()) == report["coverable"]
    assert report["unseeable"]["unreachable"] == 144
    from PIL import Image

    with Image.open(pic) as img:
        assert img.size[0] >= 40 and img.size[1] > 24
    text = pirl("site", "check", str(folder))
    assert text.returncode == 0 and "144 cannot be seen" in text.stdout


def test_frustum_occlusion_hides_ground_behind_a_wall(tmp_path: Path) -> None:
    # A wall one cell thick, every level high, along x = 5: from x < 5 a camera looking +x
    # sees nothing beyond it; the voxel march stops those rays.
    occluding = np.zeros((12, 6, 3), dtype=bool)
    occluding[5, :, :] = True
    lens = lens_of(1, (12, 6), 90.0, 8.0, True)
    buf = np.zeros((400, 2), dtype=np.int64)
    pose = CameraPose(2, 3, 2, 30, 0, 10)
    n = footprint_cells(lens, pose, np.zeros((0, 4)), occluding, NO_GROUND, buf)
    seen = {tuple(r) for r in buf[:n]}
    open_n = footprint_cells(lens, pose, np.zeros((0, 4)), occluding[:0, :0, :0], NO_GROUND, buf)
    assert n < open_n and not any(i > 5 for i, _ in seen)


def test_roofs_inside_a_block_are_hidden_from_every_cell(tmp_path: Path) -> None:
    # roofs: true makes a 5 x 5 block (every level high) coverable. Frustum with occlusion:
    # its edge roofs are seen from beside it (a roof is not hidden by its own column), its
    # inner 3 x 3 lie behind the edge columns from every free cell: hidden. The free ground
    # round it is seen from straight above.
    h = np.zeros((11, 11))
    h[3:8, 3:8] = 30.0
    site = load_site(write_site(tmp_path / "s", h, cell_size_m=10.0, start=[0, 0], roofs=True))
    cfg = VCPPConfig(size=site.size, footprint="frustum", occlusion=True)
    seen = analyse(site, lens_for(cfg))
    assert seen.coverable == 121
    assert seen.counts == {"hidden": 9, "no_fly": 0, "unreachable": 0}
    assert (seen.reason[4:7, 4:7] == 0).all()


# -- real inputs ------------------------------------------------------------------------------
def test_example_sites_load_and_check() -> None:
    for name, size in (("campus", (48, 40, 3)), ("village", (128, 128, 3))):
        site = load_site(EXAMPLES / name)
        assert site.size == size and site.georef.real
        seen = analyse(site, lens_for(VCPPConfig(size=site.size)))
        assert seen.seeable.sum() > 0.9 * seen.coverable
    campus = load_site(EXAMPLES / "campus")
    assert campus.no_fly.sum() > 0 and not campus.area.all()
    # The start's lat/lon goes there and back.
    lon, lat = campus.georef.lonlat_from_cells(np.array([3.5]), np.array([3.5]))
    assert 11 < lon[0] < 12 and 48 < lat[0] < 48.2
    x, y = campus.georef.cells_from_lonlat(lon, lat)
    assert abs(x[0] - 3.5) < 1e-6 and abs(y[0] - 3.5) < 1e-6


def test_geotiff_start_by_lat_lon(tmp_path: Path) -> None:
    import shutil

    import yaml

    folder = tmp_path / "campus"
    shutil.copytree(EXAMPLES / "campus", folder)
    site = load_site(folder)
    lon, lat = site.georef.lonlat_from_cells(np.array([10.5]), np.array([20.5]))
    data = yaml.safe_load((folder / "site.yaml").read_text())
    data["start"] = {"lat": float(lat[0]), "lon": float(lon[0])}
    (folder / "site.yaml").write_text(yaml.safe_dump(data))
    assert load_site(folder).starts.tolist() == [[10, 20, 0]]


def test_uavsim_map_imports_and_checks(tmp_path: Path) -> None:
    from pirl.world.uavsim import read_uavsim

    out = tmp_path / "manhattan32"
    proc = pirl("site", "import-uavsim", str(UAVSIM), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    site = load_site(out)
    no_fly, obstacle, start, _ = read_uavsim(UAVSIM)
    grid = lambda layer: layer[::-1].T  # noqa: E731 - raster rows to (x, y)
    assert site.size == (32, 32, 3)
    assert (site.blocked.all(axis=2) == grid(no_fly)).all()  # red and yellow: every level
    assert (site.occluding[:, :, 0] == grid(obstacle)).all()
    assert (site.blocked[:, :, 1] == grid(no_fly)).all()  # green only: flown over
    assert len(site.starts) == int(start.sum())
    again = pirl("site", "import-uavsim", str(UAVSIM), "--out", str(out))
    one_error_line(again, "already exists")
    check = pirl("site", "check", str(out), "--json")
    assert check.returncode == 0 and json.loads(check.stdout)["seeable"] > 0


def test_resampling_keeps_the_highest_pixel(tmp_path: Path) -> None:
    h = np.zeros((8, 8))
    h[0, 0] = 7.0  # north-west pixel
    site = load_site(write_site(tmp_path / "s", h, pixel_size_m=5.0, cell_size_m=10.0))
    assert site.size[:2] == (4, 4)
    assert site.heights[0, 3] == 7.0 and site.heights.sum() == 7.0


# -- a site in the environment and in evaluation -------------------------------------------
def test_env_on_a_site_draws_starts_and_counts_seeable_cells(tmp_path: Path) -> None:
    folder = courtyard_site(tmp_path / "yard")
    cfg = with_site(VCPPConfig(wind_prob=0.0), str(folder))
    assert cfg.size == (40, 24, 3) and cfg.ground_cells == 884 - 153
    env = VCPPEnv(cfg)
    env.reset(seed=3)
    w = env.world
    assert w.status[0]["coverable"] == 884 - 153 and w.coverable_all[0] == 884
    assert w.blocked[0, 2, 5].all() and w.position(0) == (0, 0, 0)
    *_, info = env.step(0)
    while "episode_metrics" not in info:
        *_, info = env.step(int(env.np_random.integers(env.action_space.n)))
    m = info["episode_metrics"]
    assert m["vcr_all"] == pytest.approx(m["covered"] / 884)


def test_evaluate_site_planner_covers_seeable_cells(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    proc = pirl(
        "evaluate", "--methods", "boustrophedon", "--site", str(EXAMPLES / "campus"),
        "--episodes", "2", "--out", str(out),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert len(rows) == 2 and all(
        r["site"] == "campus" and r["size"] == "site:campus" for r in rows
    )
    assert all(r["vcr"] >= 0.99 and r["vcr_all"] < r["vcr"] for r in rows)


def test_report_tables_take_a_site_beside_a_size(tmp_path: Path) -> None:
    from pirl.evaluate.summary import read_summary
    from pirl.report.document import camera_table, improvements, paper_tables
    from pirl.report.physics import physics_gap_table

    out = tmp_path / "eval"
    proc = pirl(
        "evaluate", "--methods", "boustrophedon,random", "--sizes", "15",
        "--site", str(EXAMPLES / "campus"), "--episodes", "2", "--out", str(out),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    rows = read_summary(out / "summary.csv")
    assert [r["size"] for r in rows if r["method"] == "random"] == ["15x15x3", "site:campus"]
    assert "site:campus VCR" in paper_tables(rows, "fixed")[0].header
    assert "site:campus" in [row[2] for row in camera_table(rows).rows]
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    # The planner's rows as a two-seed PIRL and the same as physics rows: the P(improvement)
    # and the physics gap tables sort a site beside a size too.
    as_pirl = [{**r, "method": "pirl", "train_seed": k % 2, "act": "stochastic"}
               for k, r in enumerate(records) if r["method"] == "boustrophedon"]  # fmt: skip
    found = improvements(records + as_pirl, "stochastic")
    assert {c["size"] for c in found} == {"15x15x3", "site:campus"}
    physics = [{**r, "sim": "physics"} for r in as_pirl]
    assert "site:campus" in [row[2] for row in physics_gap_table(as_pirl + physics).rows]


# -- mistakes -------------------------------------------------------------------------------
def bad_site(tmp_path: Path, name: str) -> Path:
    folder = tmp_path / name
    h = np.zeros((10, 10))
    if name == "not-a-raster":
        folder.mkdir()
        (folder / "h.png").write_text("not an image")
        (folder / "site.yaml").write_text("heights: h.png\n")
    elif name == "tif-no-crs":
        import warnings

        import rasterio

        folder.mkdir()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
            with rasterio.open(
                folder / "h.tif", "w", driver="GTiff", width=10, height=10, count=1,
                dtype="float32",
            ) as dst:  # fmt: skip
                dst.write(h.astype("float32"), 1)
        (folder / "site.yaml").write_text("heights: h.tif\n")
    elif name == "area-outside":
        write_site(folder, h, area="a.geojson")
        (folder / "a.geojson").write_text(json.dumps(square(50, 50, 60, 60)))
    elif name == "nan":
        h[2, 2] = np.nan
        write_site(folder, h)
    elif name == "negative":
        h[2, 2] = -1.0
        write_site(folder, h)
    elif name == "start-in-building":
        h[0, 0] = 100.0  # row 0 north: cell (0, 9)
        write_site(folder, h, start=[0, 9])
    elif name == "start-in-no-fly":
        write_site(folder, h, start=[1, 1], no_fly="n.geojson")
        (folder / "n.geojson").write_text(json.dumps(square(0, 0, 3, 3)))
    elif name == "nothing-seeable":
        # Only a 2 x 2 area deep inside a closed courtyard is to be covered.
        g = np.zeros((30, 30))
        g[10:20, 10] = g[10:20, 19] = g[10, 10:20] = g[19, 10:20] = 100.0
        write_site(folder, g, start=[0, 0], area="a.geojson")
        (folder / "a.geojson").write_text(json.dumps(square(14, 14, 16, 16)))
    elif name == "too-large":
        write_site(folder, h, levels=8, max_cells=100)
    elif name == "unknown-key":
        write_site(folder, h, cel_size_m=2.0)
    return folder


MISTAKES = {
    "not-a-raster": "not a readable png raster",
    "tif-no-crs": "has no CRS",
    "area-outside": r"spans x 50 to 60, y 50 to 60 \(cell units\), the grid x 0 to 10, y 0 to 10",
    "nan": "NaN or nodata",
    "negative": "negative",
    "start-in-building": "inside a building",
    "start-in-no-fly": "inside a no-fly zone",
    "nothing-seeable": "no coverable cell can be seen",
    "too-large": "site.max_cells",
    "unknown-key": "cell_size_m",
}


def test_an_area_or_start_off_a_georeferenced_grid_is_named_in_degrees(tmp_path: Path) -> None:
    """Both the polygon's extent and the grid's in the GeoJSON's longitude/latitude (the
    site's projected metres or cell units labelled as degrees would mislead)."""
    import re

    h = np.zeros((10, 10))
    area = write_site(tmp_path / "area", h, cell_size_m=10.0, origin=[48.15, 11.57],
                      area="a.geojson")  # fmt: skip
    (area / "a.geojson").write_text(json.dumps(square(11.60, 48.20, 11.61, 48.21)))
    with pytest.raises(ConfigError) as caught:
        load_site(area)
    line = str(caught.value)
    assert "spans lon 11.600000 to 11.610000, lat 48.200000 to 48.210000 (WGS84" in line, line
    grid = r"the grid lon 11\.570000 to 11\.5713\d+, lat 48\.150000 to 48\.1508\d+ \(WGS84"
    assert re.search(grid, line), line
    one_error_line(pirl("site", "check", str(area)), "spans lon 11.600000 to 11.610000")
    start = write_site(tmp_path / "start", h, cell_size_m=10.0, origin=[48.15, 11.57],
                       start={"lat": 48.3, "lon": 11.57})  # fmt: skip
    with pytest.raises(ConfigError, match=r"lies outside the 10 x 10 grid, which spans lon 11\.5"):
        load_site(start)


@pytest.mark.parametrize("name", sorted(MISTAKES))
def test_bad_sites_are_refused_in_one_line(tmp_path: Path, name: str) -> None:
    folder = bad_site(tmp_path, name)
    with pytest.raises(ConfigError, match=MISTAKES[name]):
        with_site(VCPPConfig(), str(folder))
    if name in ("nan", "unknown-key", "nothing-seeable"):  # the same line from the CLI
        out = tmp_path / "render.gif"
        proc = pirl("render", "--policy", "boustrophedon", "--site", str(folder), "--out", str(out))
        one_error_line(proc, MISTAKES[name])
        assert not out.exists()


# -- physics -------------------------------------------------------------------------------
def test_boxes_cover_exactly_the_voxels() -> None:
    from pirl.world.boxes import merge_boxes

    rng = np.random.default_rng(0)
    for _ in range(20):
        grid = rng.random((9, 7, 4)) < 0.4
        filled = np.zeros(grid.shape, dtype=int)
        for x0, y0, z0, x1, y1, z1 in merge_boxes(grid):
            filled[x0 : x1 + 1, y0 : y1 + 1, z0 : z1 + 1] += 1
        assert (filled == grid).all()  # disjoint, and their union is the grid
    town = load_site(EXAMPLES / "town")
    assert len(merge_boxes(town.occluding)) < town.occluding.sum() / 100


def test_pyflyt_flies_a_site_among_its_buildings(tmp_path: Path) -> None:
    from pirl.agents.loading import load_policy
    from pirl.physics.flight import Mission
    from pirl.physics.pyflyt_backend import run_physics_episode

    h = np.zeros((8, 8))
    h[2:5, 3:6] = 12.0  # one building, 2 levels of 10 m
    folder = write_site(tmp_path / "s", h, cell_size_m=10.0, start=[0, 0])
    cfg = with_site(VCPPConfig(), str(folder)).replace(max_steps=4, scale_by_alpha=False)
    mission = Mission(cfg)
    mission.reset(seed=1)
    boxes = mission.obstacle_boxes_m()
    assert len(boxes) == 1 and boxes[0, 2] - boxes[0, 5] == 0.0  # it stands on the ground
    metrics = run_physics_episode(cfg, load_policy("boustrophedon", seed=0), 1)
    assert metrics["steps"] == 4 and metrics["collisions"] == 0 and metrics["vcr"] > 0


def test_a_profile_that_trains_on_a_site_checks_its_sizes_as_generated_worlds() -> None:
    from pirl.config.run import RunConfig
    from pirl.reproduce.plan import check_reproduce

    cfg = RunConfig.from_yaml(ROOT / "configs" / "test.yaml")
    site = with_site(cfg.env, str(EXAMPLES / "campus"))
    cfg = cfg.with_overrides(
        env={"site": site.site, "size": list(site.size), "ground_cells": site.ground_cells},
        reproduce={"methods": ["ppo-ewri"]},
    )
    checked = check_reproduce(cfg, "oracle")
    assert [run.method for run in checked.runs] == ["ppo-ewri"] * len(cfg.reproduce.seeds)
