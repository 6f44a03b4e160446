"""``pirl reproduce``: train every method that is not trained yet, evaluate all, write the report.

The output folder is the unit of work: ``runs/`` holds one run folder per method and seed,
``eval/`` the evaluation, ``report/`` the report. Finished runs are kept, interrupted ones
resume from their last checkpoint, so an interrupted reproduction picks up where it stopped.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from concurrent.futures import Executor, Future
from pathlib import Path
from typing import Any

from pirl import _quiet
from pirl.advice.registry import DEFAULT_ADVISOR
from pirl.agents.loading import BUILTIN
from pirl.agents.methods import ADVISED, asks, method
from pirl.agents.run_folder import RunFolder, folder_lock
from pirl.config.errors import UserError
from pirl.config.presets import load_preset, preset_path
from pirl.config.run import RunConfig
from pirl.evaluate.runner import (
    MethodSpec,
    distinct_specs,
    evaluate,
    process_pool,
    spec_for_builtin,
    spec_for_run,
)
from pirl.evaluate.scenarios import scenario_seeds
from pirl.evaluate.summary import honest_label
from pirl.reproduce.plan import (
    Log,
    Plan,
    check_reproduce,
    make_plan,
    pirl_variants,
    steps_text,
    variant_name,
)
from pirl.reproduce.schedule import executor_for, run_plan

GIF_SIZE = (30, 30, 3)


def train_all(
    cfg: RunConfig,
    out: Path,
    advisor: str,
    log: Log,
    show_progress: bool = True,
    ray_address: str | None = None,
    workers: int | None = None,
) -> list[Path]:
    """Train (or resume, or skip) every run of :func:`plan_runs`; returns the run folders.

    With ``workers`` > 1 the runs train in that many spawned processes at once, each with one
    torch and one numba thread; with ``ray_address`` they go to Ray instead. A run trains the
    same model whichever way (:func:`~pirl.reproduce.schedule.run_plan`).
    """
    checked = check_reproduce(cfg, advisor, workers)  # refused before any folder is made
    with folder_lock(Path(out)):  # the plan reads the run folders already there
        plan = make_plan(checked, Path(out))
        for line in plan.status_lines():
            log(line)
        run_plan(plan, executor_for(plan, ray_address), log, show_progress)
    return plan.folders


def _record_gif(
    spec: MethodSpec, cfg_dict: dict[str, Any], seed: int, path: Path
) -> tuple[str, Path]:
    """One animation (in a worker process): ``spec`` on the 30x30x3 scenario ``seed``, a
    trained policy acting in the headline act mode. Returns (caption, GIF path)."""
    import torch

    from pirl.advice.factory import make_advisor
    from pirl.agents.loading import load_policy
    from pirl.env.vcpp_env import VCPPEnv
    from pirl.evaluate.rollout import run_episode, save_gif

    _quiet.install()
    torch.set_num_threads(1)  # beside the evaluation's workers, one core's share each
    cfg = RunConfig.from_dict(cfg_dict)
    env = VCPPEnv(cfg.env.replace(size=GIF_SIZE, render_cell_px=8), render_mode="rgb_array")
    act = cfg.reproduce.headline_act
    adv = make_advisor(spec.advisor, cfg) if spec.advisor else None
    policy = load_policy(
        spec.source,
        advisor=adv,
        seed=0,
        max_calls=spec.max_calls,
        prompt_variant=cfg.pare.prompt_variant,
        act=act,
    )
    result = run_episode(env, policy, seed, record=True, frame_every=cfg.reproduce.gif_every)
    how = f", act {act}" if spec.source not in BUILTIN else ""
    caption = f"{honest_label(spec.label, [spec.source])}{how}: VCR {result.metrics['vcr']:.2f}"
    return caption, save_gif(result.frames, path, fps=12)


def start_gifs(
    pool: Executor, cfg: RunConfig, runs: list[Path], advisor: str, folder: Path
) -> list[Future]:
    """Submit one animation per method to ``pool``, all on the same 30x30x3 scenario (the
    first evaluation seed), trained policies from the first training seed; each future gives
    (caption, GIF path)."""
    seed = scenario_seeds(GIF_SIZE, 1)[0]
    specs = [spec_for_run(r) for r in runs if r.name.endswith(f"-s{cfg.reproduce.seeds[0]}")]
    specs += [
        spec_for_builtin(name, advisor, cfg.reproduce.llm_only_max_calls)
        for name in cfg.reproduce.builtins
        if method(name).animated
    ]
    cfg_dict = cfg.to_dict()
    return [
        pool.submit(_record_gif, spec, cfg_dict, seed, folder / f"{spec.key}.gif")
        for spec in distinct_specs(specs)
    ]


def reproduce_settings(
    profile: str,
    config: Path | None = None,
    seeds: list[int] | None = None,
    out: Path | None = None,
    advisor: str | None = None,
) -> tuple[Path, RunConfig, Path, str]:
    """What ``pirl reproduce`` runs: (the preset's path, the preset, the output folder, the
    advisor). The preset is ``config`` when given, else the ``profile``'s, with ``seeds``,
    when given, as ``reproduce.seeds``; ``out`` defaults to ``results/<profile>`` and
    ``advisor`` to the preset's."""
    path = preset_path(config, "--config") if config else preset_path(profile, "--profile")
    cfg = load_preset(path)
    if seeds:
        cfg = cfg.with_overrides(reproduce={"seeds": list(seeds)})
    return path, cfg, out or Path("results") / profile, advisor or cfg.pare.advisor


