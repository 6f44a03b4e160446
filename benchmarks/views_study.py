"""Train choosers of candidate views (macro actions) and judge them beside the planner.

A chooser (:mod:`pirl.env.views`) picks one of eight candidate places to look from next;
the grid's breadth-first moves fly it there. Each training seed trains sb3-contrib's
MaskablePPO on :class:`~pirl.env.views.ViewsEnv` over the quick profile's training env
(15x15x3, its wind, no stall guard), one process per seed, two at a time, with the first
prototype's PPO settings (8 envs, 256 steps, batch 256, net [128, 128]; ``--reward`` picks
the weights). The method itself, ``pirl train --method ppo-views``, takes the profile's
``ppo`` section and the static weights; judge its runs with ``judge_runs.py``. Judging plays every
seed on validation scenarios (:func:`pirl.evaluate.scenarios.validation_seeds`, which no
evaluation uses) of larger worlds and sites, acting greedy and stochastic, under the quick
env (stall guard 32), beside the boustrophedon planner and the nearest-view rule
(:func:`~pirl.agents.views.nearest_view`). Rows: VCR IQM over seeds [stratified bootstrap 95%
interval], the worst seed, steps to 0.99 of coverable cells over the planner's (mean over
the episodes that got there; how many did, of all), and the stall guard's share of steps.

Usage (docs/experiments/2026-12-07-candidate-views.md gives the commands behind its tables)::

    python benchmarks/views_study.py --out runs/views --seeds 0 1 2 3 4 \
        --sizes 30 45 60 --sites examples/sites/campus examples/sites/village --episodes 6
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from agent_sweep import worlds_of  # noqa: E402
from pirl.agents.loading import load_policy  # noqa: E402
from pirl.agents.views import ViewsPolicy, nearest_view  # noqa: E402
from pirl.config.run import RunConfig  # noqa: E402
from pirl.env.views import Candidates, ViewsEnv  # noqa: E402
from pirl.evaluate.rollout import run_episode  # noqa: E402
from pirl.evaluate.scenarios import parse_size, validation_seeds  # noqa: E402
from pirl.evaluate.summary import interval_estimates  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
N_ENVS = 8


def train(seed: int, choices: int, reward: str, out: Path) -> str:
    """One chooser, trained on ``choices`` choices; saved as ``out/s{seed}.zip``."""
    import torch
    from sb3_contrib import MaskablePPO
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    from pirl.agents.train import training_env

    torch.set_num_threads(1)
    target = out / f"s{seed}.zip"
    if target.exists():
        return f"s{seed}: trained already"
    env_cfg = training_env(RunConfig.from_yaml(ROOT / "configs" / "quick.yaml"))
    venv = VecMonitor(DummyVecEnv([lambda: ViewsEnv(env_cfg.replace(reward=reward))] * N_ENVS))
    venv.seed(seed * 1000)
    model = MaskablePPO(
        "MlpPolicy", venv, n_steps=256, batch_size=256, n_epochs=4, learning_rate=3e-4,
        gamma=0.99, gae_lambda=0.95, ent_coef=0.01, policy_kwargs={"net_arch": [128, 128]},
        seed=seed, device="cpu", verbose=0,
    )  # fmt: skip
    model.set_logger(Logger(None, []))  # SB3's default would make a folder in the temp dir
    started = time.process_time()
    model.learn(choices)
    partial = out / f".s{seed}.part.zip"
    model.save(partial)
    os.replace(partial, target)
    return f"s{seed}: {choices:,} choices in {time.process_time() - started:.0f} CPU-s"


def chooser(model, act: str, seed: int):
    """The trained chooser as a function of the candidates: its most likely slot (greedy) or
    one drawn from its masked probabilities, seeded per scenario (stochastic)."""
    import torch

    rng = np.random.default_rng([seed, 0x5EED])

    def choose(c: Candidates) -> int:
        with torch.no_grad():
            dist = model.policy.get_distribution(
                torch.as_tensor(c.obs[None]), action_masks=c.mask[None]
            )
            p = dist.distribution.probs[0].numpy().astype(np.float64)
        return int(p.argmax()) if act == "greedy" else int(rng.choice(len(p), p=p / p.sum()))

    return choose


def judge(world: str, env_cfg, grid, seeds_of_runs: list[int], out: Path, episodes: int) -> str:
    import torch
    from sb3_contrib import MaskablePPO

    from pirl.env.vcpp_env import VCPPEnv

    torch.set_num_threads(1)
    scenarios = validation_seeds(grid, episodes)
    env = VCPPEnv(env_cfg)
    planner = [run_episode(env, load_policy("boustrophedon"), s).metrics for s in scenarios]
    rows = []

    def row(name: str, per_run: list[list[dict]]) -> str:
        vcr = [np.mean([m["vcr"] for m in run]) for run in per_run]
        pace = [
            m["steps_to_99"] / p["steps_to_99"]
            for run in per_run
            for m, p in zip(run, planner, strict=True)
            if m["steps_to_99"] is not None and p["steps_to_99"]
        ]
        guard = np.mean([m["guarded_steps"] / m["steps"] for run in per_run for m in run])
        est = interval_estimates(np.array(vcr)[:, None])
        n = sum(len(run) for run in per_run)
        return (
            f"{world:>14} {name:>18}  VCR IQM {est['iqm']:.3f} [{est['iqm_lo']:.3f}, "
            f"{est['iqm_hi']:.3f}]  worst seed {min(vcr):.3f}  to 0.99 "
            f"x{np.mean(pace) if pace else float('nan'):.2f} planner ({len(pace)}/{n})  "
            f"guarded {guard:.3f}"
        )

    rows.append(row("nearest-view rule", [[
        run_episode(env, ViewsPolicy(nearest_view), s).metrics for s in scenarios
    ]]))  # fmt: skip
    models = [MaskablePPO.load(out / f"s{seed}.zip", device="cpu") for seed in seeds_of_runs]
    for act in ("greedy", "stochastic"):
        per_run = [
            [run_episode(env, ViewsPolicy(chooser(m, act, s)), s).metrics for s in scenarios]
            for m in models
        ]
        rows.append(row(f"learned {act}", per_run))
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder of the trained choosers")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--choices", type=int, default=204_800, help="training choices a seed")
    parser.add_argument("--reward", choices=["ewri", "static"], default="ewri")
    parser.add_argument("--sizes", nargs="*", default=["30", "45", "60"])
    parser.add_argument("--sites", nargs="*", default=[])
    parser.add_argument("--episodes", type=int, default=6, help="scenarios per world")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(args.workers) as pool:
        jobs = [pool.submit(train, s, args.choices, args.reward, args.out) for s in args.seeds]
        for job in jobs:
            print(job.result(), flush=True)
        env = RunConfig.from_yaml(ROOT / "configs" / "quick.yaml").env.replace(start_camera="fixed")
        worlds = worlds_of(env, [parse_size(s) for s in args.sizes], [], args.sites)
        print(f"validation scenarios, {args.episodes} per world; VCR IQM over seeds [95% interval]")
        jobs = [
            pool.submit(judge, name, cfg, grid, args.seeds, args.out, args.episodes)
            for name, cfg, grid in worlds
        ]
        for job in jobs:
            print(job.result(), flush=True)


if __name__ == "__main__":
    main()
