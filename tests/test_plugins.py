"""Registries of advisors and methods, and advisor plugins declared by entry point.

The example plugin (tests/plugins/pirl_example_advisor) is installed for real (pip, no
network) into a folder of its own, then used by ``pirl advise`` and ``pirl train --method
pirl`` as subprocesses, with no change to src/.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pirl.advice import registry
from pirl.advice.factory import make_advisor
from pirl.advice.registry import AdvisorKind, advisor_kind, advisor_names
from pirl.agents.methods import METHODS, method, report_order, trained_method
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig

ROOT = Path(__file__).resolve().parents[1]
PLUGIN = Path(__file__).parent / "plugins" / "pirl_example_advisor"
TEST_CFG = ROOT / "configs" / "test.yaml"


def _dist_info(folder: Path, name: str, entry_points: str) -> None:
    """A distribution's metadata as an installer writes it (what importlib.metadata reads)."""
    info = folder / f"{name}-0.1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1.0\n")
    (info / "entry_points.txt").write_text(entry_points)


@pytest.fixture
def plugins(tmp_path, monkeypatch):
    """A folder on sys.path for plugin metadata; the registry forgets loaded plugins after."""
    monkeypatch.syspath_prepend(str(tmp_path))
    registry._load_plugin.cache_clear()
    yield tmp_path
    registry._load_plugin.cache_clear()


def test_an_unknown_advisor_is_one_line_naming_the_known_ones():
    with pytest.raises(ConfigError, match=r"unknown advisor 'gpt9' \(known: local, openai, oracle"):
        advisor_kind("gpt9")


def test_the_oracle_entry_keeps_cache_and_budget_out():
    cfg = RunConfig().with_overrides(pare={"cache": True, "budget_calls": 3})
    advisor = make_advisor("oracle", cfg)
    assert type(advisor).__name__ == "OracleAdvisor"  # no cache, no budget in front
    assert not advisor_kind("oracle").llm and advisor_kind("local").llm


def test_a_broken_plugin_is_one_line_naming_it(plugins):
    _dist_info(plugins, "pirl_broken", "[pirl.advisors]\nbroken = pirl_no_such_module:make\n")
    assert "broken" in advisor_names()
    with pytest.raises(ConfigError) as caught:
        advisor_kind("broken")
    line = str(caught.value)
    assert "\n" not in line
    assert "advisor plugin 'broken' (pirl_no_such_module:make) cannot be loaded" in line


def test_a_plugin_may_declare_a_whole_entry(plugins):
    (plugins / "pirl_kind_plugin.py").write_text(
        "from pirl.advice.registry import AdvisorKind\n"
        "from pirl.advice.oracle import OracleAdvisor\n"
        "KIND = AdvisorKind('any', lambda cfg: OracleAdvisor(), llm=False, cacheable=False,\n"
        "                   batch_size=lambda cfg: 7)\n"
    )
    _dist_info(plugins, "pirl_kind_plugin", "[pirl.advisors]\nplanner = pirl_kind_plugin:KIND\n")
    kind = advisor_kind("planner")
    assert isinstance(kind, AdvisorKind) and kind.name == "planner" and not kind.llm
    assert kind.batch_size(RunConfig()) == 7
    assert type(make_advisor("planner", RunConfig())).__name__ == "OracleAdvisor"


def test_methods_derive_folders_order_and_checks():
    il = method("il")
    assert il.expert_folder(3) == "ppo-ewri-s3" and il.artifact == "tabnet.zip"
    keys = ["random", "pirl-oracle", "pirl", "il", "boustrophedon", "ppo-sr"]
    assert sorted(keys, key=report_order) == [
        "ppo-sr", "il", "pirl", "pirl-oracle", "boustrophedon", "random",
    ]  # fmt: skip
    assert list(METHODS)[:2] == ["ppo-sr", "ppo-ewri"]
    with pytest.raises(ConfigError, match="'random' is not trained"):
        trained_method("random", "reproduce.methods")
    with pytest.raises(ConfigError, match=r"unknown method 'ppo' \(known: ppo-sr"):
        method("ppo")


