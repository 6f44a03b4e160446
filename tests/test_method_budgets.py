"""Each method's own training budget (``train.steps_by_method``): the runs train that many
steps, the plan and the report say so, and a bad name is one line before any folder."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pirl.agents.runs import train_one, train_run
from pirl.agents.settings import method_steps
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig
from pirl.reproduce.plan import check_reproduce, make_plan, plan_runs, steps_text

ROOT = Path(__file__).resolve().parents[1]
TEST = ROOT / "configs" / "test.yaml"


def _trained_steps(run: Path) -> int:
    return json.loads((run / "meta.json").read_text())["total_steps"]


def test_a_method_with_its_own_budget_trains_it_and_the_others_keep_theirs(tmp_path):
    cfg = RunConfig.from_yaml(TEST).with_overrides(train={"steps_by_method": {"ppo-ewri": 1024}})
    assert method_steps(cfg, "ppo-ewri") == 1024 and method_steps(cfg, "ppo-sr") == 512
    train_one("ppo-ewri", "", 0, cfg, tmp_path / "ewri", False, False)
    train_one("ppo-sr", "", 0, cfg, tmp_path / "sr", False, False)
    assert _trained_steps(tmp_path / "ewri") == 1024
    assert _trained_steps(tmp_path / "sr") == 512
    # The run's own config says what it trained, so a resume or a reader sees the same budget.
    own = yaml.safe_load((tmp_path / "ewri" / "config.yaml").read_text())
    assert own["train"]["total_steps"] == 1024
    # pirl train reads the same entry; --steps still decides when given.
    preset = tmp_path / "budgets.yaml"
    preset.write_text(yaml.safe_dump(cfg.to_dict()))
    train_run("ppo-ewri", tmp_path / "cli", preset, TEST)
    assert _trained_steps(tmp_path / "cli") == 1024
    train_run("ppo-ewri", tmp_path / "cli-steps", preset, TEST, steps=256)
    assert _trained_steps(tmp_path / "cli-steps") == 256


def test_the_plan_and_the_report_name_each_budget(tmp_path):
    study = RunConfig.from_yaml(ROOT / "configs" / "study-agents.yaml")
    own = study.with_overrides(train={"total_steps": 409600,
                                      "steps_by_method": {"ppo-ewri": 1638400}})  # fmt: skip
    assert steps_text(own) == "409,600 steps (PPO-EWRI 1,638,400)"
    assert steps_text(study.with_overrides(train={"steps_by_method": {}})) == (
        f"{study.train.total_steps:,} steps"
    )

    def describe_plan(cfg: RunConfig) -> list[str]:
        return make_plan(check_reproduce(cfg, "oracle", 2), tmp_path).describe()

    line = next(x for x in describe_plan(own) if "training runs" in x)
    assert "409,600 steps (PPO-EWRI 1,638,400)" in line
    # The estimate counts PPO-EWRI's longer runs.
    same = study.with_overrides(train={"total_steps": 409600, "steps_by_method": {}})
    minutes = [
        float(
            next(x for x in describe_plan(c) if "training runs" in x)
            .split("about ")[1]
            .split(" min")[0]
        )  # fmt: skip
        for c in (same, own)
    ]
    assert minutes[1] > minutes[0]


@pytest.mark.parametrize(
    ("budgets", "message"),
    [
        ({"ppo-ewri": 0}, "train.steps_by_method={'ppo-ewri': 0}: ppo-ewri: must be > 0"),
        ({"ppo-ewrii": 5}, "train.steps_by_method: 'ppo-ewrii' is not trained"),
        ({"il": 5}, "train.steps_by_method: il is not trained in PPO steps"),
        ({"boustrophedon": 5}, "train.steps_by_method: 'boustrophedon' is not trained"),
    ],
)
def test_a_bad_budget_is_refused_before_any_training(budgets, message):
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("{", r"\{")):
        cfg = RunConfig.from_yaml(TEST).with_overrides(train={"steps_by_method": budgets})
        plan_runs(cfg, "oracle")


def test_pirl_train_refuses_a_bad_budget_in_one_line_and_makes_no_folder(tmp_path):
    preset = tmp_path / "bad.yaml"
    data = RunConfig.from_yaml(TEST).to_dict()
    data["train"]["steps_by_method"] = {"ppo-ewrii": 1024}
    preset.write_text(yaml.safe_dump(data))
    proc = subprocess.run(
        [sys.executable, "-m", "pirl", "train", "--method", "ppo-sr", "--config", str(preset),
         "--out", str(tmp_path / "run")],  # fmt: skip
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 2
    assert "train.steps_by_method: 'ppo-ewrii' is not trained" in proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "run").exists()


def test_a_method_with_its_own_fleet_sizes_trains_on_them_and_imitation_is_refused(tmp_path):
    """``train.uavs_by_method``: the named method's run trains on fleets (its config.yaml and
    its label say so), the others keep ``train.uavs``; naming imitation is refused in one line."""
    from pirl.agents.settings import method_config

    cfg = RunConfig.from_yaml(TEST).with_overrides(train={"uavs_by_method": {"ppo-ewri": [1, 2]}})
    assert method_config(cfg, "ppo-ewri").train.uavs == (1, 2)
    assert method_config(cfg, "ppo-sr").train.uavs == (1,)
    train_one("ppo-ewri", "", 0, cfg, tmp_path / "ewri", False, False)
    own = yaml.safe_load((tmp_path / "ewri" / "config.yaml").read_text())
    assert own["train"]["uavs"] == [1, 2]
    meta = json.loads((tmp_path / "ewri" / "meta.json").read_text())
    assert meta["label"] == "PPO-EWRI [fleets of 1, 2 UAVs]"
    bad = cfg.with_overrides(train={"uavs_by_method": {"il": [1, 2]}})
    with pytest.raises(ConfigError, match=r"^train.uavs_by_method: il is not trained in PPO"):
        plan_runs(bad, "oracle")
