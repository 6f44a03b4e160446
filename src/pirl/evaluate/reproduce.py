"""``pirl reproduce``: train every method that is not trained yet, evaluate all, write the report.

The output folder is the unit of work: ``runs/`` holds one run folder per method and seed,
``eval/`` the evaluation, ``report/`` the report. Finished runs are kept, interrupted ones
resume from their last checkpoint, so an interrupted reproduction picks up where it stopped.
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing as mp
import os
import shutil
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from pathlib import Path
from typing import Any, NamedTuple

from pirl import _quiet
from pirl.advice.registry import BUILTIN as BUILTIN_ADVISORS
from pirl.advice.registry import DEFAULT_ADVISOR, advisor_kind
from pirl.agents import checkpoint
from pirl.agents.loading import BUILTIN, check_act
from pirl.agents.methods import asks, label, trained_method
from pirl.agents.runs import check_budgets, check_layouts, method_steps, train_one
from pirl.agents.teacher_phase import TeacherPhase, phase_of, run_teacher_phase
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig
from pirl.evaluate.runner import (
    EvalPlan,
    MethodSpec,
    check_workers,
    distinct_specs,
    evaluate,
    process_pool,
    spec_for_builtin,
    spec_for_run,
)
from pirl.evaluate.scenarios import parse_size, scenario_seeds
from pirl.evaluate.summary import honest_label

Log = Callable[[str], None]
GIF_SIZE = (30, 30, 3)


def _run_state(run: Path) -> str:
    """'complete', 'resumable', 'broken' (exists, nothing to resume) or 'absent'."""
    meta = run / "meta.json"
    if meta.is_file() and json.loads(meta.read_text()).get("complete"):
        return "complete"
    if checkpoint.latest(run / "checkpoints") is not None:
        return "resumable"
    return "broken" if run.exists() else "absent"


class PlannedRun(NamedTuple):
    """One training run of a reproduction: its folder name, method, advisor, PARE overrides."""

    name: str
    method: str
    advisor: str
    seed: int
    pare: tuple[tuple[str, Any], ...] = ()


def pirl_variants(cfg: RunConfig, advisor: str) -> list[dict[str, Any]]:
    """PARE overrides of each PIRL run per seed: ``reproduce.pirl_variants`` when given (a
    variant without ``advisor`` takes ``advisor``), else PIRL with ``advisor`` and, with
    ``reproduce.oracle_pirl``, PIRL with each built-in advisor that is not an LLM (the
    oracle) beside it. Every advisor named must be a registered one."""
    rp = cfg.reproduce
    if rp.pirl_variants:
        variants = []
        for k, v in enumerate(rp.pirl_variants):
            if not isinstance(v, dict):
                raise ConfigError(f"reproduce.pirl_variants[{k}] must be a mapping of pare keys")
            variants.append({"advisor": advisor, **v})
        for v in variants:  # an unknown key or a bad value is refused before any training
            cfg.with_variant(v)
            advisor_kind(str(v["advisor"]))
        return variants
    advisor_kind(advisor)
    variants = [{"advisor": advisor}]
    if rp.oracle_pirl:
        variants += [{"advisor": k.name} for k in BUILTIN_ADVISORS.values()
                     if not k.llm and k.name != advisor]  # fmt: skip
    return variants


def _variant_name(method: str, variant: dict[str, Any]) -> str:
    """``<method>-<advisor>`` plus the other overrides, e.g. ``pirl-oracle-lamcam4-lammove1``."""
    rest = "-".join(
        f"{k.replace('_', '')}{v}" for k, v in sorted(variant.items()) if k != "advisor"
    )
    return f"{method}-" + str(variant["advisor"]) + (f"-{rest}" if rest else "")


def plan_runs(cfg: RunConfig, advisor: str) -> list[PlannedRun]:
    """Every run of the profile, per seed in the order methods are listed."""
    rp = cfg.reproduce
    entries = [trained_method(m, "reproduce.methods") for m in rp.methods]
    for entry in entries:
        if entry.expert and entry.expert not in rp.methods:
            raise ConfigError(
                f"reproduce.methods: {entry.name} learns from {entry.expert}; list "
                f"{entry.expert} too"
            )
    for act in rp.acts:
        check_act(act)
    if rp.headline_act not in rp.acts:
        raise ConfigError(f"reproduce.headline_act {rp.headline_act!r} is not in acts")
    variants = pirl_variants(cfg, advisor) if any(e.advised for e in entries) else []
    check_budgets(cfg)
    plan = []
    for seed in rp.seeds:
        for entry in entries:
            if entry.advised:
                for v in variants:
                    name = f"{_variant_name(entry.name, v)}-s{seed}"
                    plan.append(PlannedRun(name, entry.name, str(v["advisor"]), seed,
                                           tuple(sorted(v.items()))))  # fmt: skip
            else:
                plan.append(PlannedRun(entry.folder(seed), entry.name, "", seed))
    return plan


def profile_sites(cfg: RunConfig) -> list[str]:
    """``reproduce.sites`` as site folders, each checked (one line for a bad one)."""
    from pirl.world.seeable import with_site
    from pirl.world.site import site_folder

    repo = Path(__file__).resolve().parents[3]
    folders = []
    for name in cfg.reproduce.sites:
        path = Path(name).expanduser()
        if not path.is_absolute() and not path.exists() and (repo / path).exists():
            path = repo / path
        folder = str(site_folder(path).resolve())
        with_site(cfg.env, folder)
        folders.append(folder)
    return folders


def default_workers() -> int:
    """Cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _worker_init() -> None:
    """A training worker's thread budget: one torch thread, one numba thread (set before any
    work), so N workers never run more than N busy threads of their own."""
    os.environ["OMP_NUM_THREADS"] = "1"
    os.environ["MKL_NUM_THREADS"] = "1"
    import numba
    import torch

    torch.set_num_threads(1)
    with contextlib.suppress(RuntimeError):  # already set in this process
        torch.set_num_interop_threads(1)
    numba.set_num_threads(1)
    from pirl import _quiet

    _quiet.install()
    _quiet.ignore_sigint()  # Ctrl-C is the parent's: one line, no worker tracebacks


