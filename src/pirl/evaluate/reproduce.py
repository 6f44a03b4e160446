"""``pirl reproduce``: train every method that is not trained yet, evaluate all, write the report.

The output folder is the unit of work: ``runs/`` holds one run folder per method and seed,
``eval/`` the evaluation, ``report/`` the report. Finished runs are kept, interrupted ones
resume from their last checkpoint, so an interrupted reproduction picks up where it stopped.
"""

from __future__ import annotations

import functools
import json
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pirl.agents import checkpoint
from pirl.agents.config import RunConfig
from pirl.agents.runs import train_one
from pirl.evaluate.runner import EvalPlan, evaluate, spec_for_builtin, spec_for_run
from pirl.evaluate.scenarios import parse_size, scenario_seeds
from pirl.world.config import ConfigError

Log = Callable[[str], None]


def _run_state(run: Path) -> str:
    """'complete', 'resumable', 'broken' (exists, nothing to resume) or 'absent'."""
    meta = run / "meta.json"
    if meta.is_file() and json.loads(meta.read_text()).get("complete"):
        return "complete"
    if checkpoint.latest(run / "checkpoints") is not None:
        return "resumable"
    return "broken" if run.exists() else "absent"


def train_all(
    cfg: RunConfig,
    out: Path,
    advisor: str,
    log: Log,
    show_progress: bool = True,
    ray_address: str | None = None,
) -> list[Path]:
    """Train (or resume, or skip) every method x seed; returns the finished run folders.

    With ``ray_address`` the runs go to Ray in parallel (IL after its PPO-EWRI expert).
    """
    from pirl.evaluate.distributed import TrainJob, train_on_ray

    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    plan: list[tuple[str, str, int]] = []
    for seed in cfg.reproduce.seeds:
        plan += [("ppo-sr", "", seed), ("ppo-ewri", "", seed), ("pirl", advisor, seed)]
        if cfg.reproduce.oracle_pirl and advisor != "oracle":
            plan.append(("pirl", "oracle", seed))
        plan.append(("il", "", seed))
    finished = []
    remote: list[TrainJob] = []
    for method, adv, seed in plan:
        name = f"{method}{'-' + adv if adv else ''}-s{seed}"
        run = runs_dir / name
        state = _run_state(run)
        if state == "complete":
            log(f"{name}: already trained")
            finished.append(run)
            continue
        if state == "broken":
            log(f"{name}: incomplete with no checkpoint; starting again")
            shutil.rmtree(run)
        resume = state == "resumable"
        log(f"{name}: {'resuming' if resume else 'training'}")
        finished.append(run)
        if ray_address:
            remote.append(TrainJob(name, method, adv, seed, run, resume))
            continue
        start = time.perf_counter()
        train_one(method, adv, seed, cfg, run, resume, show_progress)
        log(f"{name}: done in {time.perf_counter() - start:.0f} s")
    if ray_address:
        train_on_ray(ray_address, cfg, remote, log)
    return finished


def record_gifs(cfg: RunConfig, runs: list[Path], advisor: str, folder: Path) -> dict[str, Path]:
    """One animation per method on the same 30x30x3 scenario (the first evaluation seed)."""
    from pirl.advice.factory import make_advisor
    from pirl.agents.loading import load_policy
    from pirl.env.vcpp_env import VCPPEnv
    from pirl.evaluate.rollout import run_episode, save_gif

    size = (30, 30, 3)
    seed = scenario_seeds(size, 1)[0]
    env = VCPPEnv(cfg.env.replace(size=size, render_cell_px=8), render_mode="rgb_array")
    specs = [spec_for_run(r) for r in runs if r.name.endswith(f"-s{cfg.reproduce.seeds[0]}")]
    specs += [
        spec_for_builtin("llm-only", advisor, cfg.reproduce.llm_only_max_calls),
        spec_for_builtin("boustrophedon"),
    ]
    gifs = {}
    for spec in specs:
        adv = make_advisor(spec.advisor, cfg) if spec.advisor else None
        policy = load_policy(
            spec.source,
            advisor=adv,
            seed=0,
            max_calls=spec.max_calls,
            prompt_variant=cfg.pare.prompt_variant,
        )
        result = run_episode(env, policy, seed, record=True, frame_every=cfg.reproduce.gif_every)
        gifs[f"{spec.label}: VCR {result.metrics['vcr']:.2f}"] = save_gif(
            result.frames, folder / f"{spec.key}.gif", fps=12
        )
    return gifs


