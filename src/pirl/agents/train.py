"""Training PIRL, PPO-SR and PPO-EWRI with Stable-Baselines3 PPO, top to bottom.

``train()`` is what ``pirl train`` calls. Reading it in order follows one run:

0. The config is settled once (:mod:`pirl.agents.settings`): ``resolved_config`` (the
   method's env) and, on resume, ``check_resume`` against the run's own files.
1. PIRL only: the advice (teacher, probe, student), before any folder exists.
2. :func:`~pirl.agents.run_folder.prepare_run_folder` refuses to overwrite a run, or finds the
   checkpoint to resume; a new run's :class:`~pirl.agents.run_folder.RunFolder` records
   ``config.yaml`` and ``meta.json``.
3. :func:`build_env_stack` makes the batched worlds (``make_vec_env``), wraps them in PARE for
   an advised method (the advisor's reward term), then in SB3's ``VecMonitor``;
   :func:`build_ppo` makes the PPO model (MLP actor and critic on the flat observation).
4. ``model.learn`` runs with :class:`RunCallback`, which checkpoints at rollout boundaries,
   logs reward terms, coverage and PARE statistics to TensorBoard and ``episodes.csv``, and
   shows progress. Ctrl-C writes the last rollout-boundary state as a checkpoint. The final
   model and statistics are written; ``meta.json`` says the run is complete. One
   ``try``/``finally`` closes the envs and releases the folder on every way out.
"""

from __future__ import annotations

import csv
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecMonitor

from pirl._atomic import replacing
from pirl._torch import configure as configure_torch
from pirl.agents import checkpoint
from pirl.agents.methods import PPO_ARTIFACT
from pirl.agents.run_folder import (
    RunFolder,
    git_commit,
    lock_folder,
    prepare_run_folder,
    release_folder,
    train_seed_base,
)
from pirl.agents.schedules import learning_rate_of
from pirl.agents.settings import check_resume, ppo_method, resolved_config, whole_steps
from pirl.agents.stops import TrainingInterrupted, TrainingStopped
from pirl.config.choices import DatasetScope, PareMode
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig
from pirl.config.world import REWARD_TERMS, VCPPConfig
from pirl.env.sb3_vec import make_vec_env
from pirl.env.shaping import ShapingHooks
from pirl.pare.stats import AdvisorFailing
from pirl.progress import Progress

EPISODE_COLUMNS = (
    "timesteps", "world", "vcr", "be", "rvc", "overlap", "steps", "collisions", "battery_left",
    "camera_share", "mean_footprint",
)  # fmt: skip


def fleet_note(cfg: RunConfig) -> str:
    """What a run's label adds when it trained on fleets or sees teammates, so its rows never
    pass as a single UAV's training: ``" [fleets of 1, 2, 4 UAVs; sees 2 teammates]"``."""
    parts = []
    if cfg.train.uavs != (1,):
        parts.append(f"fleets of {', '.join(map(str, cfg.train.uavs))} UAVs")
    if cfg.env.obs_teammates:
        parts.append(f"sees {cfg.env.obs_teammates} teammates")
    return f" [{'; '.join(parts)}]" if parts else ""


def training_env(cfg: RunConfig) -> VCPPConfig:
    """The resolved env with ``train.camera_start``, ``surveyed_start``, ``obstacles`` and
    ``stall_guard`` applied: exploring starts, work out of sight, denser worlds and training
    with or without the guard are ways of training, so they stay out of the env that
    config.yaml records and evaluations build."""
    env = cfg.env.replace(
        start_camera=cfg.train.camera_start, start_surveyed=cfg.train.surveyed_start
    )
    if cfg.train.obstacles:
        low, high = cfg.train.obstacles
        env = env.replace(obstacles_min=int(low), obstacles_max=int(high))
    if cfg.train.stall_guard is not None:
        env = env.replace(stall_guard=int(cfg.train.stall_guard))
    return env


# -- 2. environments ------------------------------------------------------------------------
@dataclass
class EnvStack:
    """The wrapped training environment and handles on its layers."""

    env: VecMonitor
    venv: ShapingHooks
    """The batched env itself: a :class:`VCPPVecEnv`, or a fleet's (``train.uavs``)."""
    pare: Any | None


