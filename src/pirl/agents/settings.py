"""The one settings resolver: what every command's run reads, settled once.

:func:`resolve_settings` takes what a command was given (a preset or YAML file, a resumed run
folder, the method, section overrides from options, a site folder) and returns the one
:class:`~pirl.config.run.RunConfig` the rest of the run reads; nothing downstream settles
settings again.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from pirl.agents import checkpoint
from pirl.agents.methods import (
    METHODS,
    PPO_ARTIFACT,
    PPO_METHODS,
    TRAIN_PPO,
    Method,
    trained_method,
)
from pirl.agents.run_folder import RunFolder
from pirl.config.errors import ConfigError
from pirl.config.presets import load_preset
from pirl.config.run import RunConfig


def check_budgets(cfg: RunConfig) -> None:
    """Refuse in one line a ``train.steps_by_method`` or ``train.uavs_by_method`` name that is
    not a method trained in PPO steps (called before any folder is made)."""
    for key, why in (
        ("steps_by_method", "its budget is in the il section"),
        ("uavs_by_method", "it learns from its expert's one-UAV episodes"),
    ):
        for name in getattr(cfg.train, key):
            if trained_method(name, f"train.{key}").training != TRAIN_PPO:
                raise ConfigError(f"train.{key}: {name} is not trained in PPO steps ({why})")


def method_steps(cfg: RunConfig, method: str) -> int:
    """The steps ``method`` trains in ``cfg``: its ``train.steps_by_method`` entry, else
    ``train.total_steps``."""
    check_budgets(cfg)
    return cfg.train.steps_by_method.get(method, cfg.train.total_steps)


def method_config(cfg: RunConfig, method: str) -> RunConfig:
    """``cfg`` as ``method`` trains it: total_steps set to :func:`method_steps`, uavs to its
    ``train.uavs_by_method`` entry."""
    steps = method_steps(cfg, method)
    uavs = tuple(cfg.train.uavs_by_method.get(method, cfg.train.uavs))
    own = {
        **({"total_steps": steps} if steps != cfg.train.total_steps else {}),
        **({"uavs": list(uavs)} if uavs != tuple(cfg.train.uavs) else {}),
    }
    return cfg.with_overrides(train=own) if own else cfg


def resolve_settings(
    config: str | Path | None = None,
    *,
    default: str | Path | None = None,
    run: Path | None = None,
    method: str | None = None,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
    site: Path | None = None,
    option: str = "--config",
) -> RunConfig:
    """The settings of one command, in this order:

    1. the preset or file ``config``; without one, the run folder ``run``'s own config.yaml
       (a resumed run continues as it began), else ``default``, else the defaults;
    2. ``method``'s own budget, fleet sizes and env (``train.steps_by_method``,
       ``train.uavs_by_method``, what it trains on);
    3. ``overrides``, section by section (command-line options: ``{"train": {...}}``);
    4. ``site``: the site folder's map, size and ground cells in place of generated worlds.
    """
    own = RunFolder(Path(run)) if run is not None else None
    if config is None and own is not None and own.has_config:
        cfg = own.config
    else:
        cfg = load_preset(config if config is not None else default, option)
    if method is not None:
        cfg = method_config(cfg, method)
    changes = {k: dict(v) for k, v in (overrides or {}).items() if v}
    if changes:
        cfg = cfg.with_overrides(**changes)
    if site is not None:
        from pirl.world.seeable import with_site

        on_site = with_site(cfg.env, str(site))
        cfg = cfg.with_overrides(
            env={"site": on_site.site, "size": list(on_site.size),
                 "ground_cells": on_site.ground_cells},
        )  # fmt: skip
    return cfg


def check_fleet_training(cfg: RunConfig, imitation: bool) -> None:
    """Refuse fleets in training (``train.uavs`` other than [1]) for a method that learns by
    imitation: it learns from its expert's single-UAV episodes, not in an environment."""
    if imitation and tuple(cfg.train.uavs) != (1,):
        raise ConfigError(
            f"train.uavs={list(cfg.train.uavs)}: imitation learns from its expert's one-UAV "
            "episodes; train it with train.uavs [1] and fly it in a fleet with pirl evaluate "
            "--uavs"
        )


