"""One training run of a plan, by name: a method, its advisor and a seed.

``pirl reproduce`` calls :func:`train_one` for each run in turn, and a Ray worker calls the
same function (:mod:`pirl.evaluate.distributed`), so both train with the same arguments. It
lives with training, below evaluation, so neither of those two modules imports the other.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pirl.config.run import RunConfig


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
    """Train (or resume) run folder ``run``: ``il`` from its ``ppo-ewri`` expert next to it,
    any other method with PPO (``adv`` names PIRL's advisor; empty keeps the config's;
    ``pare`` overrides PIRL's other PARE settings, e.g. ``{"lam_cam": 4.0}``)."""
    from pirl.agents.imitation import train_il
    from pirl.agents.train import train

    if method == "il":
        expert = run.parent / f"ppo-ewri-s{seed}"
        train_il(cfg, expert, run, seed=seed, resume=run.exists())
    else:
        overrides = {**(pare or {}), **({"advisor": adv} if adv else {})}
        run_cfg = cfg.with_overrides(pare=overrides) if overrides else cfg
        train(method, run_cfg, run, seed=seed, resume=resume, show_progress=show_progress)


__all__ = ["train_one"]
