"""Judge finished run folders on validation scenarios, both act modes, group beside group.

Settings are chosen on validation scenarios (:func:`pirl.evaluate.scenarios.validation_seeds`,
which no evaluation uses). This plays groups of finished runs (one folder per training seed,
for example one setting against another) on larger worlds than they trained on and on
sites, next to the boustrophedon planner, each run under the env it trained with (its stall
guard included) from the paper's camera pose. Rows: VCR IQM over seeds [stratified bootstrap
95% interval], the worst seed, steps relative to the planner, the share of steps the stall
guard chose, and steps to 0.99 of coverable cells over the planner's (the mean over
the episodes that got there; how many did, of all, in brackets).

Usage (docs/experiments/ notes give the commands behind their tables)::

    python benchmarks/judge_runs.py --group now=runs/pirl-local-s0,runs/pirl-local-s1 \
        --group rate0004=other/pirl-local-s0,other/pirl-local-s1 \
        --sizes 30 45 60 --sites examples/sites/campus --episodes 6
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from agent_sweep import worlds_of  # noqa: E402
from pirl.agents.loading import load_policy  # noqa: E402
from pirl.config.run import RunConfig  # noqa: E402
from pirl.evaluate.rollout import run_batch  # noqa: E402
from pirl.evaluate.scenarios import parse_size, validation_seeds  # noqa: E402
from pirl.evaluate.summary import interval_estimates  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--group", action="append", required=True,
                        help="NAME=RUN[,RUN...]: runs of one setting, one per seed")  # fmt: skip
    parser.add_argument("--sizes", nargs="*", default=["30", "45", "60"])
    parser.add_argument("--sites", nargs="*", default=[])
    parser.add_argument("--episodes", type=int, default=6, help="scenarios per world")
    parser.add_argument("--guard", type=int, default=None,
                        help="play every world under this stall guard (0: off), whatever "
                             "the runs trained with")  # fmt: skip
    args = parser.parse_args()
    groups = {}
    for text in args.group:
        name, _, runs = text.partition("=")
        groups[name] = [Path(r) for r in runs.split(",") if r]
    sizes = [parse_size(s) for s in args.sizes]
    print(f"validation scenarios, {args.episodes} per world; VCR IQM over seeds [95% interval]")
    for name, runs in groups.items():
        env = RunConfig.from_dict(yaml.safe_load((runs[0] / "config.yaml").read_text())).env
        env = env.replace(start_camera="fixed")
        for world, cfg, grid in worlds_of(env, sizes, [], args.sites, guard=args.guard):
            seeds = validation_seeds(grid, args.episodes)
            planned = planner_metrics(cfg, seeds)  # one planner episode per scenario
            p_steps = [m["steps"] for m in planned]
            p_99 = [m["steps_to_99"] for m in planned]
            for act in ("stochastic", "greedy"):
                vcr, ratio, guard, to_99 = [], [], [], []
                for run in runs:
                    metrics = play(cfg, load_policy(run, act=act), seeds)
                    vcr.append(np.mean([m["vcr"] for m in metrics]))
                    steps = [m["steps"] / p for m, p in zip(metrics, p_steps, strict=True)]
                    ratio.append(np.mean(steps))
                    guard.append(np.mean([m["guarded_steps"] / m["steps"] for m in metrics]))
                    to_99 += [
                        m["steps_to_99"] / p
                        for m, p in zip(metrics, p_99, strict=True)
                        if m["steps_to_99"] is not None and p
                    ]
                est = interval_estimates(np.array(vcr)[:, None])
                n = len(runs) * len(seeds)
                pace = f"x{np.mean(to_99):.2f}" if to_99 else "-"
                print(
                    f"{name:>12} {world:>14} {act:>10}  VCR IQM {est['iqm']:.3f} "
                    f"[{est['iqm_lo']:.3f}, {est['iqm_hi']:.3f}]  worst seed {min(vcr):.3f}  "
                    f"steps x{np.mean(ratio):.2f} planner  to 0.99 {pace} ({len(to_99)}/{n})  "
                    f"guarded {np.mean(guard):.3f}  seeds {' '.join(f'{v:.3f}' for v in vcr)}",
                    flush=True,
                )


def play(env_cfg, policy, seeds: list[int]) -> list[dict]:
    """A learned policy's episode metrics on each scenario: one batch of every scenario for a
    policy over the 12 actions, episode by episode for a chooser of candidate views."""
    from pirl.agents.loading import LearnedPolicy
    from pirl.env.vcpp_env import VCPPEnv
    from pirl.evaluate.rollout import run_episode

    if isinstance(policy, LearnedPolicy):
        return run_batch(env_cfg, policy, seeds)
    env = VCPPEnv(env_cfg)
    return [run_episode(env, policy, s).metrics for s in seeds]


def planner_metrics(env_cfg, seeds: list[int]) -> list[dict]:
    """The boustrophedon planner's episode metrics on each scenario (its steps, its steps to
    0.99 of coverable cells)."""
    from pirl.env.vcpp_env import VCPPEnv
    from pirl.evaluate.rollout import run_episode

    env = VCPPEnv(env_cfg)
    return [run_episode(env, load_policy("boustrophedon"), s).metrics for s in seeds]


if __name__ == "__main__":
    main()
