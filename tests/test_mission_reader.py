"""The mission reader, fed what a pilot's laptop can hand it: the files `pirl plan` writes read
back as written, and the same files mutated (types, NaN and infinity, nulls, missing and extra
keys, huge lists, truncation, other encodings). Each ends in a checked mission or in one
UserError line; never in another exception. Staging folders of a killed writer are cleared."""

from __future__ import annotations

import copy
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pirl.config.errors import UserError
from pirl.config.mission import MissionSettings
from pirl.config.world import VCPPConfig
from pirl.missions import read as R
from pirl.missions.fly import mission_ops
from pirl.missions.write import geo_for, mission_source, remove_stale_staging, write_mission

ROOT = Path(__file__).resolve().parents[1]
# 300 cases a file type in `make test`; PIRL_FUZZ_EXAMPLES=2000 for a longer search.
FUZZ = settings(
    max_examples=int(os.environ.get("PIRL_FUZZ_EXAMPLES", "300")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    database=None,
)


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> Path:
    """A 10x10x3 boustrophedon mission written once in process (`pirl plan` is run as a
    command in test_missions and test_mission_files)."""
    out = tmp_path_factory.mktemp("written") / "m"
    env, policy, what = mission_source(VCPPConfig(), 3, method="boustrophedon", size=(10, 10, 3))
    write_mission(out, env, MissionSettings(), policy, 3, what)
    return out


def test_the_written_plan_and_waypoints_read_back_alike(written: Path) -> None:
    plan = R.read_plan(written / "mission.plan")
    wpl = R.read_waypoints(written / "mission.waypoints")
    assert R.disagreement(plan, wpl) is None
    assert [i.index for i in plan.items] == list(range(1, len(plan.items) + 1))
    assert {R.role(i.command) for i in plan.items} == {"flown", "booked"}
    # A position moved by 2 cm is named; by 5 mm it is the same mission.
    for shift_m, named in ((0.02, True), (0.005, False)):
        moved = [
            R.MissionItem(i.index, i.command, i.frame,
                          (*i.params[:4], i.params[4] + shift_m / 111_320.0, *i.params[5:]))
            if i.index == 1 else i
            for i in wpl.items
        ]  # fmt: skip
        differ = R.disagreement(plan, R.MissionFile(wpl.path, wpl.home, moved))
        assert (differ is not None) == named, differ
        if named:
            assert "item 1" in differ and "apart" in differ


def test_roles_follow_pymavlinks_dialect() -> None:
    m = R.dialect()
    assert R.role(m.MAV_CMD_NAV_WAYPOINT) == R.role(m.MAV_CMD_SET_CAMERA_ZOOM) == "flown"
    assert R.role(m.MAV_CMD_NAV_RETURN_TO_LAUNCH) == "booked"
    assert R.role(m.MAV_CMD_DO_JUMP) == R.role(m.MAV_CMD_NAV_LOITER_TIME) == "skipped"
    assert R.role(60_000) == "unknown"
    assert R.command_name(m.MAV_CMD_DO_JUMP) == "MAV_CMD_DO_JUMP"
    # docs/missions.md names every command flown or understood.
    doc = (ROOT / "docs" / "missions.md").read_text()
    for command in R.GOTO | R.CAMERA | R.BOOKED:
        assert R.command_name(command).removeprefix("MAV_CMD_") in doc


def test_a_file_too_large_or_nested_too_deep_is_one_line(tmp_path: Path) -> None:
    big = tmp_path / "big.plan"
    with big.open("wb") as f:  # sparse: nothing of it is read
        f.truncate(R.MAX_BYTES + 1)
    with pytest.raises(UserError, match="at most 16 MB"):
        R.read_plan(big)
    deep = tmp_path / "deep.plan"
    deep.write_text("[" * 200_000 + "]" * 200_000)
    with pytest.raises(UserError, match="not a QGroundControl plan"):
        R.read_plan(deep)


def test_stale_staging_folders_go_and_a_running_writers_stay(tmp_path: Path) -> None:
    from pirl.missions.staging import host_name as _host

    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)  # fmt: skip
    dead = tmp_path / f".m.staging-{_host()}-{int(done.stdout)}-abc123"
    live = tmp_path / f".n.staging-{_host()}-{os.getpid()}-def456"
    other = tmp_path / ".o.staging-elsewhere-1-ghi789"
    user = tmp_path / ".config"
    for folder in (dead, live, other, user):
        folder.mkdir()
        (folder / "mission.plan").write_text("{}")
    assert remove_stale_staging(tmp_path) == [dead]
    assert not dead.exists() and live.exists() and other.exists() and user.exists()


def test_flown_json_is_replaced_whole_and_a_killed_writers_temporary_goes(tmp_path: Path) -> None:
    from pirl.missions.fly import _write

    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)  # fmt: skip
    stale = tmp_path / f".flown.json.{int(done.stdout)}.tmp"
    stale.write_text('{"vcr": ')  # what a kill mid-write leaves
    _write(tmp_path / "flown.json", '{"vcr": 1.0}\n')
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flown.json"]
    assert json.loads((tmp_path / "flown.json").read_text()) == {"vcr": 1.0}