def build_env_stack(
    cfg: RunConfig, seed: int, advice: Any | None, source: str = "", views: bool = False
) -> EnvStack:
    """make_vec_env on the resolved config's training env -> (PARE when there is ``advice``,
    a :class:`~pirl.pare.bundle.AdviceBundle`) -> VecMonitor. ``views``: the candidate views'
    batch (:class:`~pirl.env.views_sb3.ViewsVecEnv`) instead, one choice a step."""
    if views:
        from pirl.env.views_sb3 import ViewsVecEnv

        venv = ViewsVecEnv(cfg.ppo.n_envs, training_env(cfg))
        venv.seed(train_seed_base(seed))
    elif cfg.train.uavs != (1,):
        from pirl.env.fleet import MixedFleetVecEnv

        venv = MixedFleetVecEnv(
            cfg.ppo.n_envs, training_env(cfg), cfg.train.uavs, seed=train_seed_base(seed)
        )
    else:
        venv = make_vec_env(cfg.ppo.n_envs, seed=train_seed_base(seed), config=training_env(cfg))
    pare = None
    inner = venv
    if advice is not None:
        from pirl.pare.sb3_vec import PAREVecEnv

        pare = PAREVecEnv.from_settings(
            venv, cfg.pare, advice, refit_every=cfg.ppo.n_steps, seed=seed, source=source
        )
        inner = pare
    return EnvStack(VecMonitor(inner), venv, pare)


# -- 3. the PPO model ------------------------------------------------------------------------
def pick_device(setting: str) -> str:
    if setting == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if setting == "cuda" and not torch.cuda.is_available():
        raise ConfigError("ppo.device='cuda' but no CUDA device is available")
    return setting


def build_ppo(env: VecMonitor, cfg: RunConfig, seed: int, tb_dir: Path | None) -> PPO:
    """SB3 PPO with separate MLPs for actor and critic (the observation is a flat vector of
    local maps, a coarse global map and scalars, so an MLP reads it directly).

    With ``ppo.action_masking`` it is sb3-contrib's ``MaskablePPO``, which asks the env stack
    for ``action_masks()`` at every step (PARE and VecMonitor pass the call through)."""
    configure_torch()
    p = cfg.ppo
    learning_rate = learning_rate_of(p)
    algo = PPO
    if p.action_masking:
        from sb3_contrib import MaskablePPO

        algo = MaskablePPO
    return algo(
        "MlpPolicy",
        env,
        learning_rate=learning_rate,
        n_steps=p.n_steps,
        batch_size=p.batch_size,
        n_epochs=p.n_epochs,
        gamma=p.gamma,
        gae_lambda=p.gae_lambda,
        clip_range=p.clip_range,
        ent_coef=p.ent_coef,
        vf_coef=p.vf_coef,
        max_grad_norm=p.max_grad_norm,
        policy_kwargs={"net_arch": {"pi": list(p.net_arch), "vf": list(p.net_arch)}},
        tensorboard_log=str(tb_dir) if tb_dir is not None else None,
        seed=seed,
        device=pick_device(p.device),
        verbose=0,
    )


