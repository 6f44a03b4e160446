"""Imitation learning (the paper's IL baseline): TabNet trained on PPO-EWRI's choices.

Expert transitions are collected on the training world (15x15x3 by default) from a finished
PPO run acting deterministically; the features are the environment's observation vector read
as a table (one column per value); the label is the expert's action. A ``pytorch-tabnet``
``TabNetClassifier`` is fitted with a validation split and early stopping; its validation
accuracy is written to ``il_stats.json``.
"""

from __future__ import annotations

import contextlib
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import torch
from sb3_contrib import MaskablePPO

from pirl._atomic import replacing, write_json
from pirl.agents.methods import IL, IMITATION_ARTIFACT, method
from pirl.agents.run_folder import (
    RunFolder,
    git_commit,
    prepare_run_folder,
    train_seed_base,
)
from pirl.config.run import RunConfig
from pirl.env.sb3_vec import make_vec_env


def load_expert(expert_run: Path) -> Any:
    """The expert's PPO model, checked before an IL run folder is made: the run must exist,
    be a finished PPO run and hold a model that loads (:func:`check_expert`, then the
    weights)."""
    from pirl.agents.loading import PPOPolicy, check_expert

    expert = check_expert(expert_run)
    return PPOPolicy(expert.model_file(), expert.method, masked=expert.masked).model


def collect_expert(
    expert_run: Path | Any, cfg: RunConfig, transitions: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """(observations, actions) of the expert (a run folder or its loaded model) acting
    deterministically on the training world (on the valid actions, when it trained masked)."""
    model = load_expert(expert_run) if isinstance(expert_run, str | Path) else expert_run
    venv = make_vec_env(
        cfg.ppo.n_envs,
        seed=train_seed_base(seed) + 500,
        config=method(IL.expert).trains_on(cfg.env),
    )
    masked = isinstance(model, MaskablePPO)
    obs = venv.reset()
    xs, ys = [], []
    while sum(len(x) for x in xs) < transitions:
        if masked:
            actions, _ = model.predict(obs, deterministic=True, action_masks=venv.action_masks())
        else:
            actions, _ = model.predict(obs, deterministic=True)
        xs.append(obs.copy())
        ys.append(np.asarray(actions, dtype=np.int64))
        obs, _, _, _ = venv.step(actions)
    return np.concatenate(xs)[:transitions], np.concatenate(ys)[:transitions]


def train_il(cfg: RunConfig, expert: Path, out: Path, seed: int = 0, resume: bool = False) -> Path:
    """Collect expert data, fit TabNet, save it in run folder ``out``; returns the model file."""
    from pytorch_tabnet.tab_model import TabNetClassifier

    from pirl import _quiet

    _quiet.install()  # TabNet's "Device used" and "Best weights" warnings
    out, expert = Path(out), Path(expert)
    run = RunFolder(out)
    if resume:
        run.check_resumes(IL.name, seed)
    if resume and (out / IMITATION_ARTIFACT).is_file():
        return out / IMITATION_ARTIFACT
    expert_model = load_expert(expert)  # before the run folder exists
    if resume:
        out.mkdir(parents=True, exist_ok=True)
    else:
        prepare_run_folder(out, resume=False)
    torch.set_num_threads(cfg.ppo.torch_threads)
    run.write_config(cfg)
    il = cfg.il
    x, y = collect_expert(expert_model, cfg, il.expert_steps, seed)
    order = np.random.default_rng(seed).permutation(len(x))
    n_valid = max(1, int(len(x) * il.valid_fraction))
    valid, fit = order[:n_valid], order[n_valid:]
    x_fit, y_fit = x[fit], y[fit]
    known = np.isin(y[valid], np.unique(y_fit))  # TabNet cannot score classes it never saw
    x_valid, y_valid = x[valid][known], y[valid][known]

    # TabNet prints its early-stopping and save messages: they go to the run's tabnet.log.
    with open(out / "tabnet.log", "a") as log, contextlib.redirect_stdout(log):
        clf = TabNetClassifier(seed=seed, verbose=0, device_name="cpu")
        clf.fit(
            x_fit,
            y_fit,
            eval_set=[(x_valid, y_valid)],
            eval_name=["valid"],
            eval_metric=["accuracy"],
            max_epochs=il.max_epochs,
            patience=il.patience,
            batch_size=min(il.batch_size, len(x_fit)),
            virtual_batch_size=min(128, il.batch_size, len(x_fit)),
            drop_last=False,
        )
        accuracy = float((clf.predict(x_valid) == y_valid).mean()) if len(y_valid) else 0.0
        # TabNet zips a folder it names after the path given, adding ".zip" to it.
        with replacing(out / IMITATION_ARTIFACT, out / "tabnet.tmp.zip") as tmp:
            clf.save_model(str(tmp.with_suffix("")))
        shutil.rmtree(out / "tabnet.tmp", ignore_errors=True)
    stats = {
        "valid_accuracy": accuracy,
        "train_rows": len(x_fit),
        "valid_rows": len(x_valid),
        "best_epoch": int(getattr(clf, "best_epoch", -1)),
        "action_counts": np.bincount(y, minlength=12).tolist(),
        "expert": str(expert),
    }
    write_json(out / "il_stats.json", stats)
    run.write_meta(
        {
            "method": IL.name,
            "seed": seed,
            "git_commit": git_commit(),
            "expert": str(expert),
            "complete": True,
            "valid_accuracy": accuracy,
        },
    )
    return out / IMITATION_ARTIFACT
