"""The plan of ``pirl reproduce``: built once, printed from the object, run by one job runner.

:func:`check_reproduce` makes every check ``pirl reproduce`` makes (it refuses before any
folder is made); :func:`make_plan` builds on the checked profile a :class:`Plan`: the runs, the
training still to do with what each job waits for (an imitation run its expert's run, a PIRL
run its teacher's phase), the evaluation tasks and the time estimates. :meth:`Plan.describe`
and :meth:`Plan.status_lines` print it; :func:`pirl.reproduce.schedule.run_plan` trains its
jobs.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from pirl.advice.registry import BUILTIN as BUILTIN_ADVISORS
from pirl.advice.registry import advisor_kind
from pirl.agents.loading import check_act
from pirl.agents.methods import PLANNER, asks, label, trained_method
from pirl.agents.run_folder import RunFolder
from pirl.agents.runs import check_layouts
from pirl.agents.settings import check_budgets, method_steps
from pirl.agents.teacher_phase import TeacherPhase, phase_of
from pirl.config.choices import PareMode, Sim
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig
from pirl.evaluate.runner import EvalPlan, MethodSpec, check_workers, spec_for_builtin, spec_for_run
from pirl.evaluate.scenarios import parse_size
from pirl.reproduce.jobs import TEACHER, TrainJob

Log = Callable[[str], None]
Size = tuple[int, int, int]


# -- the runs of a profile -----------------------------------------------------------------
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


def variant_name(method: str, variant: dict[str, Any]) -> str:
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
                    name = f"{variant_name(entry.name, v)}-s{seed}"
                    plan.append(PlannedRun(name, entry.name, str(v["advisor"]), seed,
                                           tuple(sorted(v.items()))))  # fmt: skip
            else:
                plan.append(PlannedRun(entry.folder(seed), entry.name, "", seed))
    return plan


def teacher_phases(cfg: RunConfig, jobs: list[PlannedRun]) -> dict[str, TeacherPhase]:
    """The teacher phase each PIRL job waits for (by job name); one phase per teacher."""
    out = {}
    for job in jobs:
        if trained_method(job.method).advised:
            phase = phase_of(cfg, dict(job.pare))
            if phase is not None:
                out[job.name] = phase
    return out


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


def steps_text(cfg: RunConfig) -> str:
    """The training budget in words: '409,600 steps', or with each method's own budget
    ('409,600 steps (PPO-EWRI 1,638,400)') when ``train.steps_by_method`` names one; a
    chooser of candidate views counts choices ('PPO-views 262,144 choices')."""
    views = [m for m in cfg.reproduce.methods if trained_method(m).views]
    own = [
        f"{label(name)} {steps:,}"
        for name, steps in cfg.train.steps_by_method.items()
        if steps != cfg.train.total_steps and name not in views
    ]
    own += [
        f"{trained_method(n).short or label(n)} {method_steps(cfg, n):,} choices" for n in views
    ]
    return f"{cfg.train.total_steps:,} steps" + (f" ({', '.join(own)})" if own else "")


# -- the plan ------------------------------------------------------------------------------
@dataclass(frozen=True)
class EvalTasks:
    """What the evaluation step plays once training is done (the trained runs' specs are read
    from their folders then)."""

    builtins: tuple[MethodSpec, ...]
    """The built-in methods (planners, random, LLM-only), each with its advisor."""
    sizes: tuple[Size, ...]
    """Grid sizes every method plays in the grid simulator."""
    sites: tuple[str, ...]
    """Site folders (checked) every method plays beside the sizes."""
    site_sizes: tuple[Size, ...]
    """Each site's grid, what a site costs in the estimate."""
    physics_sizes: tuple[Size, ...]
    """Sizes flown in the physics simulator, in the headline act mode only."""