def test_a_bad_advisor_in_a_profile_is_refused_before_training(tmp_path):
    from pirl.reproduce.pipeline import check_reproduce

    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(
        reproduce={"pirl_variants": [{"advisor": "gpt9"}]}
    )
    with pytest.raises(ConfigError, match="unknown advisor 'gpt9'"):
        check_reproduce(cfg, "oracle")
    assert not any(tmp_path.iterdir())


def test_train_run_refuses_before_it_makes_a_folder(tmp_path):
    from pirl.agents.runs import train_run

    out = tmp_path / "run"
    with pytest.raises(ConfigError, match="--method il needs --expert"):
        train_run("il", out, TEST_CFG, TEST_CFG)
    with pytest.raises(ConfigError, match="--student is not an option of --method ppo-sr"):
        train_run("ppo-sr", out, TEST_CFG, TEST_CFG, student=tmp_path)
    with pytest.raises(ConfigError, match="--student needs --method pirl with pare.mode student"):
        train_run("pirl", out, TEST_CFG, TEST_CFG, student=tmp_path)
    with pytest.raises(ConfigError, match="unknown advisor 'gpt9'"):
        train_run("pirl", out, TEST_CFG, TEST_CFG, advisor="gpt9")
    with pytest.raises(ConfigError, match="'random' is not trained"):
        train_run("random", out, TEST_CFG, TEST_CFG)
    assert not out.exists()


def _install(plugin: Path, target: Path, scratch: Path) -> None:
    """pip-install a plugin folder into ``target`` offline (its build files go to a copy)."""
    source = scratch / plugin.name
    shutil.copytree(plugin, source)
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
         "--no-index", "--target", str(target), str(source)],
        check=True, capture_output=True, text=True, timeout=120,
    )  # fmt: skip


def test_an_installed_plugin_answers_pirl_advise_and_trains_pirl(tmp_path):
    site = tmp_path / "site"
    _install(PLUGIN, site, tmp_path)
    assert (site / "pirl_example_advisor").is_dir()
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(site), str(ROOT / "src")]),
        "PIRL_CACHE_DIR": str(tmp_path / "cache"),
    }

    def pirl(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "pirl", *args], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=300)  # fmt: skip

    advised = pirl("advise", "--advisor", "example", "--config", str(TEST_CFG), "--no-cache")
    assert advised.returncode == 0, advised.stderr
    assert "answer from example:steady" in advised.stdout
    assert "parsed:      Recommendation(" in advised.stdout
    # Scored against the oracle like any advisor: a steady answer carries no state information.
    scored = pirl(
        "advise", "--advisor", "example", "--config", str(TEST_CFG), "--no-cache",
        "--score", "40", "--out", str(tmp_path / "score.json"), "--price-in", "1",
    )  # fmt: skip
    assert scored.returncode == 0, scored.stderr
    score = json.loads((tmp_path / "score.json").read_text())
    assert score["parse_rate"] == 1.0 and score["states"] == 40
    assert abs(score["kappa_move"]) < 0.2 and "price of one PIRL run" in scored.stdout
    run = tmp_path / "run"
    trained = pirl(
        "train", "--method", "pirl", "--advisor", "example", "--config", str(TEST_CFG),
        "--steps", "128", "--out", str(run),
    )  # fmt: skip
    assert trained.returncode == 0, trained.stderr
    stats = json.loads((run / "advisor_stats.json").read_text())
    assert stats["advisor"] == "example:steady" and stats["answers_ok"] > 0
    assert stats["answers_failed"] == stats["answers_unparseable"] == 0
    meta = json.loads((run / "meta.json").read_text())
    assert meta["complete"] and "example:steady" in meta["label"]
    unknown = pirl("advise", "--advisor", "nope")
    assert unknown.returncode == 2 and "example" in unknown.stderr
    assert "Traceback" not in unknown.stderr