# -- a PPO run's settings: resolved_config, check_resume ------------------------------------
def ppo_method(name: str) -> Method:
    """The entry of a PPO method; one line naming the PPO methods for any other name."""
    entry = METHODS.get(name)
    if entry is None or entry.training != TRAIN_PPO:
        raise ConfigError(f"method {name!r}: PPO methods are {', '.join(PPO_METHODS)}")
    return entry


def resolved_config(method: str, cfg: RunConfig) -> RunConfig:
    """``cfg`` with the env the method trains and is judged on (its reward weights, the LLM
    weight for an advised method): what config.yaml records and evaluations rebuild. A
    chooser of candidate views trains on one UAV (fleets refused in one line)."""
    entry = ppo_method(method)
    if entry.views and tuple(cfg.train.uavs) != (1,):
        raise ConfigError(
            f"train.uavs={list(cfg.train.uavs)}: --method {method} chooses views for one UAV; "
            "train it with train.uavs [1]"
        )
    return replace(cfg, env=entry.trains_on(cfg.env))


# Settings a resumed run may change: how long it runs, how often it checkpoints and logs, what
# `pirl reproduce` does around it, how the physics simulator evaluates it and the memory limit
# of its worlds (env.max_memory_gb, a property of the machine). Everything else
# that the method uses (PARE and the advisor for PIRL only) must match the run's config.yaml.
RESUME_MAY_CHANGE = ("train.", "reproduce.", "physics.", "env.max_memory_gb")


def check_resume(run: RunFolder, method: str, cfg: RunConfig, seed: int, log: Any) -> RunConfig:
    """Before anything is built: the run in ``run`` must be the one this command describes.

    ``cfg`` is resolved (:func:`resolved_config`), as the run's own config.yaml is. A
    different method, seed or config value (advisor included) is refused with a message naming
    both values. A larger ``train.total_steps`` extends the run (said in one line). Returns the
    config to continue with: the run's own, with this command's ``train`` settings.
    """
    if not run.path.is_dir():
        raise ConfigError(f"--resume: run folder {run.path} does not exist")
    if not run.meta_file.is_file() or not run.has_config:
        if checkpoint.latest(run.checkpoints) is None and not (run.path / PPO_ARTIFACT).exists():
            return cfg  # stopped before the run was recorded: nothing to continue, start it
        raise ConfigError(f"--resume: {run.path} is not a run folder (no meta.json or config.yaml)")
    run.check_resumes(method, seed)
    saved = run.config
    old, new = _flat(saved.to_dict()), _flat(cfg.to_dict())
    unused = () if ppo_method(method).advised else ("pare.", "advisor.")
    free = RESUME_MAY_CHANGE + ("il.", *unused)
    for key in sorted(old.keys() | new.keys()):
        if key.startswith(free) or old.get(key) == new.get(key):
            continue
        raise ConfigError(
            f"--resume: {run.path} was trained with {key}={old.get(key)!r}; this command gives "
            f"{key}={new.get(key)!r}; resume takes the run's own settings (leave the option "
            "out) or choose a new --out"
        )
    # meta.json records the whole-rollout count that runs; compare like with like.
    before = int(run.meta.get("total_steps") or 0)
    after = whole_steps(saved, cfg.train.total_steps)
    if after > before:
        log(f"resume: extending {run.path} from {before:,} to {after:,} steps")
    elif after < before:
        raise ConfigError(
            f"--resume: {run.path} was set to train {before:,} steps; --steps {after:,} would "
            "cut it short (give at least that many, or leave --steps out)"
        )
    return replace(saved, train=cfg.train, reproduce=cfg.reproduce)


def _flat(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in data.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def whole_steps(cfg: RunConfig, steps: int) -> int:
    """``steps`` rounded up to whole rollouts (n_envs x n_steps): the steps PPO really runs."""
    rollout = cfg.ppo.n_envs * cfg.ppo.n_steps
    return -(-steps // rollout) * rollout


__all__ = [
    "RESUME_MAY_CHANGE",
    "check_budgets",
    "check_fleet_training",
    "check_resume",
    "method_config",
    "method_steps",
    "ppo_method",
    "resolve_settings",
    "resolved_config",
    "whole_steps",
]