@dataclass(frozen=True)
class Estimate:
    """About how long each part of a plan takes at :data:`RATES` (finished runs count as
    done)."""

    phase_min: dict[str, float]
    """Each teacher phase's minutes in its one worker, by phase name."""
    train_min: float
    """Training, teacher phases included, spread over the training processes."""
    eval_min: float
    """Evaluation in its worker processes."""
    mission_min: float
    """The missions' flights (0 without ``reproduce.missions``)."""

    @property
    def total_h(self) -> float:
        """Everything, in hours."""
        return (self.train_min + self.eval_min + self.mission_min) / 60


@dataclass(frozen=True)
class Plan:
    """Everything one reproduction does, built once before it starts (:func:`make_plan`),
    printed from here (:meth:`describe`, :meth:`status_lines`) and run by
    :func:`~pirl.reproduce.schedule.run_plan`."""

    cfg: RunConfig
    """The profile."""
    advisor: str
    """PIRL's advisor (a variant in ``reproduce.pirl_variants`` may name its own)."""
    out: Path
    """The output folder: ``runs/``, ``eval/`` and ``report/``."""
    runs: tuple[PlannedRun, ...]
    """Every run of the profile, in plan order (seed by seed, methods as listed)."""
    states: dict[str, str]
    """Each run's folder when planned, by run name: complete, resumable, broken or absent."""
    phases: tuple[TeacherPhase, ...]
    """The teacher phases to run first (one per slow teacher of a PIRL run still to train)."""
    jobs: tuple[TrainJob, ...]
    """The training still to do: the teacher phases, then the runs not complete in plan
    order; each job names the jobs it waits for."""
    evaluation: EvalTasks
    """What the evaluation plays."""
    estimate: Estimate
    """About how long it all takes."""
    train_workers: int
    """Training processes (a pool never gets more than there are jobs)."""
    eval_workers: int
    """Evaluation processes."""

    @property
    def folders(self) -> list[Path]:
        """Every run's folder in plan order: what the evaluation and the report read."""
        return [self.out / "runs" / run.name for run in self.runs]

    def to_train(self) -> int:
        """How many runs still train (finished runs are kept)."""
        return sum(1 for run in self.runs if self.states[run.name] != "complete")

    def describe(self) -> list[str]:
        """What the profile will do and about how long it takes, one ``plan:`` line each."""
        rp, est, ev = self.cfg.reproduce, self.estimate, self.evaluation
        places = len(ev.sizes) + len(ev.sites)
        learned = len(self.runs) * len(rp.acts)
        lines = [self._phase_line(phase) for phase in self.phases]
        lines.append(
            f"plan: {len(self.runs)} training runs ({self.to_train()} to train) of "
            f"{steps_text(self.cfg)}, seeds {list(rp.seeds)}, in {self.train_workers} worker "
            f"processes: about {est.train_min:.0f} min"
        )
        lines.append(
            f"plan: evaluation of {learned * rp.episodes * places:,} episodes of trained "
            f"policies ({rp.episodes} scenarios x {places} sizes and sites x {len(rp.acts)} act "
            f"modes x {len(self.runs)} runs), the built-ins and "
            f"{physics_episodes(self.cfg, len(self.runs))} physics episodes in "
            f"{self.eval_workers} processes: about {est.eval_min:.0f} min"
        )
        if rp.missions and ev.sites:
            names = ", ".join(Path(f).name for f in ev.sites)
            lines.append(
                f"plan: missions on {names}: the planner's and the best learned policy's, "
                f"written and flown back from their files in PyFlyt: about "
                f"{est.mission_min:.0f} min"
            )
        lines.append(
            f"plan: about {est.total_h:.1f} h in all (rates measured on a 2-core machine; "
            "scale by your cores)"
        )
        return lines

    def _phase_line(self, phase: TeacherPhase) -> str:
        waiting = sum(1 for job in self.jobs if job.phase == phase.name)
        return (
            f"plan: teacher phase {phase.name}: the {phase.advisor} teacher answers "
            f"{phase.answers} planner states into the shared teacher dataset (answers already "
            f"there count) in one worker while PPO-SR and PPO-EWRI train: about "
            f"{self.estimate.phase_min[phase.name]:.0f} min; its {waiting} PIRL runs start "
            "after it, with a student past its gate"
        )

    def status_lines(self) -> list[str]:
        """Each job's state before any starts: already trained, or queued (and how it will
        start); a job says ``training`` (or ``resuming``) when it starts."""
        lines = [f"{phase.name}: queued (teacher phase)" for phase in self.phases]
        how = {
            "complete": "already trained",
            "resumable": "queued (resumes from its last checkpoint)",
            "broken": "queued (incomplete with no checkpoint; starts again)",
            "absent": "queued",
        }
        return lines + [f"{run.name}: {how[self.states[run.name]]}" for run in self.runs]

    def eval_plan(self) -> EvalPlan:
        """The evaluation of every run (finished by now) and the built-ins."""
        rp, ev = self.cfg.reproduce, self.evaluation
        return EvalPlan(
            specs=[*map(spec_for_run, self.folders), *ev.builtins],
            sizes=list(ev.sizes),
            episodes=rp.episodes,
            env=self.cfg.env,
            config=self.cfg,
            episodes_per_method={m: rp.llm_only_episodes for m in rp.builtins if asks(m)},
            sims=list(Sim) if ev.physics_sizes else [Sim.GRID],
            sim_sizes={Sim.PHYSICS: list(ev.physics_sizes)},
            sim_episodes={Sim.PHYSICS: rp.physics_episodes},
            acts=list(rp.acts),
            sim_acts={Sim.PHYSICS: [rp.headline_act]},  # the physics simulator flies slowly
            sites=list(ev.sites),
            sim_sites={Sim.PHYSICS: []},  # reproduce.sites: zero-shot in the grid simulator
        )

    def fleet_eval_plan(self) -> EvalPlan | None:
        """The fleets of ``reproduce.uavs`` on the profile's sites: the planner and the runs
        of ``reproduce.fleet_methods``, K = 1 among the sizes (None: no fleets)."""
        rp, ev = self.cfg.reproduce, self.evaluation
        if not rp.uavs:
            return None
        # By the planned method, so `pirl` flies every PIRL variant (pirl-local, pirl-oracle).
        runs = [self.out / "runs" / r.name for r in self.runs if r.method in rp.fleet_methods]
        return EvalPlan(
            specs=[*map(spec_for_run, runs), spec_for_builtin(PLANNER.name)],
            sizes=[],
            episodes=rp.episodes,
            env=self.cfg.env,
            config=self.cfg,
            acts=list(rp.acts),
            sites=list(ev.sites),
            uavs=sorted({1, *rp.uavs}),
        )