def _train_job(job: PlannedRun, cfg_dict: dict[str, Any], run: str, resume: bool) -> float:
    start = time.perf_counter()
    cfg = RunConfig.from_dict(cfg_dict)
    if job.method == TEACHER:
        phase = TeacherPhase(job.advisor, job.pare, cfg.reproduce.teacher_phase_answers)
        _log_phase(phase, run_teacher_phase(cfg, phase), print)
    else:
        train_one(job.method, job.advisor, job.seed, cfg, Path(run), resume, False, dict(job.pare))
    return time.perf_counter() - start


def _expert(job: PlannedRun) -> str:
    """The run folder an imitation job waits for (its expert's), or empty."""
    entry = trained_method(job.method)
    return entry.expert_folder(job.seed) if entry.expert else ""


TEACHER = "teacher"
"""The method name of a teacher phase among the training jobs (it has no run folder)."""


def teacher_phases(cfg: RunConfig, jobs: list[PlannedRun]) -> dict[str, TeacherPhase]:
    """The teacher phase each PIRL job waits for (by job name); one phase per teacher."""
    out = {}
    for job in jobs:
        if trained_method(job.method).advised:
            phase = phase_of(cfg, dict(job.pare))
            if phase is not None:
                out[job.name] = phase
    return out


def _log_phase(phase: TeacherPhase, done: dict[str, Any], log: Log) -> None:
    log(
        f"{phase.name}: {done['teacher']} answered {done['asked']} planner states, "
        f"{done['stored']} stored (the dataset had {done['had']}; wanted {phase.answers}) "
        f"in {done['seconds']:.0f} s"
    )


