"""Agent settings sweep: action masking and observation blocks, judged at scale in both act modes.

Trains PPO-EWRI and PIRL with oracle advice (the profile's ``reproduce.pirl_variants``) for
every variant below and every training seed, with ``pirl reproduce``'s training (worker
processes, one folder per variant), then plays every run on larger worlds than it trained on,
acting stochastic and greedy, next to the boustrophedon planner on the same scenarios, and
optionally on cluttered worlds (``--clutter``: 8-20 spheres) and sites (``--sites``). Rows:
VCR IQM over training seeds [stratified bootstrap 95% interval], the worst seed, steps, steps
relative to the planner, camera share, and the episodes that ended in a loop (their last 60
steps visit fewer than 10 cells). ``--split validation`` (the default) plays validation
scenarios, which no evaluation uses: settings are chosen there. ``--split evaluation`` plays the
evaluation scenarios of ``pirl reproduce`` (the ablation in
docs/experiments/2026-11-30-agents-masks-memory.md).

Usage (docs/results.md and the notes in docs/experiments/ give the commands that produced their
tables)::

    python benchmarks/agent_sweep.py --variants unmasked masked masked-memory \
        --seeds 0 1 --sizes 30 45 60 --episodes 6 --out results/agent-sweep
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
import yaml

from pirl.agents.loading import load_policy
from pirl.config.run import RunConfig
from pirl.evaluate.rollout import run_batch, run_episode
from pirl.evaluate.scenarios import parse_size, scenario_seeds, size_name, validation_seeds
from pirl.evaluate.summary import interval_estimates
from pirl.reproduce.pipeline import steps_text, train_all
from pirl.world.metrics import LOOP_CELLS

ROOT = Path(__file__).resolve().parents[1]

# name -> overrides of the profile (sections env, ppo, train); every variant trains the same runs.
PAPER_OBS = {"obs_visits": False, "obs_target": False}
MEMORY = {"obs_visits": True, "obs_target": True}
PATH = {**MEMORY, "obs_target_path": True}
FIXED = {"camera_start": "fixed"}  # training starts at the paper's camera pose
# PIRL trained as long as PPO-EWRI (quick's budgets since "PIRL's budget",
# docs/experiments/2026-12-03-stall-scalar-and-pirl-budget.md).
PIRL409 = {"ppo-ewri": 409600, "pirl": 409600}


def overrides(masks: bool = True, env=MEMORY, ppo=None, train=None) -> dict[str, dict]:
    """Overrides of one variant: masks or not, observation blocks, other PPO and train
    settings (training from the paper's camera pose unless ``train`` says otherwise)."""
    return {
        "ppo": {"action_masking": masks, **(ppo or {})},
        # Without the stall guard unless a variant asks for it (quick has it on since "The
        # stall guard"; the variants measured before it stay what they were).
        "env": {"stall_guard": 0, **env},
        "train": {**FIXED, "stall_guard": None, **(train or {})},
    }


def budget(steps: int) -> dict:
    """One budget for every method (the profile's per-method budgets dropped)."""
    return {"total_steps": steps, "steps_by_method": {}}


VARIANTS: dict[str, dict[str, dict]] = {
    "unmasked": overrides(masks=False, env=PAPER_OBS),
    "masked": overrides(env=PAPER_OBS),
    "masked-memory": overrides(),
    "masked-visits": overrides(env={**PAPER_OBS, "obs_visits": True}),
    "masked-target": overrides(env={**PAPER_OBS, "obs_target": True}),
    # Exploring starts: training episodes begin at a random camera pose (evaluation never does).
    "masked-memory-explore": overrides(train={"camera_start": "random"}),
    "masked-memory-mixed": overrides(train={"camera_start": "mixed"}),
    # Longer credit horizons, more exploration, a longer budget (PPO-EWRI's battery-bound runs).
    "masked-memory-gamma995": overrides(ppo={"gamma": 0.995}),
    "masked-memory-ent03": overrides(ppo={"ent_coef": 0.03}),
    "masked-memory-long": overrides(train=budget(819200)),
    "masked-memory-long3x": overrides(train=budget(1228800)),
    "masked-memory-long4x": overrides(train=budget(1638400)),
    # More learning per step, for a fixed budget (the demo's): a larger step size, more epochs.
    "masked-memory-lr6e4": overrides(ppo={"learning_rate": 0.0006}),
    "masked-memory-lr1e3": overrides(ppo={"learning_rate": 0.001}),
    "masked-memory-epochs8": overrides(ppo={"n_epochs": 8}),
    # Less entropy bonus: a sampled policy that leans less on chance camera actions.
    "masked-memory-ent005": overrides(ppo={"ent_coef": 0.005}),
    # More steps, fewer passes over each rollout: about the update cost of 262,144 x 4 epochs.
    "masked-memory-s409e2": overrides(ppo={"n_epochs": 2}, train=budget(409600)),
    "masked-memory-s409e3": overrides(ppo={"n_epochs": 3}, train=budget(409600)),
    # The same with the same rollout size from twice the worlds (32 x 128 steps): 20% faster.
    "masked-memory-s409e3-envs32": overrides(
        ppo={"n_epochs": 3, "n_envs": 32, "n_steps": 128}, train=budget(409600)
    ),
    # The target block by the way round obstacles (breadth-first), not the straight line, which
    # trapped greedy policies in front of walls on 60x60x3
    # (docs/experiments/2026-11-30-way-round-obstacles.md).
    "masked-memory-path": overrides(
        env={**MEMORY, "obs_target_path": True}, train={"obstacles": []}
    ),
    # ... with PPO-EWRI at 409,600 steps (the other methods at the profile's budget).
    "masked-memory-path-ewri409": overrides(
        env={**MEMORY, "obs_target_path": True}, train={"steps_by_method": {"ppo-ewri": 409600}}
    ),
    # Train on a world 4 times the paper's 15x15x3 (episodes of 364 steps, not 91).
    "masked-memory-train30": overrides(env={**MEMORY, "size": [30, 30, 3]}),
    # Greedy loops on clutter and sites (docs/experiments/2026-12-02-greedy-loops-clutter-sites.md):
    # training worlds twice as dense as the evaluation's (4-10 spheres on 15x15x3), or visit
    # counts that saturate at 8, not 3.
    "masked-memory-path-dense": overrides(env=PATH, train={"obstacles": [4, 10]}),
    "masked-memory-path-visits8": overrides(env={**PATH, "obs_visits_cap": 8}),
    # ... or half the training episodes start with the work left in one box out of sight.
    "masked-memory-path-surveyed": overrides(env=PATH, train={"surveyed_start": 0.5}),
    # Trained on a site's seeded starts, not on generated worlds (what training on sites changes).
    "masked-memory-path-village": overrides(env={**PATH, "site": "examples/sites/village"}),
    "masked-memory-path-dense-surveyed": overrides(
        env=PATH, train={"obstacles": [4, 10], "surveyed_start": 0.5}
    ),
    # ... or a scalar that keeps climbing inside a loop: the steps since coverage last grew.
    "masked-memory-path-stall": overrides(env={**PATH, "obs_stall": True}),
    "masked-memory-path-dense-stall": overrides(
        env={**PATH, "obs_stall": True}, train={"obstacles": [4, 10]}
    ),
    # ... or PIRL trained as long as PPO-EWRI (409,600 steps: the budget at which every
    # greedy-sampled gap on 30/45/60 closed, "The budget" in
    # docs/experiments/2026-11-30-budgets.md).
    "masked-memory-path-pirl409": overrides(env=PATH, train={"steps_by_method": PIRL409}),
    "masked-memory-path-pirl409-stall": overrides(
        env={**PATH, "obs_stall": True},
        train={"steps_by_method": PIRL409},
    ),
    "masked-memory-path-pirl409-dense-stall": overrides(
        env={**PATH, "obs_stall": True},
        train={"obstacles": [4, 10], "steps_by_method": PIRL409},
    ),
    # ... or the env's stall guard (env.stall_guard: after 32 steps without new coverage the
    # env leads the UAV to the nearest work), on in training as in evaluation.
    "masked-memory-path-pirl409-guard32": overrides(
        env={**PATH, "stall_guard": 32}, train={"steps_by_method": PIRL409}
    ),
    # The demo's own profile (--profile configs/quick.yaml --stall-guard 32) with a cheaper
    # PPO update (about 60% of its training time): a smaller network, or 4x larger minibatches.
    "quick": {},
    "quick-net64": {"ppo": {"net_arch": [64, 64]}},
    "quick-net128": {"ppo": {"net_arch": [128, 128]}},
    "quick-batch2048": {"ppo": {"batch_size": 2048}},
    "quick-net128-batch2048": {"ppo": {"net_arch": [128, 128], "batch_size": 2048}},
}

# Cluttered generated worlds: 8-20 spheres where the evaluation's have 2-5 (a held-out family).
CLUTTER = {"obstacles_min": 8, "obstacles_max": 20}


def worlds_of(
    base_env,
    sizes,
    clutter: list[str],
    sites: list[str],
    wind: bool = True,
    guard: int | None = None,
):
    """(name, env config with size or site, grid size) of every world family to play; without
    ``wind`` the grid's random wind pushes are off (the PyFlyt flight has none either); with
    ``guard`` every world plays under that stall guard, whatever the run trained with."""
    from pirl.world.seeable import with_site

    base_env = base_env.replace(site="", ground_cells=0)  # a run may have trained on a site
    if guard is not None:
        base_env = base_env.replace(stall_guard=guard)
    if not wind:
        base_env = base_env.replace(wind_prob=0.0)
    out = [(size_name(s), base_env.replace(size=s), s) for s in sizes]
    for text in clutter:
        s = parse_size(text)
        out.append((f"clutter-{size_name(s)}", base_env.replace(size=s, **CLUTTER), s))
    for site in sites:
        env = with_site(base_env, site)
        out.append((f"site:{Path(site).name}", env, env.size))
    return out


def planner_steps(env_cfg, seeds: list[int]) -> tuple[list[float], list[float]]:
    """The boustrophedon planner's steps and VCR on each scenario."""
    from pirl.env.vcpp_env import VCPPEnv

    env = VCPPEnv(env_cfg)
    steps, vcr = [], []
    for seed in seeds:
        m = run_episode(env, load_policy("boustrophedon"), seed).metrics
        steps.append(m["steps"])
        vcr.append(m["vcr"])
    return steps, vcr


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default=str(ROOT / "configs" / "study-agents.yaml"))
    parser.add_argument("--variants", nargs="+", default=["masked", "masked-memory"],
                        choices=sorted(VARIANTS))  # fmt: skip
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--methods", nargs="+", default=None, help="default: the profile's")
    parser.add_argument("--steps", type=int, default=None,
                        help="PPO steps of every method (default: the profile's)")  # fmt: skip
    parser.add_argument("--sizes", nargs="*", default=["30", "45", "60"])
    parser.add_argument(
        "--clutter",
        nargs="*",
        default=[],
        help="sizes also played with 8-20 spheres (cluttered worlds)",
    )
    parser.add_argument("--sites", nargs="*", default=[], help="site folders also played")
    parser.add_argument("--episodes", type=int, default=6, help="scenarios per size")
    parser.add_argument("--no-wind", action="store_true",
                        help="no random wind pushes in the grid (as in PyFlyt); results go to "
                        "sweep-nowind.md/.csv")  # fmt: skip
    parser.add_argument("--stall-guard", type=int, default=None,
                        help="play every world under this env.stall_guard (0: off), "
                        "whatever the runs trained with; results go to "
                        "sweep[-nowind]-guardN.md/.csv")  # fmt: skip
    parser.add_argument("--split", default="validation", choices=("validation", "evaluation"))
    parser.add_argument("--workers", type=int, default=None, help="training processes")
    parser.add_argument("--out", type=Path, default=Path("results/agent-sweep"))
    args = parser.parse_args()

    base = RunConfig.from_yaml(args.profile)
    if args.steps:
        # One budget for every method (the profile's own per-method budgets are dropped).
        base = base.with_overrides(train=budget(args.steps))
    base = base.with_overrides(reproduce={"seeds": args.seeds})
    if args.methods:
        base = base.with_overrides(reproduce={"methods": args.methods})
    # PIRL with oracle advice only (a profile such as quick also trains PIRL with its LLM).
    oracle = [v for v in base.reproduce.pirl_variants if v.get("advisor") == "oracle"]
    if oracle:
        base = base.with_overrides(reproduce={"pirl_variants": oracle})
    pick = validation_seeds if args.split == "validation" else scenario_seeds
    sizes = [parse_size(s) for s in args.sizes]
    planner = {}
    wind = not args.no_wind
    guard = args.stall_guard
    for name, env, grid_size in worlds_of(base.env, sizes, args.clutter, args.sites, wind, guard):
        planner[name] = planner_steps(env, pick(grid_size, args.episodes))
    rows = []
    budgets = {}
    for variant in args.variants:
        cfg = base.with_overrides(**VARIANTS[variant])
        if cfg.env.site:  # as `pirl train --site` settles it: the site's grid and ground
            from pirl.world.seeable import with_site

            on_site = with_site(cfg.env, str(ROOT / cfg.env.site))
            cfg = cfg.with_overrides(
                env={
                    "site": on_site.site,
                    "size": list(on_site.size),
                    "ground_cells": on_site.ground_cells,
                }
            )
        budgets[variant] = steps_text(cfg)
        runs = train_all(cfg, args.out / variant, "oracle", print, False, workers=args.workers)
        groups: dict[str, list[Path]] = {}
        for run in runs:
            groups.setdefault(run.name.rsplit("-s", 1)[0], []).append(run)
        for group, members in groups.items():
            label = json.loads((members[0] / "meta.json").read_text()).get("label", group)
            trained_env = RunConfig.from_dict(
                yaml.safe_load((members[0] / "config.yaml").read_text())
            ).env
            # Every evaluation starts at the paper's camera pose (a run that trained with
            # exploring starts recorded start_camera: random before they left its env).
            trained_env = trained_env.replace(start_camera="fixed")
            worlds = worlds_of(trained_env, sizes, args.clutter, args.sites, wind, guard)
            for world, env, grid_size in worlds:
                seeds = pick(grid_size, args.episodes)
                p_steps, p_vcr = planner[world]
                for act in ("stochastic", "greedy"):
                    per_seed_vcr, per_seed_steps, ratios, cams, guided = [], [], [], [], []
                    loops = 0
                    for run in members:
                        metrics = run_batch(env, load_policy(run, act=act), seeds)
                        loops += sum(m["tail_cells"] < LOOP_CELLS for m in metrics)
                        per_seed_vcr.append(np.mean([m["vcr"] for m in metrics]))
                        per_seed_steps.append(np.mean([m["steps"] for m in metrics]))
                        ratios.append(
                            np.mean([m["steps"] / p for m, p in zip(metrics, p_steps, strict=True)])
                        )
                        cams.append(np.mean([m["camera_share"] for m in metrics]))
                        guided.append(np.mean([m["guarded_steps"] / m["steps"] for m in metrics]))
                    est = interval_estimates(np.array(per_seed_vcr)[:, None])
                    rows.append({
                        "variant": variant, "method": group, "label": label,
                        "size": world, "act": act, "seeds": len(members),
                        "vcr_iqm": est["iqm"],
                        "vcr_iqm_lo": est["iqm_lo"], "vcr_iqm_hi": est["iqm_hi"],
                        "vcr_min_seed": float(min(per_seed_vcr)),
                        "vcr_per_seed": " ".join(f"{v:.3f}" for v in per_seed_vcr),
                        "steps": float(np.mean(per_seed_steps)),
                        "steps_vs_planner": float(np.mean(ratios)),
                        "planner_steps": float(np.mean(p_steps)),
                        "planner_vcr": float(np.mean(p_vcr)),
                        "vcr_per_100_steps": float(
                            100 * np.mean(per_seed_vcr) / max(1.0, np.mean(per_seed_steps))
                        ),
                        "camera_share": float(np.mean(cams)),
                        "guarded_share": float(np.mean(guided)),
                        "loop_episodes": int(loops),
                        "episodes": len(seeds) * len(members),
                    })  # fmt: skip
                    r = rows[-1]
                    print(
                        f"{variant:>14} {group:>22} {r['size']:>8} {act:>10}  VCR IQM "
                        f"{r['vcr_iqm']:.3f} [{r['vcr_iqm_lo']:.3f}, {r['vcr_iqm_hi']:.3f}] "
                        f"min {r['vcr_min_seed']:.3f}  steps x{r['steps_vs_planner']:.2f} "
                        f"planner  cam {r['camera_share']:.2f}  guarded {r['guarded_share']:.3f}  "
                        f"loops {loops}/{r['episodes']}",
                        flush=True,
                    )
    args.out.mkdir(parents=True, exist_ok=True)
    stem = "sweep" + ("-nowind" if args.no_wind else "")
    stem += f"-guard{guard}" if guard is not None else ""
    with open(args.out / f"{stem}.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    lines = [
        f"Agent sweep on {args.split} scenarios ({args.episodes} per size"
        + (", no wind pushes" if args.no_wind else "")
        + (f", every world under stall guard {guard}" if guard is not None else "")
        + "), profile "
        f"{Path(args.profile).name}, training seeds {args.seeds}; PPO steps: "
        + "; ".join(f"{v} {b}" for v, b in budgets.items())
        + "\n",
        "| variant | method | size | act | VCR IQM [95% interval] | per seed | steps "
        "| x planner's steps | VCR / 100 steps | camera share | guarded share | loop episodes |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['variant']} | {r['label']} | {r['size']} | {r['act']} | {r['vcr_iqm']:.3f} "
            f"[{r['vcr_iqm_lo']:.3f}, {r['vcr_iqm_hi']:.3f}] | {r['vcr_per_seed']} | "
            f"{r['steps']:.0f} | {r['steps_vs_planner']:.2f} | {r['vcr_per_100_steps']:.3f} | "
            f"{r['camera_share']:.2f} | {r['guarded_share']:.3f} | "
            f"{r['loop_episodes']}/{r['episodes']} |"
        )
    text = "\n".join(lines) + "\n"
    (args.out / f"{stem}.md").write_text(text)
    print(text)
    print(f"results: {args.out / stem}.md and {args.out / stem}.csv")


if __name__ == "__main__":
    main()
