"""Evaluation throughput: episodes per second, per-episode against batched, same policy.

Plays the same trained policy on the same scenarios twice in this process: episode by episode
(``EvalPlan(batched=False)``: one environment, a batch-of-one forward per step) and batched
(all scenarios of the size in one batched world, one forward per step), then prints both
rates, the speed-up and whether the records are identical. Without ``--run`` it first trains a
throwaway PPO-EWRI run with the quick profile's network for one rollout (its skill does not
matter for speed; the episodes run to the step limit or the battery like any other).

Usage: ``python benchmarks/eval_throughput.py [--run runs/ppo-ewri-s0] [--episodes 32]
[--size 30] [--act stochastic]``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from pirl.config.run import RunConfig
from pirl.evaluate.runner import EvalPlan, evaluate, spec_for_run
from pirl.evaluate.scenarios import parse_size

ROOT = Path(__file__).resolve().parents[1]


def _throwaway_run(folder: Path) -> Path:
    from pirl.agents.runs import train_one

    cfg = RunConfig.from_yaml(ROOT / "configs" / "quick.yaml")
    steps = cfg.ppo.n_envs * cfg.ppo.n_steps
    cfg = cfg.with_overrides(train={"total_steps": steps, "checkpoint_every": steps})
    run = folder / "ppo-ewri-s0"
    train_one("ppo-ewri", "", 0, cfg, run, False, False)
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, default=None, help="a finished run folder")
    parser.add_argument("--episodes", type=int, default=32, help="scenarios")
    parser.add_argument("--size", default="30", help="world size (30 = 30x30x3)")
    parser.add_argument("--act", default="stochastic", choices=("stochastic", "greedy"))
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        run = args.run or _throwaway_run(Path(tmp))
        cfg = RunConfig.from_yaml(run / "config.yaml")
        spec = spec_for_run(run)
        size = parse_size(args.size)
        print(f"policy: {spec.label} ({run}); {args.episodes} scenarios at {args.size}, "
              f"act {args.act}; one process, one torch thread")  # fmt: skip
        rates, outputs = [], []
        for batched in (False, True):
            plan = EvalPlan(
                specs=[spec], sizes=[size], episodes=args.episodes, env=cfg.env, config=cfg,
                acts=[args.act], batched=batched,
            )  # fmt: skip
            out = Path(tmp) / f"eval-{batched}"
            start = time.perf_counter()
            evaluate(plan, out, workers=1)
            rates.append(args.episodes / (time.perf_counter() - start))
            outputs.append((out / "episodes.jsonl").read_text())
    print(f"{'per-episode ep/s':>17} {'batched ep/s':>13} {'speed-up':>9} {'same records':>13}")
    same = "yes" if outputs[0] == outputs[1] else "NO"
    print(f"{rates[0]:>17.2f} {rates[1]:>13.2f} {rates[1] / rates[0]:>9.1f} {same:>13}")


if __name__ == "__main__":
    main()
