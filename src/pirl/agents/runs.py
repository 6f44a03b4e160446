"""Training runs by name: ``pirl train``'s one run, and one run of a reproduction's plan.

``pirl train`` calls :func:`train_run`; ``pirl reproduce`` calls :func:`train_one` for each run
in turn, and a Ray worker calls the same function (:mod:`pirl.evaluate.executors`), so all
of them train with the same arguments. Both choose the trainer from the method's entry
(:mod:`pirl.agents.methods`). It lives with training, below evaluation, so neither of those
two modules imports the other.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from pirl.advice.registry import advisor_kind
from pirl.agents.loading import check_expert
from pirl.agents.methods import METHODS, TRAIN_IMITATION, trained_method
from pirl.agents.run_folder import RunFolder, lock_folder
from pirl.agents.settings import (
    check_fleet_training,
    check_resume,
    method_config,
    resolve_settings,
    resolved_config,
)
from pirl.config.choices import PareMode
from pirl.config.errors import ConfigError
from pirl.config.load import check_seed
from pirl.config.run import RunConfig
from pirl.config.world import VCPPConfig


def check_layouts(env: VCPPConfig, sizes: Iterable[tuple[int, int, int]], worlds: int = 1) -> None:
    """Before any folder is made (not by a worker, after): ``worlds`` worlds of each size must
    fit in memory (:func:`pirl.world.memory.check_memory`), and one scenario is drawn per
    size, so an impossible obstacle layout is refused."""
    import numpy as np

    from pirl.world.memory import check_memory
    from pirl.world.scenario import draw_scenario

    for size in sizes:
        check_memory(env.replace(size=tuple(size)), worlds)
        draw_scenario(env.replace(size=tuple(size)), np.random.default_rng(0))


def train_one(
    method: str,
    adv: str,
    seed: int,
    cfg: RunConfig,
    run: Path,
    resume: bool,
    show_progress: bool,
    pare: dict[str, Any] | None = None,
) -> None:
    """Train (or resume) run folder ``run`` of a reproduction: an imitation method from its
    expert's run next to it, any other method with PPO (``adv`` names an advised method's
    advisor; empty keeps the config's; ``pare`` overrides its other PARE settings, e.g.
    ``{"lam_cam": 4.0}``)."""
    from pirl.agents.imitation import train_il
    from pirl.agents.train import train

    entry = trained_method(method)
    if entry.training == TRAIN_IMITATION:
        expert = run.parent / entry.expert_folder(seed)
        train_il(cfg, expert, run, seed=seed, resume=run.exists())
    else:
        overrides = {**(pare or {}), **({"advisor": adv} if adv else {})}
        run_cfg = method_config(cfg, method)
        run_cfg = run_cfg.with_variant(overrides) if overrides else run_cfg
        train(method, run_cfg, run, seed=seed, resume=resume, show_progress=show_progress)


def train_run(
    method: str,
    out: Path,
    config: str | Path | None,
    default_config: str | Path,
    steps: int | None = None,
    seed: int | None = None,
    advisor: str | None = None,
    expert: Path | None = None,
    resume: bool = False,
    student: Path | None = None,
    site: Path | None = None,
    uavs: list[int] | None = None,
) -> Path:
    """``pirl train``: train (or resume) ``method`` into run folder ``out``; returns the model.

    ``site``: train on that site folder's map and seeded starts instead of generated worlds.
    ``uavs``: the fleet sizes to train with (``train.uavs``; one policy shared by every UAV).

    The settings come from :func:`~pirl.agents.settings.resolve_settings`: the preset (name
    or file) ``config``; without one, a resumed run's own config.yaml, else
    ``default_config``. ``seed`` defaults to 0, or to the resumed run's. ``steps`` and
    ``advisor`` override ``train.total_steps`` (after the method's own
    ``train.steps_by_method`` entry) and ``pare.advisor``. Everything that can be
    refused (an unknown method or advisor, a missing key, an impossible layout, a missing
    expert, a student without student mode) is refused before the run folder is made.
    """
    entry = trained_method(method, "--method")
    entry.check_options(expert=expert, advisor=advisor, student=student)
    if seed is not None:
        check_seed(seed)
    own = RunFolder(Path(out))
    if seed is None:
        seed = own.seed if resume else 0
    cfg = resolve_settings(
        config, default=default_config, run=own.path if resume else None, method=method,
        overrides={"train": {**({"total_steps": steps} if steps is not None else {}),
                             **({"uavs": list(uavs)} if uavs else {})},
                   "pare": {"advisor": advisor} if advisor is not None else {}},
        site=site,
    )  # fmt: skip
    check_fleet_training(cfg, entry.training == TRAIN_IMITATION)
    if entry.advised:
        advisor_kind(cfg.pare.advisor).check_key(cfg)
    check_layouts(cfg.env, [cfg.env.size], cfg.ppo.n_envs)
    if entry.training == TRAIN_IMITATION:
        if expert is None:
            raise ConfigError(
                f"--method {method} needs --expert runs/<a finished {entry.expert} run>"
            )
        check_expert(expert)  # before torch, SB3 and TabNet load (about 5 CPU-s)
        from pirl.agents.imitation import train_il

        return train_il(cfg, expert, out, seed=seed, resume=resume)
    if student is not None and (not entry.advised or cfg.pare.mode != PareMode.STUDENT):
        advised = " or ".join(m.name for m in METHODS.values() if m.advised)
        raise ConfigError(f"--student needs --method {advised} with pare.mode student")
    if resume:
        # A second writer, or a run this command does not describe, is refused before torch
        # and SB3 load (about 5 CPU-s), in train()'s order: the lock (train() takes it again
        # as a no-op), then the run's own files; train() checks again and says what it extends.
        if own.path.is_dir():
            lock_folder(own.path)
        check_resume(own, method, resolved_config(method, cfg), seed, log=lambda _line: None)
    from pirl.agents.train import train  # torch and SB3: only once everything is checked

    return train(method, cfg, out, seed=seed, resume=resume, student=None if resume else student)


__all__ = ["check_layouts", "train_one", "train_run"]
