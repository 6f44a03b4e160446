"""PARE weight sweep on validation scenarios: lam_cam x lam_move per advisor, seeds as the unit.

Trains PIRL for every (lam_cam, lam_move, training seed) with ``pirl reproduce``'s training
(parallel worker processes, one folder and one label per configuration), then plays every run
on *validation* scenario seeds (:func:`pirl.evaluate.scenarios.validation_seeds`, which no
evaluation ever uses) in both act modes, and prints one row per point: VCR IQM over training
seeds with its stratified bootstrap 95% interval, mean VCR, camera share, steps. It writes
``sweep.csv`` and ``sweep.md`` into ``--out`` and names the best point by VCR IQM in the
headline act mode. Weights are chosen here, never on evaluation seeds.

Usage (reduced size; see docs/results.md for the full command)::

    python benchmarks/pare_sweep.py --advisor oracle --lam-cam 1 4 --lam-move 1 \
        --seeds 0 1 --steps 32768 --size 15 --episodes 8 --out results/sweep-oracle
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
from pathlib import Path

import numpy as np

from pirl.agents.loading import load_policy
from pirl.config.run import RunConfig
from pirl.evaluate.rollout import run_batch
from pirl.evaluate.scenarios import parse_size, size_name, validation_seeds
from pirl.evaluate.summary import interval_estimates
from pirl.reproduce.pipeline import train_all

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default=str(ROOT / "configs" / "quick.yaml"))
    parser.add_argument("--advisor", default="oracle", choices=("oracle", "local", "openai"))
    parser.add_argument("--lam-cam", type=float, nargs="+", default=[1.0, 2.0, 4.0, 8.0])
    parser.add_argument("--lam-move", type=float, nargs="+", default=[0.5, 1.0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--steps", type=int, default=None, help="PPO steps (default: profile)")
    parser.add_argument("--size", default="15", help="validation world (15 = 15x15x3)")
    parser.add_argument("--episodes", type=int, default=20, help="validation scenarios")
    parser.add_argument("--act", default="stochastic", choices=("stochastic", "greedy"),
                        help="headline act mode for the choice")  # fmt: skip
    parser.add_argument("--workers", type=int, default=None, help="training processes")
    parser.add_argument("--out", type=Path, default=Path("results/sweep"))
    args = parser.parse_args()

    cfg = RunConfig.from_yaml(args.profile)
    if args.steps:
        cfg = cfg.with_overrides(train={"total_steps": args.steps})
    points = list(itertools.product(args.lam_cam, args.lam_move))
    variants = [{"advisor": args.advisor, "lam_cam": c, "lam_move": m} for c, m in points]
    cfg = cfg.with_overrides(
        reproduce={"methods": ["pirl"], "seeds": args.seeds, "pirl_variants": variants}
    )
    runs = train_all(cfg, args.out, args.advisor, print, False, workers=args.workers)
    size = parse_size(args.size)
    seeds = validation_seeds(size, args.episodes)
    env = cfg.env.replace(size=size)
    rows = []
    for (lam_cam, lam_move), act in itertools.product(points, ("stochastic", "greedy")):
        per_seed, episodes, label = [], [], ""
        for seed in args.seeds:
            name = f"pirl-{args.advisor}-lamcam{lam_cam}-lammove{lam_move}-s{seed}"
            run = next(r for r in runs if r.name == name)
            label = json.loads((run / "meta.json").read_text()).get("label", name)
            metrics = run_batch(env, load_policy(run, act=act), seeds)
            per_seed.append(np.mean([m["vcr"] for m in metrics]))
            episodes += metrics
        est = interval_estimates(np.array(per_seed)[:, None])
        rows.append({
            "advisor": args.advisor, "lam_cam": lam_cam, "lam_move": lam_move, "act": act,
            "seeds": len(args.seeds), "episodes": len(episodes),
            "vcr_iqm": est["iqm"], "vcr_iqm_lo": est["iqm_lo"], "vcr_iqm_hi": est["iqm_hi"],
            "vcr_mean": float(np.mean([m["vcr"] for m in episodes])),
            "camera_share": float(np.mean([m["camera_share"] for m in episodes])),
            "steps": float(np.mean([m["steps"] for m in episodes])),
            "label": label,
        })  # fmt: skip
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "sweep.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    head = (
        f"PARE sweep, advisor {args.advisor}, {cfg.train.total_steps:,} PPO steps, training "
        f"seeds {args.seeds}, {args.episodes} validation scenarios at {size_name(size)}\n\n"
        "| lam_cam | lam_move | act | VCR IQM [95% interval] | VCR mean | camera share | steps |\n"
        "|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for r in rows:
        lines.append(
            f"| {r['lam_cam']:g} | {r['lam_move']:g} | {r['act']} | {r['vcr_iqm']:.3f} "
            f"[{r['vcr_iqm_lo']:.3f}, {r['vcr_iqm_hi']:.3f}] | {r['vcr_mean']:.3f} | "
            f"{r['camera_share']:.3f} | {r['steps']:.0f} |"
        )
    best = max((r for r in rows if r["act"] == args.act), key=lambda r: r["vcr_iqm"])
    lines.append(
        f"\nBest by VCR IQM acting {args.act}: lam_cam {best['lam_cam']:g}, "
        f"lam_move {best['lam_move']:g}."
    )
    text = "\n".join(lines) + "\n"
    (args.out / "sweep.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