@dataclass(frozen=True)
class CheckedProfile:
    """A profile that passed every check of ``pirl reproduce`` (:func:`check_reproduce`), with
    what the checks worked out on the way; :func:`make_plan` builds the plan on it."""

    cfg: RunConfig
    """The profile."""
    advisor: str
    """PIRL's advisor (a variant in ``reproduce.pirl_variants`` may name its own)."""
    workers: int | None
    """Training and evaluation processes asked for; None: the profile's."""
    runs: tuple[PlannedRun, ...]
    """Every run of the profile, in plan order (seed by seed, methods as listed)."""
    sites: tuple[str, ...]
    """``reproduce.sites`` as checked site folders."""


def check_reproduce(cfg: RunConfig, advisor: str, workers: int | None = None) -> CheckedProfile:
    """Everything ``pirl reproduce`` refuses, refused before any folder is made: an unknown
    advisor or one without its key, a bad worker count, an unknown method, advisor or act in
    the profile, an impossible obstacle layout at any of its sizes, a bad site."""
    advisor_kind(advisor).check_key(cfg)
    check_workers(workers)
    runs = plan_runs(cfg, advisor)
    rp = cfg.reproduce
    check_layouts(cfg.env, [cfg.env.size], cfg.ppo.n_envs)
    # The sizes are generated worlds even when the runs train on a site.
    generated = cfg.env.replace(site="", ground_cells=0)
    check_layouts(generated, [*map(parse_size, rp.sizes + rp.physics_sizes)], rp.episodes)
    sites = tuple(profile_sites(cfg))
    if rp.uavs:
        from pirl.evaluate.fleet import check_fleet_starts
        from pirl.world.seeable import with_site

        for name in rp.fleet_methods:  # a method the profile does not train flies no fleet
            trained_method(name, "reproduce.fleet_methods")
        for site in sites:
            check_fleet_starts(with_site(cfg.env, str(site)), max(rp.uavs))
    return CheckedProfile(cfg, advisor, workers, tuple(runs), sites)


