"""Ray (``pirl[distributed]``): evaluation and training on a real local Ray instance.

The Ray tests start one Ray instance with 2 CPUs for the module (about 5 s) and keep the
work tiny; ``make test`` installs the extra, so they run in CI. Select them alone with
``pytest -m ray``.
"""

from __future__ import annotations

import functools
import json
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig
from pirl.evaluate.executors import ray_executor
from pirl.evaluate.runner import EvalPlan, evaluate, spec_for_builtin
from pirl.reproduce.pipeline import train_all

ROOT = Path(__file__).resolve().parents[1]


def _plan() -> EvalPlan:
    return EvalPlan(
        specs=[spec_for_builtin("boustrophedon"), spec_for_builtin("random")],
        sizes=[(16, 16, 3), (20, 12, 3)],
        episodes=2,
    )


def _ray():
    try:
        import ray
    except ImportError:
        pytest.fail("Ray is missing: pip install -e '.[dev,distributed]' (make test does)")
    return ray


@pytest.fixture(scope="module")
def ray_instance():
    ray = _ray()
    ray.init(num_cpus=2, include_dashboard=False, object_store_memory=100 * 1024**2)
    yield ray
    ray.shutdown()


@pytest.mark.ray
def test_evaluation_on_ray_gives_the_local_numbers(ray_instance, tmp_path):
    # In-process here; test_evaluate shows the process pool gives the same files.
    local = evaluate(_plan(), tmp_path / "local", workers=1)
    factory = functools.partial(ray_executor, "local")
    on_ray = evaluate(_plan(), tmp_path / "ray", workers=2, executor_factory=factory)
    assert on_ray.read_text() == local.read_text()
    episodes = (tmp_path / "ray" / "episodes.jsonl").read_text()
    assert episodes == (tmp_path / "local" / "episodes.jsonl").read_text()
    assert len(episodes.splitlines()) == 2 * 2 * 2
    assert ray_instance.is_initialized()  # a connection made by the caller is left open


@pytest.mark.ray
def test_training_runs_go_to_ray_il_after_its_expert(ray_instance, tmp_path):
    cfg = RunConfig.from_yaml(ROOT / "configs" / "test.yaml")
    logs: list[str] = []
    runs = train_all(cfg, tmp_path, "oracle", logs.append, show_progress=False, ray_address="local")
    assert [r.name for r in runs] == ["ppo-sr-s0", "ppo-ewri-s0", "pirl-oracle-s0", "il-s0"]
    for run in runs:
        assert json.loads((run / "meta.json").read_text()).get("method") in (
            "ppo-sr", "ppo-ewri", "pirl", "il",
        )  # fmt: skip
    for run in runs[:3]:
        assert json.loads((run / "meta.json").read_text())["complete"], run
    assert (runs[3] / "tabnet.zip").is_file()
    done = [line.split(":")[0] for line in logs if "done in" in line]
    assert sorted(done) == sorted(r.name for r in runs)
    assert done.index("il-s0") > done.index("ppo-ewri-s0")
    again: list[str] = []
    train_all(cfg, tmp_path, "oracle", again.append, show_progress=False, ray_address="local")
    assert sum("already trained" in line for line in again) == 4


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.ray
def test_an_unreachable_address_is_a_clear_error(tmp_path):
    _ray()
    factory = functools.partial(ray_executor, f"127.0.0.1:{_closed_port()}")
    with pytest.raises(ConfigError, match="cannot reach a Ray cluster there"):
        evaluate(_plan(), tmp_path, executor_factory=factory)
    with pytest.raises(ConfigError, match="expected HOST:PORT"):
        evaluate(_plan(), tmp_path, executor_factory=functools.partial(ray_executor, "nowhere"))


def test_without_ray_the_error_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # makes `import ray` fail, as if not installed
    with pytest.raises(ConfigError, match=r"pip install 'pirl\[distributed\]'"):
        evaluate(_plan(), tmp_path, executor_factory=functools.partial(ray_executor, "local"))
    with pytest.raises(ConfigError, match="not installed"):
        train_all(
            RunConfig.from_yaml(ROOT / "configs" / "test.yaml"), tmp_path, "oracle", print,
            show_progress=False, ray_address="auto",
        )  # fmt: skip


CLI = """
import sys
sys.modules["ray"] = None  # Ray not installed
import pirl.cli
def pirl_(*args):
    sys.argv = ["pirl", "evaluate", "--methods", "random", "--sizes", "16", "--episodes", "1",
                *args]
    try:
        pirl.cli.main()
    except SystemExit as stop:
        print("exit", stop.code, file=sys.stderr, flush=True)
pirl_("--out", "local")
pirl_("--out", "none", "--ray-address", "local")
del sys.modules["ray"]  # installed again
pirl_("--out", "far", "--ray-address", "127.0.0.1:PORT")
"""


def test_the_cli_runs_locally_without_ray_and_says_what_is_wrong(tmp_path):
    code = CLI.replace("PORT", str(_closed_port()))
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert "Traceback" not in proc.stderr, proc.stderr
    assert (tmp_path / "local" / "summary.csv").is_file()  # no --ray-address: no Ray needed
    exits = [line for line in proc.stderr.splitlines() if line.startswith("exit")]
    assert exits == ["exit 0", "exit 2", "exit 2"], proc.stderr
    stderr = " ".join(proc.stderr.split())  # rich wraps long lines
    assert "install the extra: pip install 'pirl[distributed]'" in stderr
    assert "cannot reach a Ray cluster there" in stderr
    assert not list(tmp_path.glob("none/*")) and not list(tmp_path.glob("far/*"))