def reproduce(
    cfg: RunConfig,
    out: Path,
    advisor: str = DEFAULT_ADVISOR,
    workers: int | None = None,
    log: Log = print,
    progress: Callable[[int, int], None] | None = None,
    show_progress: bool = True,
    ray_address: str | None = None,
) -> Path:
    """The main job (``pirl reproduce``, ``pirl demo``). Returns the path of ``report.html``.

    Everything the profile can be refused for is checked before any folder is made; then,
    under ``out``'s lock (a second reproduction into the same folder is refused), the plan
    is made from the run folders already there and run. ``workers`` training processes at
    once (default ``reproduce.train_workers``, 0 = the cores) and evaluation processes
    (default ``reproduce.workers``). ``ray_address`` sends training runs and evaluation
    episodes to Ray (``pirl[distributed]``).
    """
    checked = check_reproduce(cfg, advisor, workers)
    with folder_lock(Path(out)):
        return run_reproduction(
            make_plan(checked, Path(out)), log=log, progress=progress,
            show_progress=show_progress, ray_address=ray_address,
        )  # fmt: skip


def run_reproduction(
    plan: Plan,
    log: Log = print,
    progress: Callable[[int, int], None] | None = None,
    show_progress: bool = True,
    ray_address: str | None = None,
) -> Path:
    """Print ``plan``, train its jobs (with Ray at ``ray_address``, else its workers), evaluate
    every run and the built-ins, write the report. Returns the path of ``report.html``."""
    from pirl.agents.run_folder import git_commit
    from pirl.env.core import compile_kernels
    from pirl.report.document import write_report

    cfg, out, advisor, rp = plan.cfg, plan.out, plan.advisor, plan.cfg.reproduce
    for line in plan.describe() + plan.status_lines():
        log(line)
    started = time.perf_counter()
    # Compiled here once, so the workers that start together load the kernels, not each
    # compile them (a fresh machine or a new version: ~25 CPU-s per process saved).
    compile_kernels()
    run_plan(plan, executor_for(plan, ray_address), log, show_progress)
    trained_s = time.perf_counter() - started
    runs = plan.folders
    evaluation = plan.eval_plan()
    where = [*map(str, rp.sizes), *(f"site {Path(s).name}" for s in evaluation.sites)]
    log(f"evaluating {len(evaluation.specs)} methods on {', '.join(where)}")
    # The animations record in processes of their own beside the evaluation's.
    with process_pool(plan.eval_workers) as gif_pool:
        gif_jobs = start_gifs(gif_pool, cfg, runs, advisor, out / "report" / "gifs")
        summary = evaluate(
            evaluation, out / "eval", plan.eval_workers, progress=progress, ray_address=ray_address
        )
        gifs = dict(job.result() for job in gif_jobs)
    fleets = plan.fleet_eval_plan()
    fleet_summary = None
    if fleets is not None:
        sites = ", ".join(Path(s).name for s in fleets.sites)
        log(f"flying fleets of {', '.join(map(str, fleets.uavs))} UAVs on {sites}")
        fleet_summary = evaluate(
            fleets, out / "eval-fleets", plan.eval_workers, ray_address=ray_address
        )
    stats = _advisor_stats(runs, out / "eval" / "episodes.jsonl", log)
    notes = [
        f"Profile values: {rp.episodes} scenarios per size ({rp.llm_only_episodes} for "
        f"LLM-only), training seeds {list(rp.seeds)}, {steps_text(cfg)} per PPO run; "
        f"physics simulator: {rp.physics_episodes} scenarios on "
        f"{', '.join(rp.physics_sizes) or 'no size'}. "
        f"Training took {trained_s / 60:.1f} min ({plan.train_workers} worker processes), "
        f"everything {(time.perf_counter() - started) / 60:.1f} min.",
        f"Trained policies are evaluated acting {' and '.join(rp.acts)}; the headline mode is "
        f"{rp.headline_act} for every trained method (docs/results.md says why).",
        "Advisors other than an LLM (the oracle) and planners are labelled as such.",
        settings_line(cfg),
    ]
    extras = []
    if rp.score_states:
        extras.append(
            ("PIRL by advice quality", *advice_quality(cfg, out, advisor, runs, stats, log))
        )
    if rp.missions:
        from pirl.report.missions import reproduction_missions

        records = [json.loads(line) for line in (out / "eval" / "episodes.jsonl").open()]
        missions = reproduction_missions(cfg, out, evaluation.sites, records, log)
        if missions is not None:
            extras.append(missions)
    return write_report(
        out / "report",
        summary,
        runs,
        gifs,
        stats,
        code_version=git_commit(),
        notes=notes,
        headline_act=rp.headline_act,
        extras=extras,
        fleet_summary=fleet_summary,
    )