def make_plan(profile: CheckedProfile, out: Path) -> Plan:
    """The plan of a reproduction of ``profile`` into ``out``. It reads the run folders already
    there (so ``pirl reproduce`` makes it while it holds the folder's lock) and writes
    nothing. Training and evaluation processes: ``profile.workers``, else
    ``reproduce.train_workers`` (0 = the cores) and ``reproduce.workers``."""
    from pirl.world.site import load_site

    cfg, runs, workers = profile.cfg, list(profile.runs), profile.workers
    rp, out = cfg.reproduce, Path(out)
    states = {run.name: RunFolder(out / "runs" / run.name).state() for run in runs}
    todo = [run for run in runs if states[run.name] != "complete"]
    by_run = teacher_phases(cfg, todo)
    phases = tuple({p.name: p for p in by_run.values()}.values())
    builtins = (spec_for_builtin(m, profile.advisor, rp.llm_only_max_calls) for m in rp.builtins)
    evaluation = EvalTasks(
        builtins=tuple(builtins),
        sizes=tuple(parse_size(s) for s in rp.sizes),
        sites=profile.sites,
        site_sizes=tuple(load_site(folder).size for folder in profile.sites),
        physics_sizes=tuple(parse_size(s) for s in rp.physics_sizes),
    )
    train_workers = workers or rp.train_workers or default_workers()
    eval_workers = workers or rp.workers
    return Plan(
        cfg=cfg,
        advisor=profile.advisor,
        out=out,
        runs=profile.runs,
        states=states,
        phases=phases,
        jobs=(*map(_phase_job, phases), *(_run_job(cfg, out, r, states, by_run) for r in todo)),
        evaluation=evaluation,
        estimate=estimate(cfg, todo, phases, evaluation, len(runs), train_workers, eval_workers),
        train_workers=train_workers,
        eval_workers=eval_workers,
    )


def _phase_job(phase: TeacherPhase) -> TrainJob:
    return TrainJob(phase.name, TEACHER, phase.advisor, 0, pare=phase.pare)


def _run_job(
    cfg: RunConfig,
    out: Path,
    run: PlannedRun,
    states: dict[str, str],
    phases: dict[str, TeacherPhase],
) -> TrainJob:
    entry = trained_method(run.method)
    return TrainJob(
        run.name,
        run.method,
        run.advisor,
        run.seed,
        out / "runs" / run.name,
        states[run.name],
        run.pare,
        expert=entry.expert_folder(run.seed) if entry.expert else "",
        phase=phases[run.name].name if run.name in phases else "",
    )


# -- the estimate --------------------------------------------------------------------------
# Rates on the 2-core development machine, one worker process each, shared with other jobs.
# Measured (quick profile in 2 workers): PPO steps/s at quick's network (262,144
# steps in 45 s: 5,800/s; 5,000 leaves room for a busy machine), PIRL's cost against PPO in
# student mode (157 s with the embedded-LLM teacher, 165 s with the oracle's), grid
# evaluation of trained policies at 3 episodes of 30x30x3 per second and worker, other sizes
# scaling with the area (the demo's 352 grid episodes on 30/45/60 and the campus took 2.1 min
# in 2 workers, loading every run and the batched policy steps included; the 145 episodes/s
# of benchmarks/eval_throughput.py is the batched core alone, which made the plan say
# "0 min"). Estimated, not measured here: an IL run, a physics episode (PyFlyt), one
# embedded-LLM answer for LLM-only, one batch of answers in sync PARE (docs/deviations.md).
# An advised run's cost against PPO, a sync batch's seconds and a teacher phase's answers per
# second are per advisor: its entry in pirl.advice.registry holds them.
RATES: dict[str, Any] = {
    "ppo_steps_per_s": 5000.0,
    "views_choices_per_s": 2000.0,  # ppo-views (a choice flies several steps, offers 8
    # places): 262,144 choices in 113-121 s in the demo's 2 workers
    "il_s": 60.0,
    "eval_eps_per_s": {30: 3.0},
    "physics_s_per_episode": 30.0,
    "llm_only_s_per_call": 1.0,
}


