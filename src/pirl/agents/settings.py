"""The one settings resolver: what every command's run reads, settled once.

:func:`resolve_settings` takes what a command was given (a preset or YAML file, a resumed run
folder, the method, section overrides from options, a site folder) and returns the one
:class:`~pirl.config.run.RunConfig` the rest of the run reads; nothing downstream settles
settings again.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pirl.agents.methods import TRAIN_PPO, trained_method
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


__all__ = [
    "check_budgets",
    "check_fleet_training",
    "method_config",
    "method_steps",
    "resolve_settings",
]