# -- 4. the callback -------------------------------------------------------------------------
class RunCallback(BaseCallback):
    """Checkpoints, TensorBoard scalars, episodes.csv and progress for one run."""

    def __init__(
        self, out: Path, stack: EnvStack, cfg: RunConfig, total: int, progress: Any, csv_rows: int
    ) -> None:
        super().__init__()
        self.out, self.stack, self.cfg, self.total = out, stack, cfg, total
        self.progress = progress
        self.snapshot: dict | None = None
        self.next_checkpoint = 0
        self.csv_path = RunFolder(out).episodes_file
        self.csv_rows = csv_rows
        self._terms_sum = np.zeros(len(REWARD_TERMS))
        self._terms_n = 0
        self._episodes: list[dict[str, float]] = []
        self._recent_vcr: list[float] = []

    def _on_training_start(self) -> None:
        every = self.cfg.train.checkpoint_every
        self.next_checkpoint = (self.num_timesteps // every + 1) * every
        _truncate_csv(self.csv_path, self.csv_rows)
        new = not self.csv_path.exists()
        self._csv_file = open(self.csv_path, "a", newline="")  # noqa: SIM115 - closed at end
        self._csv = csv.writer(self._csv_file)
        if new:
            self._csv.writerow(EPISODE_COLUMNS)

    def _on_rollout_start(self) -> None:
        # A rollout boundary: the state here resumes exactly. Keep it for Ctrl-C.
        s = self.stack
        self.snapshot = checkpoint.capture(self.model, s.env, s.venv, s.pare)
        self.snapshot["csv_rows"] = self.csv_rows
        if self.num_timesteps >= self.next_checkpoint:
            self.save_snapshot()
            every = self.cfg.train.checkpoint_every
            self.next_checkpoint = (self.num_timesteps // every + 1) * every

    def save_snapshot(self) -> Path | None:
        if self.snapshot is None:
            return None
        self._csv_file.flush()
        return checkpoint.write(self.snapshot, self.model, self.out / "checkpoints")

    def _on_step(self) -> bool:
        snap = self.stack.venv.step_snapshot
        self._terms_sum += snap.terms.sum(axis=0)
        self._terms_n += snap.terms.shape[0]
        dones, infos = self.locals["dones"], self.locals["infos"]
        for e in np.flatnonzero(dones):
            if not infos[e].get("fleet_active", True):
                continue  # a fleet's UAV parked since it left: its episode was logged then
            m = infos[e]["episode_metrics"]
            self._csv.writerow([self.num_timesteps, int(e)] + [m[c] for c in EPISODE_COLUMNS[2:]])
            self.csv_rows += 1
            self._episodes.append(m)
            self._recent_vcr = (self._recent_vcr + [m["vcr"]])[-50:]
        vcr, calls = self.recent_vcr(), self.advisor_calls()
        info = [f"VCR(recent) {vcr:.2f}"] if vcr is not None else []
        self.progress.update(self.num_timesteps, info="  ".join(info + ([calls] if calls else [])))
        return True

    def _on_rollout_end(self) -> None:
        log = self.logger.record
        if self._terms_n:
            for name, value in zip(REWARD_TERMS, self._terms_sum / self._terms_n, strict=True):
                log(f"reward_terms/{name}", float(value))
        if self._episodes:
            for key in ("vcr", "be", "rvc", "steps", "collisions", "camera_share"):
                log(f"episode/{key}", float(np.mean([m[key] for m in self._episodes])))
        pare = self.stack.pare
        if pare is not None:
            for key, value in pare.stats.as_dict().items():
                if isinstance(value, int | float):
                    log(f"pare/{key}", float(value))
        self._terms_sum[:] = 0
        self._terms_n = 0
        self._episodes = []
        self._csv_file.flush()

    def _on_training_end(self) -> None:
        self._csv_file.close()

    def recent_vcr(self) -> float | None:
        return float(np.mean(self._recent_vcr)) if self._recent_vcr else None

    def advisor_calls(self) -> str | None:
        """Advice health for the progress line: answered and failed, not calls sent."""
        pare = self.stack.pare
        if pare is None:
            return None
        st = pare.stats
        failed = st.answers_failed + st.answers_unparseable
        text = f"advisor answered {st.answers_ok:,} failed {failed:,}"
        if pare.mode == PareMode.STUDENT:
            text += f"  student agreement {st.student_agreement:.2f}"
        return text


def _truncate_csv(path: Path, rows: int) -> None:
    """Drop episode rows written after the checkpoint being resumed (line endings kept as
    written: newline="" reads and writes them untouched)."""
    if not path.exists():
        return
    with open(path, newline="") as fh:
        lines = fh.read().splitlines(keepends=True)
    with open(path, "w", newline="") as fh:
        fh.write("".join(lines[: rows + 1]))


# -- the whole run ---------------------------------------------------------------------------
def train(
    method: str,
    cfg: RunConfig,
    out: Path,
    seed: int = 0,
    resume: bool = False,
    advisor: Any | None = None,
    show_progress: bool = True,
    student: Path | None = None,
) -> Path:
    """Train ``method`` with ``cfg`` into run folder ``out``; returns the final model path.

    ``advisor`` (pirl only) defaults to the one the config names; it is probed before the run
    folder exists. ``student`` (pirl, student mode): a distilled advisor to start from.
    Interrupting with Ctrl-C writes a checkpoint; ``resume=True`` continues from the latest
    one; an advisor that keeps failing stops the run the same way (:class:`TrainingStopped`).
    """
    from pirl import _quiet

    _quiet.install()
    run = RunFolder(Path(out))
    log = print if show_progress else (lambda _m: None)
    entry = ppo_method(method)  # refused before the disk is touched
    # The one place the config is settled: the method's env, or a resumed run's own config.
    cfg = resolved_config(method, cfg)
    if resume:
        if run.path.is_dir():
            lock_folder(run.path)  # first: a second writer is refused before it reads anything
        cfg = check_resume(run, method, cfg, seed, log)
        done = run.finished_steps()
        if done is not None and done >= cfg.train.total_steps:
            log(f"{out} is already complete ({done:,} steps); give a larger --steps to extend it")
            release_folder(run.path)
            return run.path / entry.artifact
    total = whole_steps(cfg, cfg.train.total_steps)
    if total != cfg.train.total_steps:
        log(
            f"note: PPO trains whole rollouts of n_envs x n_steps = "
            f"{cfg.ppo.n_envs * cfg.ppo.n_steps:,} steps, so {cfg.train.total_steps:,} steps "
            f"become {total:,}"
        )

    # 1. the advice (PIRL): built and probed before the folder exists, so a dead server or a
    #    wrong student leaves nothing behind.
    advice = None
    if entry.advised:
        from pirl.agents.pirl_advice import build_pirl_advice

        advice = build_pirl_advice(
            cfg, advisor, student, probe=True, seed=seed, log=_warn, run=str(run.path.resolve())
        )
        advisor = advice.advisor

    # 2. the run folder: new (config.yaml and meta.json record the run) or resumed.
    found = prepare_run_folder(run.path, resume, log)
    own = cfg.pare.student_dataset_scope == DatasetScope.RUN and student is None
    if found is None and advice is not None and own:
        from pirl.agents.teacher_phase import take_head_start

        advice.drop_own_answers()  # an earlier run of this folder must not teach this one
        # Its head start: the teacher phase's first answers, fixed before this run trains.
        take_head_start(cfg, advice, str(run.path.resolve()), log)
    meta = {
        "method": method,
        "label": (advice.label if advice is not None else entry.label) + fleet_note(cfg),
        "seed": seed,
        "git_commit": git_commit(),
        "advisor": getattr(advisor, "label", None),
        "complete": False,
        "total_steps": total,
    }
    if student is not None:
        meta["student_from"] = str(student)
    if found is None:
        run.write_config(cfg)
        run.write_meta(meta)

    # 3. the env stack and the model (restored from the checkpoint when resuming).
    torch.set_num_threads(cfg.ppo.torch_threads)
    stack = build_env_stack(cfg, seed, advice, str(run.path.resolve()), entry.views)
    model = build_ppo(stack.env, cfg, seed, run.tensorboard)
    csv_rows = 0
    if found is not None:
        checkpoint.restore(found[1], model, stack.env, stack.venv, stack.pare)
        csv_rows = found[1].get("csv_rows", 0)
    progress = Progress(
        method,
        cfg.train.total_steps,
        every_s=cfg.train.log_every_s,
        enabled=show_progress,
        rate_unit="fps",
    )
    callback = RunCallback(run.path, stack, cfg, cfg.train.total_steps, progress, csv_rows)

    # 4. learn; every way out closes the envs and gives the folder's lock back.
    try:
        remaining = max(0, cfg.train.total_steps - model.num_timesteps)
        if remaining:
            model.learn(
                total_timesteps=remaining,
                callback=callback,
                reset_num_timesteps=found is None,
                tb_log_name="ppo",
            )
        progress.close()
        return _finish(run, model, stack, advisor, cfg, meta)
    except KeyboardInterrupt:
        progress.close()
        raise TrainingInterrupted(callback.save_snapshot()) from None
    except AdvisorFailing as failing:
        progress.close()
        saved = callback.save_snapshot()
        if stack.pare is not None:
            run.write_advisor_stats(_advisor_stats(stack.pare, advisor))
        raise TrainingStopped(str(failing), saved) from None
    finally:
        stack.env.close()
        release_folder(run.path)  # the caller may resume it, in this process or another


def _finish(
    run: RunFolder, model: Any, stack: EnvStack, advisor: Any, cfg: RunConfig, meta: dict
) -> Path:
    """Write the final model (atomically), the advisor's statistics, and mark the run
    complete; a mostly unshaped PIRL run is PPO-EWRI under PIRL's name, so it says so."""
    final = run.path / PPO_ARTIFACT
    with replacing(final, run.path / "model.tmp.zip") as tmp:  # SB3 adds ".zip" to other names
        checkpoint.save_model(model, tmp)
    if stack.pare is not None:
        from pirl.agents.pirl_advice import unshaped_warning

        stats = _advisor_stats(stack.pare, advisor)
        run.write_advisor_stats(stats)
        warning = unshaped_warning(
            stats, cfg.pare.min_shaped, cfg.pare.gate()[0], cfg.pare.student_min_heldout
        )
        if warning:
            _warn(warning)
    run.write_meta({**meta, "complete": True, "timesteps": int(model.num_timesteps)})
    return final


def _warn(line: str) -> None:
    """Warnings go to stderr, with or without the progress display."""
    print(line, file=sys.stderr, flush=True)


def _advisor_stats(pare: Any, advisor: Any) -> dict[str, Any]:
    stats = pare.settle().as_dict()  # answers still in flight at the end are counted too
    stats["advisor"] = getattr(advisor, "label", str(advisor))
    for attr in ("hits", "misses", "calls", "tokens"):
        value = getattr(advisor, attr, None)
        if isinstance(value, int | float):
            stats[f"advisor_{attr}"] = value
    return stats