def _phase_jobs(phases: dict[str, TeacherPhase]) -> list[PlannedRun]:
    unique = {p.name: p for p in phases.values()}
    return [PlannedRun(p.name, TEACHER, p.advisor, 0, p.pare) for p in unique.values()]


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
    torch and one numba thread; an IL run starts once its PPO-EWRI expert has finished. With
    ``ray_address`` the runs go to Ray instead. A run trains the same model whichever way.
    """
    from pirl.evaluate.distributed import TrainJob, train_on_ray

    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    finished = []
    todo: list[tuple[PlannedRun, Path, bool]] = []
    for job in plan_runs(cfg, advisor):
        run = runs_dir / job.name
        state = _run_state(run)
        finished.append(run)
        if state == "complete":
            log(f"{job.name}: already trained")
            continue
        if state == "broken":
            log(f"{job.name}: incomplete with no checkpoint; starting again")
            shutil.rmtree(run)
        resume = state == "resumable"
        log(f"{job.name}: {'resuming' if resume else 'training'}")
        todo.append((job, run, resume))
    phases = teacher_phases(cfg, [job for job, _, _ in todo])
    if ray_address:
        for phase in {p.name: p for p in phases.values()}.values():  # here, before the runs
            _log_phase(phase, run_teacher_phase(cfg, phase), log)
        remote = [TrainJob(j.name, j.method, j.advisor, j.seed, r, res, j.pare)
                  for j, r, res in todo]  # fmt: skip
        train_on_ray(ray_address, cfg, remote, log)
        return finished
    workers = workers if workers is not None else (cfg.reproduce.train_workers or default_workers())
    workers = max(1, min(workers, len(todo) + len(_phase_jobs(phases))))
    if workers == 1:
        for phase in {p.name: p for p in phases.values()}.values():
            _log_phase(phase, run_teacher_phase(cfg, phase), log)
        for job, run, resume in sorted(todo, key=lambda t: bool(_expert(t[0]))):
            start = time.perf_counter()
            train_one(job.method, job.advisor, job.seed, cfg, run, resume, show_progress,
                      dict(job.pare))  # fmt: skip
            log(f"{job.name}: done in {time.perf_counter() - start:.0f} s")
        return finished
    _train_parallel(cfg, todo, workers, log, phases)
    return finished


def _train_parallel(
    cfg: RunConfig,
    todo: list[tuple[PlannedRun, Path, bool]],
    workers: int,
    log: Log,
    phases: dict[str, TeacherPhase] | None = None,
) -> None:
    """``todo`` in ``workers`` processes; IL waits for its expert, a PIRL run for its
    teacher's phase (which goes first, beside PPO-SR and PPO-EWRI). Every run goes to its end
    even when another fails (finished runs are kept); then the first failure is raised."""
    cfg_dict = cfg.to_dict()
    phases = phases or {}
    needs: dict[str, str] = {t[0].name: _expert(t[0]) for t in todo if _expert(t[0])}
    needs.update({name: phase.name for name, phase in phases.items()})
    ready = [(j, Path(j.name), False) for j in _phase_jobs(phases)]
    ready += [t for t in todo if t[0].name not in needs]
    waiting = [t for t in todo if t[0].name in needs]
    pending = {t[0].name for t in ready}
    failure: BaseException | None = None
    log(f"training {len(todo)} runs in {workers} worker processes (1 torch + 1 numba thread each)")
    ctx = mp.get_context("spawn")
    with _quiet.QuietProcessPool(workers, mp_context=ctx, initializer=_worker_init) as pool:
        futures: dict[Future, PlannedRun] = {}

        def submit(item: tuple[PlannedRun, Path, bool]) -> None:
            job, run, resume = item
            futures[pool.submit(_train_job, job, cfg_dict, str(run), resume)] = job

        for item in ready:
            submit(item)
        for item in list(waiting):
            if needs[item[0].name] not in pending:  # its prerequisite was done before
                waiting.remove(item)
                submit(item)
        while futures:
            done, _ = wait(futures, return_when=FIRST_COMPLETED)
            for future in done:
                job = futures.pop(future)
                ok = False
                try:
                    log(f"{job.name}: done in {future.result():.0f} s")
                    ok = True
                except Exception as exc:  # noqa: BLE001 - reported, raised after the others
                    log(f"{job.name}: failed ({type(exc).__name__}: {exc})")
                    if job.method != TEACHER:  # a failed head start only slows PIRL down
                        failure = failure or exc
                pending.discard(job.name)
                for item in list(waiting):
                    if needs[item[0].name] != job.name:
                        continue
                    waiting.remove(item)
                    if ok or job.method == TEACHER:
                        submit(item)  # without a head start it still trains, and says so
                    else:
                        log(f"{item[0].name}: not trained (its expert failed)")
    if failure is not None:
        raise failure


# Rates on the 2-core development machine, one worker process each, shared with other jobs.
# Measured (quick profile in 2 workers): PPO steps/s at quick's network (262,144
# steps in 45 s: 5,800/s; 5,000 leaves room for a busy machine), PIRL's cost against PPO in
# student mode (157 s with the embedded-LLM teacher, 165 s with the oracle's), batched grid
# evaluation at 30x30x3 (145 episodes/s, benchmarks/eval_throughput.py; other sizes scale
# with the area). Estimated, not measured here: an IL run, a physics episode (PyFlyt), one
# embedded-LLM answer for LLM-only, one batch of answers in sync PARE (docs/deviations.md).
# An advised run's cost against PPO, a sync batch's seconds and a teacher phase's answers per
# second are per advisor: its entry in pirl.advice.registry holds them.
RATES: dict[str, Any] = {
    "ppo_steps_per_s": 5000.0,
    "il_s": 60.0,
    "eval_eps_per_s": {30: 145.0},
    "physics_s_per_episode": 30.0,
    "llm_only_s_per_call": 1.0,
}


def steps_text(cfg: RunConfig) -> str:
    """The training budget in words: '409,600 steps', or with each method's own budget
    ('409,600 steps (PPO-EWRI 1,638,400)') when ``train.steps_by_method`` names one."""
    own = [
        f"{label(name)} {steps:,}"
        for name, steps in cfg.train.steps_by_method.items()
        if steps != cfg.train.total_steps
    ]
    return f"{cfg.train.total_steps:,} steps" + (f" ({', '.join(own)})" if own else "")


def describe_plan(
    cfg: RunConfig, advisor: str, out: Path, train_workers: int, eval_workers: int
) -> list[str]:
    """What the profile will do and about how long it takes, before it starts: runs and steps,
    episodes per phase, and estimated minutes from :data:`RATES` (already finished runs
    count as done)."""
    rp, r = cfg.reproduce, RATES
    jobs = plan_runs(cfg, advisor)
    todo = [j for j in jobs if _run_state(Path(out) / "runs" / j.name) != "complete"]
    ppo_s = 0.0
    for j in todo:
        entry = trained_method(j.method)
        if entry.expert:
            ppo_s += r["il_s"]
        elif not entry.advised:
            ppo_s += method_steps(cfg, j.method) / r["ppo_steps_per_s"]
        else:
            pare = cfg.with_variant(dict(j.pare)).pare
            kind = advisor_kind(j.advisor)
            steps = method_steps(cfg, j.method)
            ppo_s += steps * kind.train_cost / r["ppo_steps_per_s"]
            if pare.mode != "student" and kind.sync_batch_s:  # every K steps an answer
                batches = steps / pare.query_every / kind.batch_size(cfg)
                ppo_s += batches * kind.sync_batch_s
    phases = {p.name: p for p in teacher_phases(cfg, todo).values()}
    phase_lines = []
    for phase in phases.values():
        seconds = phase.answers / advisor_kind(phase.advisor).answers_per_s
        ppo_s += seconds  # it takes a worker while PPO-SR and PPO-EWRI train
        waiting = sum(1 for j in todo if trained_method(j.method).advised
                      and phase_of(cfg, dict(j.pare)))  # fmt: skip
        phase_lines.append(
            f"plan: teacher phase {phase.name}: the {phase.advisor} teacher answers "
            f"{phase.answers} planner states into the shared teacher dataset (answers already "
            f"there count) in one worker while PPO-SR and PPO-EWRI train: about "
            f"{seconds / 60:.0f} min; its {waiting} PIRL runs start after it, with a student "
            "past its gate"
        )
    train_min = ppo_s / max(1, min(train_workers, len(todo) + len(phases) or 1)) / 60
    sizes = [parse_size(s) for s in rp.sizes]
    from pirl.world.site import load_site

    # A site costs about what a generated world of its grid costs.
    sizes += [load_site(folder).size for folder in profile_sites(cfg)]
    learned = len(jobs) * len(rp.acts)
    eval_s = 0.0
    for size in sizes:
        rate = r["eval_eps_per_s"][30] * (30 * 30) / (size[0] * size[1])
        eval_s += learned * rp.episodes / rate
        for name in rp.builtins:
            n = rp.llm_only_episodes if asks(name) else rp.episodes
            eval_s += n * (4.0 / rate)  # a planner plays episode by episode
            if asks(name):
                calls = rp.llm_only_max_calls or 200
                eval_s += n * calls * r["llm_only_s_per_call"]
    physics_eps = (len(jobs) + len(rp.builtins)) * rp.physics_episodes  # headline act only
    physics_eps *= len(rp.physics_sizes)
    eval_s += physics_eps * r["physics_s_per_episode"]
    eval_min = eval_s / max(1, eval_workers) / 60
    total_eval = learned * rp.episodes * len(sizes)
    mission_lines, mission_min = [], 0.0
    if rp.missions and profile_sites(cfg):
        # Two flights a site, each about a physics episode per 30x30 cells, one process.
        areas = [load_site(f).size[0] * load_site(f).size[1] for f in profile_sites(cfg)]
        mission_min = sum(2 * r["physics_s_per_episode"] * a / 900 for a in areas) / 60
        names = ", ".join(Path(f).name for f in profile_sites(cfg))
        mission_lines.append(
            f"plan: missions on {names}: the planner's and the best learned policy's, written "
            f"and flown back from their files in PyFlyt: about {mission_min:.0f} min"
        )
    return [
        *phase_lines,
        f"plan: {len(jobs)} training runs ({len(todo)} to train) of {steps_text(cfg)}, "
        f"seeds {list(rp.seeds)}, in {train_workers} worker processes: about "
        f"{train_min:.0f} min",
        f"plan: evaluation of {total_eval:,} episodes of trained policies "
        f"({rp.episodes} scenarios x {len(sizes)} sizes and sites x {len(rp.acts)} act modes x "
        f"{len(jobs)} runs), the built-ins and {physics_eps} physics episodes in "
        f"{eval_workers} processes: about {eval_min:.0f} min",
        *mission_lines,
        f"plan: about {(train_min + eval_min + mission_min) / 60:.1f} h in all (rates measured "
        "on a 2-core "
        "machine; scale by your cores)",
    ]


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
        if name in ("llm-only", "boustrophedon")  # the random walk's animation shows nothing
    ]
    cfg_dict = cfg.to_dict()
    return [
        pool.submit(_record_gif, spec, cfg_dict, seed, folder / f"{spec.key}.gif")
        for spec in distinct_specs(specs)
    ]


def check_reproduce(cfg: RunConfig, advisor: str, workers: int | None = None) -> None:
    """Everything ``pirl reproduce`` refuses, refused before any folder is made: an unknown
    advisor or one without its key, a bad worker count, an unknown method, advisor or act in
    the profile, an impossible obstacle layout at any of its sizes."""
    advisor_kind(advisor).check_key(cfg)
    check_workers(workers)
    plan_runs(cfg, advisor)
    rp = cfg.reproduce
    check_layouts(cfg.env, [cfg.env.size], cfg.ppo.n_envs)
    check_layouts(cfg.env, [*map(parse_size, rp.sizes + rp.physics_sizes)], rp.episodes)
    profile_sites(cfg)


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
    """The main job. Returns the path of ``report.html``.

    ``workers`` training processes at once (default ``reproduce.train_workers``, 0 = the
    cores) and evaluation processes (default ``reproduce.workers``). ``ray_address`` sends
    training runs and evaluation episodes to Ray (``pirl[distributed]``).
    """
    from pirl.agents.run_folder import git_commit
    from pirl.evaluate.report import write_report

    check_reproduce(cfg, advisor, workers)
    out = Path(out)
    rp = cfg.reproduce
    train_workers = workers or rp.train_workers or default_workers()
    for line in describe_plan(cfg, advisor, out, train_workers, workers or rp.workers):
        log(line)
    started = time.perf_counter()
    runs = train_all(cfg, out, advisor, log, show_progress, ray_address, train_workers)
    trained_s = time.perf_counter() - started
    specs = [spec_for_run(r) for r in runs]
    specs += [spec_for_builtin(name, advisor, rp.llm_only_max_calls) for name in rp.builtins]
    plan = EvalPlan(
        specs=specs,
        sizes=[parse_size(s) for s in rp.sizes],
        episodes=rp.episodes,
        env=cfg.env,
        config=cfg,
        episodes_per_method={m: rp.llm_only_episodes for m in rp.builtins if asks(m)},
        sims=["grid", "physics"] if rp.physics_sizes else ["grid"],
        sim_sizes={"physics": [parse_size(x) for x in rp.physics_sizes]},
        sim_episodes={"physics": rp.physics_episodes},
        acts=list(rp.acts),
        sim_acts={"physics": [rp.headline_act]},  # the physics simulator flies slowly
        sites=profile_sites(cfg),
    )
    where = [*map(str, rp.sizes), *(f"site {Path(s).name}" for s in plan.sites)]
    log(f"evaluating {len(specs)} methods on {', '.join(where)}")
    # The animations record in processes of their own beside the evaluation's.
    with process_pool(workers or rp.workers) as gif_pool:
        gif_jobs = start_gifs(gif_pool, cfg, runs, advisor, out / "report" / "gifs")
        summary = evaluate(
            plan, out / "eval", workers or rp.workers, progress=progress, ray_address=ray_address
        )
        gifs = dict(job.result() for job in gif_jobs)
    stats = _advisor_stats(runs, out / "eval" / "episodes.jsonl", log)
    notes = [
        f"Profile values: {rp.episodes} scenarios per size ({rp.llm_only_episodes} for "
        f"LLM-only), training seeds {list(rp.seeds)}, {steps_text(cfg)} per PPO run; "
        f"physics simulator: {rp.physics_episodes} scenarios on "
        f"{', '.join(rp.physics_sizes) or 'no size'}. "
        f"Training took {trained_s / 60:.1f} min ({train_workers} worker processes), "
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
        from pirl.evaluate.mission_report import reproduction_missions

        records = [json.loads(line) for line in (out / "eval" / "episodes.jsonl").open()]
        missions = reproduction_missions(cfg, out, plan.sites, records, log)
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
    from pirl.evaluate.advice_curve import CurveAdvisor, curve_points, plot, section
    from pirl.evaluate.advice_score import score_advisor

    rp = cfg.reproduce
    folder = out / "report" / "scores"
    folder.mkdir(parents=True, exist_ok=True)
    records = [json.loads(line) for line in (out / "eval" / "episodes.jsonl").open()]
    by_name = {r.name: r for r in runs}
    advisors = []
    for variant in pirl_variants(cfg, advisor):
        name = _variant_name("pirl", variant)
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
    return f"Agents: {masks}; {seen}{starts} (docs/deviations.md)."


def _advisor_stats(
    runs: list[Path], episodes: Path, log: Callable[[str], None] = print
) -> dict[str, Any]:
    """Each run's ``advisor_stats.json`` by run name (a damaged one is named in one line and
    recorded as ``{"damaged": reason}``, so the report still comes out and says so), and the
    LLM-only evaluation's calls."""
    stats: dict[str, Any] = {}
    for run in runs:
        path = run / "advisor_stats.json"
        if path.is_file():
            try:
                found = json.loads(path.read_text())
                if not isinstance(found, dict):
                    raise ValueError("not a JSON object")
            except (OSError, ValueError) as exc:
                reason = f"{path} is damaged ({type(exc).__name__})"
                log(f"warning: {reason}; the report's advice table leaves this run out")
                stats[run.name] = {"damaged": reason, "source": str(run)}
                continue
            stats[run.name] = {**found, "source": str(run)}
    calls = 0
    if episodes.is_file():
        for line in episodes.open():
            record = json.loads(line)
            if asks(record["method"]):
                calls += int(record.get("llm_calls", 0))
    stats["llm-only evaluation calls"] = calls
    return stats