def test_a_plan_killed_mid_write_leaves_nothing_and_the_next_run_clears_its_staging(
    tmp_path: Path,
) -> None:
    parent = tmp_path / "missions"
    parent.mkdir()
    out = parent / "m"
    proc = subprocess.Popen(
        [sys.executable, "-m", "pirl", "plan", "--method", "boustrophedon", "--size", "30", "30",
         "3", "--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    deadline = time.monotonic() + 240
    while not list(parent.glob(".m.staging-*")) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    left = sorted(p.name for p in parent.iterdir())
    # Killed while staging: no folder at --out, only the staging one; had the kill come after
    # the rename, the finished folder and nothing else.
    assert left == ["m"] or (len(left) == 1 and left[0].startswith(".m.staging-")), left
    if left == ["m"]:
        pytest.skip("the writer finished before the kill (a fast machine)")
    done = subprocess.run(
        [sys.executable, "-m", "pirl", "plan", "--method", "boustrophedon", "--size", "10", "10",
         "3", "--out", str(parent / "again")], capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in parent.iterdir()) == ["again"]


# -- fuzzing ----------------------------------------------------------------------------------
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.sampled_from(["north", "", "Plan", "SimpleItem", "ComplexItem", "1e999", "NaN"]),
)
values = st.recursive(
    scalars,
    lambda inner: (
        st.lists(inner, max_size=8) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),  # fmt: skip
    max_leaves=10,
)


def _paths(node: Any, at: tuple = ()) -> list[tuple]:
    """Every place in a JSON document (dict keys and list positions), the root first."""
    out = [at]
    if isinstance(node, dict):
        for key, value in node.items():
            out += _paths(value, (*at, key))
    elif isinstance(node, list):
        for k, value in enumerate(node):
            out += _paths(value, (*at, k))
    return out


def _get(doc: Any, at: tuple) -> Any:
    for key in at:
        doc = doc[key]
    return doc


@st.composite
def mutated_plans(draw, base: dict) -> bytes:
    doc = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        at = draw(st.sampled_from(_paths(doc)))
        op = draw(st.sampled_from(["value", "value", "delete", "extra", "huge", "repeat"]))
        if not at:
            if op == "value":
                doc = draw(values)
            continue
        parent, key = _get(doc, at[:-1]), at[-1]
        if op == "value":
            parent[key] = draw(values)
        elif op == "delete":
            del parent[key]
        elif op == "extra" and isinstance(parent, dict):
            parent[draw(st.text(max_size=8))] = draw(values)
        elif op == "huge":
            parent[key] = [draw(scalars)] * draw(st.integers(1_000, 100_000))
        elif op == "repeat" and isinstance(parent, list):
            parent.insert(key, copy.deepcopy(parent[key]))
    text = json.dumps(doc, allow_nan=True)
    return _as_bytes(draw, text)


def _as_bytes(draw, text: str) -> bytes:
    """The text as UTF-8, or one time in three damaged as bytes: another encoding, a character
    from outside ASCII, cut short, bytes changed."""
    if draw(st.integers(0, 2)):
        return text.encode()
    if draw(st.booleans()):
        k = draw(st.integers(0, max(0, len(text) - 1)))
        text = text[:k] + draw(st.sampled_from(["é", "\u00ff", "\ufeff", "\x00", "漢"])) + text[k:]
    coding = draw(st.sampled_from(["utf-8", "utf-8-sig", "utf-16", "latin-1", "cp1252"]))
    data = text.encode(coding, errors="replace")
    if draw(st.booleans()):
        data = data[: draw(st.integers(0, len(data)))]
    for _ in range(draw(st.integers(0, 2))):
        if data:
            k = draw(st.integers(0, len(data) - 1))
            data = data[:k] + bytes([draw(st.integers(0, 255))]) + data[k + 1 :]
    return data


TOKENS = st.one_of(
    st.sampled_from(
        ["nan", "NaN", "inf", "-inf", "1e999", "1e-400", "", "north", "0x10", "1_0", "\u0663",
         "99999999999999999999999", "-1", "3", "0", "10", "16", "22", "177", "2.5", "47.4",
         "-91", "181"]
    ),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(2**40), 2**40).map(str),
    st.text(max_size=6),
)  # fmt: skip


