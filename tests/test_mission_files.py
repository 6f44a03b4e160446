"""`pirl fly` on mission folders edited by hand, as a pilot brings them back from a ground
station: each damage refused in one line naming the file, the item and the field (exit 2, no
traceback); frames honoured; items it does not fly named with their count; a missing sortie
caught; an edited file named in a warning."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from cli_checks import one_error_line


def pirl(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pirl", *args], capture_output=True, text=True, timeout=300
    )


@pytest.fixture(scope="module")
def folders(tmp_path_factory) -> dict[str, Path]:
    """A 10x10x3 boustrophedon mission written by `pirl plan` as one sortie and as several
    (a 60 s battery); tests copy them before editing."""
    root = tmp_path_factory.mktemp("written")
    preset = root / "short.yaml"
    preset.write_text("mission:\n  battery_s: 60\n  reserve: 0.1\n")
    out = {"one": root / "one", "split": root / "split"}
    for name, extra in (("one", []), ("split", ["--config", str(preset)])):
        proc = pirl("plan", "--method", "boustrophedon", "--size", "10", "10", "3", "--seed", "3",
                    "--out", str(out[name]), *extra)  # fmt: skip
        assert proc.returncode == 0, proc.stderr
    return out


def edited(folders: dict[str, Path], tmp_path: Path, change: Callable[[dict], Any],
           which: str = "one", name: str = "mission") -> Path:  # fmt: skip
    """A copy of a written folder with ``change`` applied to ``name``.plan's JSON."""
    folder = tmp_path / which
    shutil.copytree(folders[which], folder)
    doc = json.loads((folder / f"{name}.plan").read_text())
    change(doc)
    (folder / f"{name}.plan").write_text(json.dumps(doc, indent=1))
    return folder


def first(doc: dict, command: int) -> dict:
    return next(i for i in doc["mission"]["items"] if i["command"] == command)


@pytest.mark.parametrize(
    "change, needles",
    [
        # a waypoint's latitude a string, NaN, its params null
        (lambda d: first(d, mav.MAV_CMD_NAV_WAYPOINT)["params"].__setitem__(4, "north"),
         ["params[4] (latitude)", "'north' is str, not a number"]),
        (lambda d: first(d, mav.MAV_CMD_NAV_WAYPOINT)["params"].__setitem__(4, math.nan),
         ["params[4] (latitude)", "nan is not a finite number"]),
        (lambda d: first(d, mav.MAV_CMD_NAV_WAYPOINT).update(params=None),
         ["params: None is not a list of 7"]),
        # items an object, or holding a string
        (lambda d: d["mission"].update(items={"1": {}}), ["mission.items", "is not a list"]),
        (lambda d: d["mission"]["items"].insert(4, "north"), ["item 5: 'north' is not an object"]),
        # a file that is not a mission plan
        (lambda d: d.update(fileType="GeoFence"), ["fileType: 'GeoFence', not 'Plan'"]),
        # above terrain, on a world without a ground model
        (lambda d: first(d, mav.MAV_CMD_NAV_WAYPOINT).update(frame=10),
         ["frame: 10 (above terrain) needs a site with a terrain model"]),
        # a waypoint moved off the world
        (lambda d: first(d, mav.MAV_CMD_NAV_WAYPOINT)["params"].__setitem__(6, 400.0),
         ["400 m above home lies outside the 10x10x3 world"]),
    ],
)  # fmt: skip
def test_a_damaged_plan_is_one_line_naming_the_file_item_and_field(
    folders: dict[str, Path], tmp_path: Path, change: Callable, needles: list[str]
) -> None:
    folder = edited(folders, tmp_path, change)
    doc = json.loads((folders["one"] / "mission.plan").read_text())
    waypoint = next(
        n for n, i in enumerate(doc["mission"]["items"], 1)
        if i["command"] == mav.MAV_CMD_NAV_WAYPOINT
    )  # fmt: skip
    # A change to the first waypoint names it as QGroundControl numbers it.
    named = [] if "item" in needles[0] or "fileType" in needles[0] else [
        f"item {waypoint} (MAV_CMD_NAV_WAYPOINT)"
    ]  # fmt: skip
    one_error_line(pirl("fly", str(folder)), f"{folder / 'mission.plan'}", *named, *needles)
    assert not (folder / "flown.json").exists()