def reproduce(
    cfg: RunConfig,
    out: Path,
    advisor: str = "local",
    workers: int | None = None,
    log: Log = print,
    progress: Callable[[int, int], None] | None = None,
    show_progress: bool = True,
    ray_address: str | None = None,
) -> Path:
    """The main job. Returns the path of ``report.html``.

    ``ray_address`` sends training runs and evaluation episodes to Ray (``pirl[distributed]``).
    """
    from pirl.agents.train import git_commit
    from pirl.evaluate.report import write_report

    if advisor not in ("local", "openai", "oracle"):
        raise ConfigError(f"--advisor {advisor!r}: allowed values are local, openai, oracle")
    out = Path(out)
    started = time.perf_counter()
    runs = train_all(cfg, out, advisor, log, show_progress, ray_address)
    trained_s = time.perf_counter() - started
    rp = cfg.reproduce
    specs = [spec_for_run(r) for r in runs]
    specs += [
        spec_for_builtin("llm-only", advisor, rp.llm_only_max_calls),
        spec_for_builtin("boustrophedon"),
        spec_for_builtin("random"),
    ]
    plan = EvalPlan(
        specs=specs,
        sizes=[parse_size(s) for s in rp.sizes],
        episodes=rp.episodes,
        env=cfg.env,
        config=cfg,
        episodes_per_method={"llm-only": rp.llm_only_episodes},
        sims=["grid", "physics"] if rp.physics_sizes else ["grid"],
        sim_sizes={"physics": [parse_size(x) for x in rp.physics_sizes]},
        sim_episodes={"physics": rp.physics_episodes},
    )
    log(f"evaluating {len(specs)} methods on {', '.join(map(str, rp.sizes))}")
    factory = None
    if ray_address:
        from pirl.evaluate.distributed import ray_executor

        factory = functools.partial(ray_executor, ray_address)
    summary = evaluate(
        plan, out / "eval", workers or rp.workers, progress=progress, executor_factory=factory
    )
    log("recording animations")
    gifs = record_gifs(cfg, runs, advisor, out / "report" / "gifs")
    stats = _advisor_stats(runs, out / "eval" / "episodes.jsonl")
    notes = [
        f"Profile values: {rp.episodes} scenarios per size ({rp.llm_only_episodes} for "
        f"LLM-only), training seeds {list(rp.seeds)}, {cfg.train.total_steps:,} steps per "
        f"PPO run; physics simulator: {rp.physics_episodes} scenarios on "
        f"{', '.join(rp.physics_sizes) or 'no size'}. "
        f"Training took {trained_s / 60:.1f} min, everything "
        f"{(time.perf_counter() - started) / 60:.1f} min.",
        "Advisors other than an LLM (the oracle) and planners are labelled as such.",
    ]
    return write_report(
        out / "report", summary, runs, gifs, stats, code_version=git_commit(), notes=notes
    )


def _advisor_stats(runs: list[Path], episodes: Path) -> dict[str, Any]:
    stats: dict[str, Any] = {}
    for run in runs:
        path = run / "advisor_stats.json"
        if path.is_file():
            stats[run.name] = json.loads(path.read_text())
    calls = 0
    if episodes.is_file():
        for line in episodes.open():
            record = json.loads(line)
            if record["method"] == "llm-only":
                calls += int(record.get("llm_calls", 0))
    stats["llm-only evaluation calls"] = calls
    return stats
