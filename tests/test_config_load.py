"""pirl.config.load: one mechanism and one message format for every settings section."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest
import yaml

from pirl.config.errors import ConfigError
from pirl.config.load import Settings
from pirl.config.mission import MissionSettings
from pirl.config.physics import PhysicsConfig
from pirl.config.run import (
    AdvisorSettings,
    ILSettings,
    PareSettings,
    PPOSettings,
    ReproduceSettings,
    RunConfig,
    TrainSettings,
)
from pirl.config.world import VCPPConfig

SECTIONS = (
    VCPPConfig, PPOSettings, TrainSettings, PareSettings, AdvisorSettings, ILSettings,
    ReproduceSettings, PhysicsConfig, MissionSettings,
)  # fmt: skip
CONFIG = Path(__file__).resolve().parents[1] / "src" / "pirl" / "config"
PRESETS = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.yaml"))


def test_run_config_holds_every_section_under_its_name():
    names = [f.name for f in dataclasses.fields(RunConfig)]
    assert names == [s.section for s in SECTIONS]
    for f, section in zip(dataclasses.fields(RunConfig), SECTIONS, strict=True):
        assert isinstance(getattr(RunConfig(), f.name), section)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        # A typo: the same words in every section, with a close match.
        ({"env": {"wind_prb": 0.2}}, "unknown setting 'wind_prb' in section 'env' (did you mean"),
        ({"ppo": {"n_env": 4}}, "unknown setting 'n_env' in section 'ppo' (did you mean"),
        ({"physics": {"wind": 1}}, "unknown setting 'wind' in section 'physics'"),
        ({"trian": {}}, "unknown setting 'trian' (did you mean 'train'?)"),
        # A wrong type: section.key=value: expected ...
        ({"env": {"wind_prob": "0.1"}}, "env.wind_prob='0.1': expected a number"),
        ({"ppo": {"n_envs": 2.5}}, "ppo.n_envs=2.5: expected an integer"),
        ({"train": {"total_steps": True}}, "train.total_steps=True: expected an integer"),
        ({"pare": {"cache": "yes"}}, "pare.cache='yes': expected true or false"),
        ({"physics": {"wind_mean": [1, 2]}}, "physics.wind_mean=[1, 2]: expected a list of 3"),
        ({"env": {"size": "15x15x3"}}, "env.size='15x15x3': expected a list of 3 integers"),
        ({"reproduce": {"seeds": [0, "a"]}}, "reproduce.seeds=[0, 'a']: expected a list of int"),
        ({"physics": {"camera_energy": "x"}}, "expected a number or null"),
        ({"ppo": 3}, "section 'ppo' must be a mapping"),
        # An impossible value: section.key=value: rule
        ({"env": {"wind_prob": 1.5}}, "env.wind_prob=1.5: allowed range is [0, 1]"),
        ({"ppo": {"n_envs": 0}}, "ppo.n_envs=0: must be > 0"),
        ({"il": {"valid_fraction": 1.0}}, "il.valid_fraction=1.0: must be in (0, 1)"),
        ({"physics": {"cell_size_m": 0}}, "physics.cell_size_m=0: must be a positive number"),
        ({"reproduce": {"seeds": []}}, "reproduce.seeds=(): must be a non-empty list"),
        ({"pare": {"mode": "later"}}, "pare.mode='later': allowed values are student, sync"),
    ],
)
def test_one_message_format_for_every_section(data, message):
    with pytest.raises(ConfigError) as err:
        RunConfig.from_dict(data)
    assert message in str(err.value)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("section", SECTIONS)
def test_each_section_loads_alone_with_the_same_checks(section):
    assert section.from_dict(None) == section() == section.from_dict({})
    assert section.from_dict(section().to_dict()) == section()
    with pytest.raises(ConfigError, match=f"in section '{section.section}'"):
        section.from_dict({"no_such_key": 1})
    with pytest.raises(ConfigError, match="in section"):
        section().replace(no_such_key=1)


def test_lists_become_tuples_and_numbers_keep_their_type():
    cfg = RunConfig.from_dict(
        {
            "env": {"size": [20, 10, 3], "ewri_ranges": [[0, 1]] * 8, "battery_capacity": 50},
            "ppo": {"net_arch": [64, 64]},
            "reproduce": {"sizes": [30, "40x25"], "pirl_variants": [{"advisor": "oracle"}]},
        }
    )
    assert cfg.env.size == (20, 10, 3) and cfg.env.ewri_ranges == ((0, 1),) * 8
    assert cfg.env.battery_capacity == 50 and isinstance(cfg.env.battery_capacity, int)
    assert cfg.ppo.net_arch == (64, 64)
    assert cfg.reproduce.sizes == (30, "40x25")
    assert cfg.reproduce.pirl_variants == ({"advisor": "oracle"},)


@pytest.mark.parametrize("preset", PRESETS, ids=lambda p: p.stem)
def test_every_preset_round_trips_through_yaml(preset, tmp_path):
    cfg = RunConfig.from_yaml(preset)
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))
    assert RunConfig.from_yaml(path) == cfg
    assert yaml.safe_load(path.read_text()) == cfg.to_dict()


def test_with_overrides_and_replace_check_like_loading():
    cfg = RunConfig().with_overrides(train={"total_steps": 10}, env={"size": [30, 30, 3]})
    assert cfg.train.total_steps == 10 and cfg.env.size == (30, 30, 3)
    with pytest.raises(ConfigError, match="train.total_steps=0"):
        RunConfig().with_overrides(train={"total_steps": 0})
    with pytest.raises(ConfigError, match="env.start_zoom"):
        VCPPConfig().replace(start_zoom=1.05)
    with pytest.raises(ConfigError, match="ppo.device='tpu'"):
        dataclasses.replace(PPOSettings(), device="tpu")


def test_nested_sections_may_be_given_as_mappings():
    cfg = RunConfig(env={"size": [30, 30, 3]}, physics=None)  # type: ignore[arg-type]
    assert cfg.env == VCPPConfig(size=(30, 30, 3)) and cfg.physics == PhysicsConfig()


def test_every_setting_has_a_docstring():
    """A field's docstring is the user's documentation of the key (config as code)."""
    missing = []
    for path in sorted(CONFIG.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ClassDef):
                continue
            body = node.body
            for k, stmt in enumerate(body):
                if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name):
                    nxt = body[k + 1] if k + 1 < len(body) else None
                    documented = isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                    if not documented and stmt.target.id != "section":
                        missing.append(f"{path.name}:{node.name}.{stmt.target.id}")
    assert not missing, missing


def test_every_section_derives_from_the_one_mechanism():
    for section in (*SECTIONS, RunConfig):
        assert issubclass(section, Settings)
        assert section.__dataclass_params__.frozen  # type: ignore[attr-defined]