@st.composite
def mutated_waypoints(draw, base: str) -> bytes:
    lines = [line.split("\t") for line in base.splitlines()]
    for _ in range(draw(st.integers(1, 3))):
        row = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["token", "token", "token", "drop", "add", "line", "twice"]))
        cols = lines[row]
        if op == "token" and cols:
            cols[draw(st.integers(0, len(cols) - 1))] = draw(TOKENS)
        elif op == "drop" and cols:
            cols.pop(draw(st.integers(0, len(cols) - 1)))
        elif op == "add":
            cols.insert(draw(st.integers(0, len(cols))), draw(TOKENS))
        elif op == "line" and len(lines) > 1:
            lines.pop(row)
        elif op == "twice":
            lines.insert(row, list(cols))
    if draw(st.integers(0, 9)) == 0:
        lines += [list(lines[-1])] * draw(st.integers(1_000, 20_000))
    return _as_bytes(draw, "\n".join("\t".join(cols) for cols in lines) + "\n")


PEAK_BYTES = 256 * 2**20
"""The most memory one read may take: the file's bound (16 MB) parsed into Python objects."""


def _read_and_convert(path: Path, geo: Any) -> None:
    """The reader and the conversion to the flight's ops: a result or one UserError, within
    :data:`PEAK_BYTES` of memory."""
    tracemalloc.start()
    try:
        mission = R.read_mission(path)
        mission_ops(mission, geo, (10, 10, 3), [0, 0, 10])
    except UserError as exc:
        assert "\n" not in str(exc) and str(path) in str(exc)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert peak < PEAK_BYTES, peak


def _geo(written: Path) -> Any:
    summary = json.loads((written / "summary.json").read_text())
    env = VCPPConfig.from_dict(summary["env"])
    return geo_for(env, MissionSettings.from_dict(summary["mission"]), (0, 0, 0))


def test_a_fuzzed_plan_is_read_or_refused_in_one_line(written: Path) -> None:
    base = json.loads((written / "mission.plan").read_text())
    geo = _geo(written)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "mission.plan"

        @FUZZ
        @given(mutated_plans(base))
        def check(data: bytes) -> None:
            path.write_bytes(data)
            _read_and_convert(path, geo)

        check()


def test_a_fuzzed_waypoints_file_is_read_or_refused_in_one_line(written: Path) -> None:
    base = (written / "mission.waypoints").read_text()
    geo = _geo(written)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "mission.waypoints"

        @FUZZ
        @given(mutated_waypoints(base))
        def check(data: bytes) -> None:
            path.write_bytes(data)
            _read_and_convert(path, geo)

        check()


@pytest.mark.parametrize(
    "change, needles",
    [
        (lambda d: d.update(fileType="KML"), ["fileType", "'KML'"]),
        (lambda d: d["mission"].update(items={"a": 1}), ["mission.items", "not a list"]),
        (lambda d: d["mission"]["items"].insert(2, "north"), ["item 3", "not an object"]),
        (lambda d: d["mission"]["items"][0].update(params=None), ["item 1", "params"]),
        (lambda d: d["mission"]["items"][0]["params"].__setitem__(4, "north"),
         ["item 1 (MAV_CMD_NAV_TAKEOFF)", "params[4]", "'north' is str"]),
        (lambda d: d["mission"]["items"][0]["params"].__setitem__(4, math.nan),
         ["item 1", "params[4]", "not a finite number"]),
        (lambda d: d["mission"]["items"][0]["params"].__setitem__(4, 91.0),
         ["item 1", "params[4] (latitude)", "[-90, 90]"]),
        (lambda d: d["mission"]["items"][0].update(frame=6), ["item 1", "frame: 6"]),
        (lambda d: d["mission"]["items"][0].update(command=60_000),
         ["item 1", "no MAVLink command"]),
        (lambda d: d["mission"]["items"][0].update(type="ComplexItem"), ["item 1", "ComplexItem"]),
        (lambda d: d["mission"].update(plannedHomePosition=[0, 0]), ["plannedHomePosition"]),
    ],
)  # fmt: skip
def test_each_damage_is_named_by_file_item_and_field(
    written: Path, tmp_path: Path, change: Any, needles: list[str]
) -> None:
    doc = json.loads((written / "mission.plan").read_text())
    change(doc)
    path = tmp_path / "mission.plan"
    path.write_text(json.dumps(doc))
    with pytest.raises(UserError) as caught:
        R.read_plan(path)
    for needle in [str(path), *needles]:
        assert needle in str(caught.value), (needle, str(caught.value))


def test_a_damaged_waypoints_line_is_named_by_item_and_column(
    written: Path, tmp_path: Path
) -> None:
    lines = (written / "mission.waypoints").read_text().splitlines()
    cols = lines[2].split("\t")  # item 1, the take-off
    cols[8] = "north"
    lines[2] = "\t".join(cols)
    path = tmp_path / "mission.waypoints"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(UserError, match=r"item 1 \(line 3\).*column 9.*'north' is not a number"):
        R.read_waypoints(path)
    path.write_text("\n".join(lines[:2] + lines[3:]) + "\n")  # item 1 gone
    with pytest.raises(UserError, match=r"line 3, column 1 \(seq\): 2 where 1 comes next"):
        R.read_waypoints(path)
