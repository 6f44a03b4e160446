"""The command line, run as a real subprocess the way a user runs it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import imageio.v2 as imageio
import pytest
import typer
from typer.testing import CliRunner

from cli_checks import one_error_line
from pirl.agents.methods import METHODS, PLAYED_ALONE
from pirl.cli import app

PIRL = [sys.executable, "-m", "pirl"]


def _run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*PIRL, *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_render_writes_a_gif(tmp_path):
    out = tmp_path / "ep.gif"
    proc = _run(
        "render", "--policy", "boustrophedon", "--size", "20", "15", "3", "--seed", "1",
        "--out", str(out), cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "VCR" in proc.stdout
    frames = [f for f in imageio.get_reader(out)]
    assert len(frames) > 10
    assert frames[0].shape[:2] == (15 * 24, 20 * 24)


def test_bad_input_is_one_clear_line(tmp_path):
    proc = _run("render", "--size", "2", "30", "3", cwd=tmp_path)
    assert proc.returncode == 2
    assert "size=(2, 30, 3) is impossible" in proc.stderr
    assert "Traceback" not in proc.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text("env:\n  sise: [15, 15, 3]\n")
    proc = _run("render", "--config", str(bad), cwd=tmp_path)
    one_error_line(proc, "unknown setting 'sise'", "did you mean 'size'")
    assert not (tmp_path / "episode.gif").exists()


# -- list options: Typer parses them (repeated, or comma-separated for names and numbers) ------


def _params(*args: str) -> dict:
    """The values Typer parses from a command line, without running the command."""
    command = typer.main.get_command(app)
    name, *rest = args
    return command.commands[name].make_context(name, list(rest)).params


def test_list_options_are_repeated_or_comma_separated() -> None:
    params = _params(
        "evaluate", "--methods", "boustrophedon,random", "--methods", "llm-only",
        "--sizes", "30, 45", "--sizes", "40x25x4", "--sim", "grid,physics",
        "--runs", "runs/my run, 2", "--runs", "runs/b", "--site", "sites/a,b",
    )  # fmt: skip
    assert params["methods"] == ["boustrophedon", "random", "llm-only"]
    assert params["sizes"] == ["30", "45", "40x25x4"]
    assert params["sim"] == ["grid", "physics"]
    # A path is one value whatever it holds: commas and spaces are kept.
    assert [str(p) for p in params["runs"]] == ["runs/my run, 2", "runs/b"]
    assert [str(p) for p in params["site"]] == ["sites/a,b"]
    assert _params("reproduce", "--seeds", "1,2", "--seeds", "3")["seeds"] == [1, 2, 3]
    none = _params("evaluate")
    assert none["methods"] is None and none["sizes"] is None and not none["runs"]


def test_evaluate_takes_repeated_and_comma_separated_values(tmp_path: Path) -> None:
    out = tmp_path / "ev"
    proc = _run(
        "evaluate", "--methods", "boustrophedon,random", "--sizes", "8", "--sizes", "9x8x3",
        "--episodes", "1", "--out", str(out), cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert sorted((r["method"], r["size"]) for r in rows) == [
        ("boustrophedon", "8x8x3"), ("boustrophedon", "9x8x3"),
        ("random", "8x8x3"), ("random", "9x8x3"),
    ]  # fmt: skip


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["reproduce", "--seeds", "1,x"], ["--seeds '1,x'", "'x' is not a whole number"]),
        (["evaluate", "--methods", "random", "--sizes", "30,,45"], ["--sizes '30,,45'", "empty"]),
        (["evaluate", "--sim", "grid,"], ["--sim 'grid,'", "empty"]),
    ],
)
def test_a_bad_list_value_is_one_line_and_exit_2(tmp_path, args, needles) -> None:
    one_error_line(_run(*args, cwd=tmp_path), *needles)
    assert not list(tmp_path.iterdir())  # refused while parsing: nothing written


def test_argv_is_not_rewritten(tmp_path: Path) -> None:
    """Several values after one flag are no longer spread over the option (exit 2)."""
    proc = _run("evaluate", "--methods", "random", "--sizes", "8", "9", cwd=tmp_path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "unexpected extra argument" in proc.stderr
    assert not list(tmp_path.iterdir())


# -- every --config: a preset name or a path --------------------------------------------------


def test_render_takes_a_preset_by_name(tmp_path: Path) -> None:
    out = tmp_path / "q.gif"
    proc = _run(
        "render", "--config", "quick", "--size", "8", "8", "3", "--footprint", "frustum",
        "--out", str(out), cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert out.is_file() and "(8, 8, 3) seed 0" in proc.stdout


def test_an_env_only_config_says_where_its_settings_go(tmp_path: Path) -> None:
    old = tmp_path / "env.yaml"
    old.write_text("size: [15, 15, 3]\nfootprint: frustum\n")
    for command in ("render", "webots-world"):
        proc = _run(command, "--config", str(old), cwd=tmp_path)
        one_error_line(proc, "size, footprint are env settings", "under 'env:'")


def test_webots_world_takes_a_preset_and_its_controller_rebuilds_that_env(tmp_path) -> None:
    from pirl.config.run import RunConfig
    from pirl.physics.webots.controller import mission_from_args, parse_args

    out = tmp_path / "project" / "worlds" / "w.wbt"
    result = CliRunner().invoke(
        app, ["webots-world", "--config", "quick", "--size", "12", "10", "3", "--seed", "3",
              "--footprint", "frustum", "--out", str(out)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    env_file = out.with_name("w.env.yaml")
    assert env_file.is_file()
    text = out.read_text()
    block = text[text.index("controllerArgs [") : text.index("]", text.index("controllerArgs ["))]
    argv = [json.loads(line.strip()) for line in block.splitlines()[1:] if line.strip()]
    assert argv[argv.index("--config") + 1] == str(env_file.resolve())
    env = parse_args(argv)
    mission = mission_from_args(env)
    quick = RunConfig.from_yaml(Path(__file__).parents[1] / "configs" / "quick.yaml").env
    assert mission.cfg == quick.replace(size=(12, 10, 3), footprint="frustum")


# -- method names: what the registry says ------------------------------------------------------


def test_built_ins_that_play_alone_come_from_the_registry(tmp_path: Path) -> None:
    assert tuple(m.name for m in METHODS.values() if m.plays_alone) == PLAYED_ALONE
    assert set(PLAYED_ALONE) == {"boustrophedon", "random"}  # not llm-only: it asks an advisor
    assert not METHODS["llm-only"].plays_alone and not METHODS["pirl"].plays_alone
    proc = _run("render", "--policy", "llm-only", "--size", "8", "8", "3", cwd=tmp_path)
    one_error_line(proc, "--policy 'llm-only'", ", ".join(PLAYED_ALONE))