def advice_quality(
    cfg: RunConfig,
    out: Path,
    advisor: str,
    runs: list[Path],
    stats: dict[str, Any],
    log: Log = print,
) -> tuple[str, Path]:
    """The advice-quality curve of a reproduction (``reproduce.score_states`` > 0): each PIRL
    variant's advisor scored against the oracle (``pirl advise --score``, kept in
    ``report/scores/``: a rerun reuses them), its runs' VCR by that measured agreement, and
    the markdown section with the break-even. Returns (section, figure)."""
    from pirl.advice.factory import make_advisor
    from pirl.agents.pirl_advice import shaped_share
    from pirl.evaluate.advice_score import score_advisor
    from pirl.report.advice_curve import CurveAdvisor, curve_points, plot, section

    rp = cfg.reproduce
    folder = out / "report" / "scores"
    folder.mkdir(parents=True, exist_ok=True)
    records = [json.loads(line) for line in (out / "eval" / "episodes.jsonl").open()]
    by_name = {r.name: r for r in runs}
    advisors = []
    for variant in pirl_variants(cfg, advisor):
        name = variant_name(ADVISED.name, variant)
        path = folder / f"{name}.json"
        vcfg = cfg.with_variant(variant)
        score = json.loads(path.read_text()) if path.is_file() else {}
        if score.get("states") != rp.score_states:
            log(f"scoring {name}'s advisor on {rp.score_states} validation states")
            adv = make_advisor(str(variant["advisor"]), vcfg, cache=True)
            try:
                score = score_advisor(adv, vcfg, rp.score_states).to_dict()
            finally:
                adv.close()
            path.write_text(json.dumps(score, indent=2))
        own = [by_name[f"{name}-s{seed}"] for seed in rp.seeds if f"{name}-s{seed}" in by_name]
        shares = [shaped_share(stats[r.name]) for r in own if "steps" in stats.get(r.name, {})]
        label = score["advisor"]
        advisors.append(
            CurveAdvisor(
                label,
                float(score["agreement_move"]),
                float(score["kappa_move"]),
                frozenset(str(r) for r in own),
                sum(shares) / len(shares) if shares else None,
            )  # fmt: skip
        )
    baseline = frozenset(str(r) for r in runs if r.name.startswith("ppo-ewri-"))
    act = rp.headline_act
    points, band = curve_points(records, advisors, baseline, act)
    figure = plot(points, band, out / "report" / "advice_quality.png", act,
                  f"PIRL by advice quality ({len(rp.seeds)} seeds; student mode)")  # fmt: skip
    return section(points, band, act), figure


def settings_line(cfg: RunConfig) -> str:
    """The agent settings that differ from the paper's, in one sentence for the report."""
    env = cfg.env
    named = (
        ("visit counts", env.obs_visits),
        ("way to the nearest uncovered cell", env.obs_target and not env.obs_target_path),
        ("path round obstacles to the nearest uncovered cell", env.obs_target_path),
        ("steps since coverage last grew", env.obs_stall),
    )
    blocks = [name for name, on in named if on]
    masks = (
        "trained and evaluated with valid-action masks (sb3-contrib MaskablePPO)"
        if cfg.ppo.action_masking
        else "no action masks (the paper's action space)"
    )
    seen = (
        f"observation with {' and '.join(blocks)} beyond the paper's"
        if blocks
        else "the paper's observation"
    )
    starts = (
        f"; training episodes start at random camera poses ({cfg.train.camera_start}; "
        "evaluation at the paper's)"
        if cfg.train.camera_start != "fixed"
        else ""
    )
    guard = (
        f"; the env's stall guard on: after {env.stall_guard} steps without new coverage it "
        "leads the UAV to the nearest uncovered ground, for every method (the camera table "
        "gives the share of steps it chose)"
        if env.stall_guard
        else ""
    )
    return f"Agents: {masks}; {seen}{starts}{guard} (docs/deviations.md)."


def _advisor_stats(
    runs: list[Path], episodes: Path, log: Callable[[str], None] = print
) -> dict[str, Any]:
    """Each run's ``advisor_stats.json`` by run name (a damaged one is named in one line and
    recorded as ``{"damaged": reason}``, so the report still comes out and says so), and the
    LLM-only evaluation's calls."""
    stats: dict[str, Any] = {}
    for run in runs:
        try:
            found = RunFolder(run).advisor_stats
        except UserError as exc:
            log(f"warning: {exc}; the report's advice table leaves this run out")
            stats[run.name] = {"damaged": str(exc), "source": str(run)}
            continue
        if found is not None:
            stats[run.name] = {**found, "source": str(run)}
    calls = 0
    if episodes.is_file():
        for line in episodes.open():
            record = json.loads(line)
            if asks(record["method"]):
                calls += int(record.get("llm_calls", 0))
    stats["llm-only evaluation calls"] = calls
    return stats