def estimate(
    cfg: RunConfig,
    todo: list[PlannedRun],
    phases: tuple[TeacherPhase, ...],
    evaluation: EvalTasks,
    runs: int,
    train_workers: int,
    eval_workers: int,
) -> Estimate:
    """Minutes of each part: ``todo`` runs and ``phases`` to train, ``runs`` to evaluate."""
    phase_s = {p.name: p.answers / advisor_kind(p.advisor).answers_per_s for p in phases}
    # A phase takes a worker while PPO-SR and PPO-EWRI train.
    train_s = sum(_run_seconds(cfg, run) for run in todo) + sum(phase_s.values())
    eval_s = _eval_seconds(cfg, evaluation, runs)
    return Estimate(
        phase_min={name: s / 60 for name, s in phase_s.items()},
        train_min=train_s / max(1, min(train_workers, len(todo) + len(phases) or 1)) / 60,
        eval_min=eval_s / max(1, eval_workers) / 60,
        mission_min=_mission_minutes(cfg, evaluation),
    )


def _run_seconds(cfg: RunConfig, run: PlannedRun) -> float:
    """One run's training at :data:`RATES`."""
    entry = trained_method(run.method)
    if entry.expert:
        return RATES["il_s"]
    steps = method_steps(cfg, run.method)
    if entry.views:
        return steps / RATES["views_choices_per_s"]
    if not entry.advised:
        return steps / RATES["ppo_steps_per_s"]
    pare = cfg.with_variant(dict(run.pare)).pare
    kind = advisor_kind(run.advisor)
    seconds = steps * kind.train_cost / RATES["ppo_steps_per_s"]
    if pare.mode != PareMode.STUDENT and kind.sync_batch_s:  # every K steps a batch of answers
        seconds += steps / pare.query_every / kind.batch_size(cfg) * kind.sync_batch_s
    return seconds


def physics_episodes(cfg: RunConfig, runs: int) -> int:
    """Episodes in the physics simulator: every run and built-in, headline act mode only."""
    rp = cfg.reproduce
    return (runs + len(rp.builtins)) * rp.physics_episodes * len(rp.physics_sizes)


def _eval_seconds(cfg: RunConfig, evaluation: EvalTasks, runs: int) -> float:
    """The evaluation of ``runs`` runs and the built-ins at :data:`RATES`."""
    rp = cfg.reproduce
    learned = runs * len(rp.acts)
    seconds = physics_episodes(cfg, runs) * RATES["physics_s_per_episode"]
    # A site costs about what a generated world of its grid costs.
    for size in (*evaluation.sizes, *evaluation.site_sizes):
        rate = RATES["eval_eps_per_s"][30] * (30 * 30) / (size[0] * size[1])
        seconds += learned * rp.episodes / rate
        for name in rp.builtins:
            n = rp.llm_only_episodes if asks(name) else rp.episodes
            seconds += n * (4.0 / rate)  # a planner plays episode by episode
            if asks(name):
                seconds += n * (rp.llm_only_max_calls or 200) * RATES["llm_only_s_per_call"]
    return seconds


def _mission_minutes(cfg: RunConfig, evaluation: EvalTasks) -> float:
    """Two flights a site, each about a physics episode per 30x30 cells, one process."""
    if not cfg.reproduce.missions:
        return 0.0
    areas = [size[0] * size[1] for size in evaluation.site_sizes]
    return sum(2 * RATES["physics_s_per_episode"] * a / 900 for a in areas) / 60