def test_a_missing_sortie_is_caught(folders: dict[str, Path], tmp_path: Path) -> None:
    folder = tmp_path / "split"
    shutil.copytree(folders["split"], folder)
    count = json.loads((folder / "summary.json").read_text())["sorties"]
    assert count >= 3
    (folder / "sortie-2.plan").unlink()
    one_error_line(
        pirl("fly", str(folder)), f"summary.json lists {count} sortie(s)", "sortie-2.plan",
        "missing; nothing flown",
    )  # fmt: skip
    shutil.copy(folders["split"] / "sortie-2.plan", folder / f"sortie-{count + 1}.plan")
    shutil.copy(folders["split"] / "sortie-2.plan", folder / "sortie-2.plan")
    one_error_line(pirl("fly", str(folder)), f"sortie-{count + 1}.plan is not among the")


def test_an_amsl_mission_over_a_high_home_flies_as_the_relative_one(
    folders: dict[str, Path], tmp_path: Path
) -> None:
    relative = tmp_path / "relative"
    shutil.copytree(folders["one"], relative)
    proc = pirl("fly", str(relative))
    assert proc.returncode == 0, proc.stderr
    assert "warning" not in proc.stderr
    flown = json.loads((relative / "flown.json").read_text())
    assert flown["edited"] == [] and flown["warnings"] == [] and flown["items_skipped"] == {}

    def amsl(doc: dict) -> None:
        # Home 500 m above sea level; every position written above sea level (frame 0).
        doc["mission"]["plannedHomePosition"][2] = 500.0
        for item in doc["mission"]["items"]:
            if item["command"] in (mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_NAV_WAYPOINT):
                item["frame"] = mav.MAV_FRAME_GLOBAL
                item["params"][6] += 500.0

    folder = edited(folders, tmp_path, amsl)
    proc = pirl("fly", str(folder))
    assert proc.returncode == 0, proc.stderr
    high = json.loads((folder / "flown.json").read_text())
    assert abs(high["vcr"] - flown["vcr"]) <= 0.02, (high["vcr"], flown["vcr"])
    assert high["steps"] == flown["steps"]
    # The edit is named: the .plan changed, and its .waypoints no longer says the same.
    warnings = [line for line in proc.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 2, proc.stderr
    assert "mission.plan changed since pirl plan wrote it" in warnings[0]
    assert "mission.waypoints disagrees with mission.plan" in warnings[1]
    assert high["edited"] == ["mission.plan"] and len(high["warnings"]) == 2


def test_items_it_does_not_fly_are_named_with_their_count(
    folders: dict[str, Path], tmp_path: Path
) -> None:
    def jumps(doc: dict) -> None:
        items = doc["mission"]["items"]
        jump = {"type": "SimpleItem", "autoContinue": True, "command": mav.MAV_CMD_DO_JUMP,
                "doJumpId": 0, "frame": 2, "params": [2, 3, 0, 0, 0, 0, 0]}  # fmt: skip
        items.insert(3, dict(jump))
        items.insert(len(items) - 1, dict(jump))
        items.insert(5, {**jump, "command": mav.MAV_CMD_CONDITION_DELAY,
                         "params": [5, 0, 0, 0, 0, 0, 0]})  # fmt: skip

    folder = edited(folders, tmp_path, jumps)
    proc = pirl("fly", str(folder))
    assert proc.returncode == 0, proc.stderr
    assert (
        "not flown: 3 item(s) pirl fly does not fly: MAV_CMD_CONDITION_DELAY x1, "
        "MAV_CMD_DO_JUMP x2" in proc.stdout
    ), proc.stdout
    flown = json.loads((folder / "flown.json").read_text())
    assert flown["items_skipped"] == {"MAV_CMD_DO_JUMP": 2, "MAV_CMD_CONDITION_DELAY": 1}


def test_a_damaged_waypoints_file_beside_a_good_plan_is_refused(
    folders: dict[str, Path], tmp_path: Path
) -> None:
    folder = tmp_path / "one"
    shutil.copytree(folders["one"], folder)
    path = folder / "mission.waypoints"
    lines = path.read_text().splitlines()
    cols = lines[3].split("\t")
    cols[9] = "inf"
    lines[3] = "\t".join(cols)
    path.write_text("\n".join(lines) + "\n")
    one_error_line(pirl("fly", str(folder)), str(path), "item 2 (line 4)", "column 10",
                   "'inf' is not a finite number")  # fmt: skip
