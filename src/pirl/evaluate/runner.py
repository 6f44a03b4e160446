"""Run every method on every scenario of every size, in parallel worker processes.

``evaluate()`` is what ``pirl evaluate`` calls. Each (method, size, act mode) is cut into
chunks of scenario seeds; a worker loads the method's policy once and plays its chunk. On the
grid a trained policy plays its whole chunk at once (one batched world, one policy forward
per step); planners and the physics simulator play episode by episode. Records are sorted
before writing, so the output depends neither on the number of workers nor on batching.

Trained policies act ``stochastic`` (sampled, seeded per scenario) and/or ``greedy``; the
built-ins (planners, LLM-only, random) act by their own rule and are played once, with act
``fixed``.
"""

from __future__ import annotations

import json
import math
import multiprocessing as mp
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from pirl import _quiet
from pirl._atomic import replacing
from pirl.advice.registry import DEFAULT_ADVISOR, builtin_of_label, find_advisor_kind
from pirl.agents.loading import ACT_MODES, BUILTIN, check_act
from pirl.agents.methods import METHODS, TRAIN_IMITATION, advised_key, asks, is_advised_key, label
from pirl.agents.run_folder import RunFolder
from pirl.config.choices import Sim
from pirl.config.errors import ConfigError
from pirl.config.physics import PhysicsConfig
from pirl.config.run import RunConfig
from pirl.config.world import OBS_BLOCKS, VCPPConfig
from pirl.evaluate.scenarios import scenario_seeds, size_name
from pirl.evaluate.summary import SITE_PREFIX, write_summary

SIMS = tuple(Sim)
FIXED = "fixed"  # the act of built-in methods: they act by their own rule in both modes


def parse_acts(text: str | list[str]) -> list[str]:
    """'both' -> both modes; 'greedy' -> ['greedy']; a list is checked as it is."""
    words = [text] if isinstance(text, str) else list(text)
    if words == ["both"]:
        return list(ACT_MODES)
    return [check_act(w) for w in words]


@dataclass(frozen=True)
class MethodSpec:
    """One method to evaluate: a finished run folder or a built-in method."""

    key: str
    label: str
    source: str
    train_seed: int | None = None
    advisor: str | None = None
    max_calls: int = 0


def run_label(meta: dict[str, Any]) -> str:
    """A run's full label: ``meta["label"]`` when the run records one, else derived from its
    method and advisor (an advisor that is not an LLM, the oracle, is labelled as such)."""
    if meta.get("label"):
        return str(meta["label"])
    method = str(meta["method"])
    advisor = str(meta.get("advisor") or "")
    entry = METHODS.get(method)
    if entry is not None and entry.advised and advisor:
        kind = builtin_of_label(advisor)
        if kind is not None and not kind.llm:
            return f"{entry.label} ({kind.name} advisor, not an LLM)"
        return f"{entry.label} ({advisor})"
    return label(method)


def spec_for_run(run: Path) -> MethodSpec:
    """The spec of a finished run, labelled by :func:`run_label`; an advised run whose advisor
    is not an LLM (PIRL with the oracle) has its own key. Runs sharing a key but not a label
    are told apart by :func:`evaluate`."""
    folder = RunFolder(run)
    meta = folder.finished_meta()
    folder.model_file()  # a missing or damaged model is reported here, before any work
    method = str(meta["method"])
    entry = METHODS.get(method)
    advised = entry is not None and entry.advised
    key = advised_key(method, folder.advisor) if advised else method
    return MethodSpec(key, run_label(meta), str(run), meta.get("seed"), None)


def spec_for_builtin(name: str, advisor: str | None = None, max_calls: int = 0) -> MethodSpec:
    if name not in BUILTIN:
        raise ConfigError(f"method {name!r}: built-in methods are {', '.join(BUILTIN)}")
    text = label(name)
    if not asks(name):
        return MethodSpec(name, text, name)
    advisor = advisor or DEFAULT_ADVISOR
    kind = find_advisor_kind(advisor)
    llm = kind is None or kind.llm
    text = f"{text} ({advisor})" if llm else f"{text} ({advisor}, not an LLM)"
    if max_calls:
        text += f", at most {max_calls} calls per episode"
    return MethodSpec(name, text, name, None, advisor, max_calls)


@dataclass
class EvalPlan:
    """What to evaluate and how.

    ``sim_sizes`` and ``sim_episodes`` override ``sizes`` and ``episodes`` for one simulator
    (the physics simulator is far slower than the grid). A method's own episode count
    (``episodes_per_method``) caps either.
    """

    specs: list[MethodSpec]
    sizes: list[tuple[int, int, int]]
    episodes: int
    sims: list[str] = field(default_factory=lambda: ["grid"])
    env: VCPPConfig = field(default_factory=VCPPConfig)
    config: RunConfig = field(default_factory=RunConfig)
    episodes_per_method: dict[str, int] = field(default_factory=dict)
    sim_sizes: dict[str, list[tuple[int, int, int]]] = field(default_factory=dict)
    sites: list[str] = field(default_factory=list)
    """Site folders evaluated beside the sizes."""
    sim_sites: dict[str, list[str]] = field(default_factory=dict)
    """Site folders per simulator, overriding ``sites`` (``pirl reproduce`` judges its sites
    in the grid simulator only)."""
    sim_episodes: dict[str, int] = field(default_factory=dict)
    acts: list[str] = field(default_factory=lambda: ["greedy"])
    sim_acts: dict[str, list[str]] = field(default_factory=dict)
    """Act modes per simulator, overriding ``acts`` (the physics simulator is slow)."""
    batched: bool = True
    """Grid episodes of a trained policy run batched (one forward per step for all scenarios
    of a chunk); False plays them one by one (the same results, slower)."""
    uavs: list[int] = field(default_factory=lambda: [1])
    """Fleet sizes. ``[1]`` plays today's single UAV; any other list plays every size as a
    fleet (K = 1 included, so every row has the fleet's makespans and speed-ups divide by
    K = 1 from the same seed), on the grid only (:mod:`pirl.evaluate.fleet`)."""


# -- worker side ---------------------------------------------------------------------------
_POLICIES: dict[tuple, Any] = {}


def _file_identity(source: str) -> tuple:
    """A run's policy files as they are now (see :meth:`RunFolder.file_identity`)."""
    return () if source in BUILTIN else RunFolder(Path(source)).file_identity()


def _policy(spec: MethodSpec, config: RunConfig) -> Any:
    from pirl.agents.loading import load_policy

    cache_key = (spec.key, spec.source, spec.advisor, spec.max_calls, _file_identity(spec.source))
    if cache_key not in _POLICIES:
        advisor = None
        if spec.advisor is not None:
            from pirl.advice.factory import make_advisor

            advisor = make_advisor(spec.advisor, config)
        _POLICIES[cache_key] = load_policy(
            spec.source,
            advisor=advisor,
            seed=0,
            max_calls=spec.max_calls,
            prompt_variant=config.pare.prompt_variant,
        )
    return _POLICIES[cache_key]


def run_chunk(
    spec: MethodSpec,
    env_dict: dict[str, Any],
    config_dict: dict[str, Any],
    size: tuple[int, int, int] | str,
    sim: str,
    seeds: list[int],
    act: str = FIXED,
    batched: bool = True,
    uavs: int | None = None,
) -> list[dict[str, Any]]:
    """Play ``spec`` on each seed of ``size`` (or of the site folder ``size`` names) acting
    ``act``; one record per episode. ``uavs`` plays a fleet of that many UAVs
    (:func:`~pirl.evaluate.fleet.run_fleet_episode`); None the single UAV."""
    from pirl import _quiet
    from pirl.agents.loading import LearnedPolicy
    from pirl.env.vcpp_env import VCPPEnv
    from pirl.evaluate.rollout import run_batch, run_episode

    _quiet.install()  # a worker process: no third-party banners or deprecation noise
    if sim == Sim.PHYSICS:
        _quiet.import_quietly("pybullet")
    config = RunConfig.from_dict(config_dict)
    # Evaluation scenarios start at the env's camera pose, whatever a run trained from.
    env_cfg = VCPPConfig.from_dict(env_dict).replace(start_camera="fixed")
    where: dict[str, Any]
    if isinstance(size, str):
        from pirl.world.seeable import with_site
        from pirl.world.site import load_site

        env_cfg = with_site(env_cfg, size)
        name = load_site(size).name
        where = {"size": SITE_PREFIX + name, "site": name, "grid": size_name(env_cfg.size)}
    else:
        env_cfg = env_cfg.replace(size=tuple(size))
        where = {"size": size_name(size)}
    if spec.source not in BUILTIN or spec.advisor is not None:  # a network plays: one
        # core's share (a planner or random policy plays without torch: ~3 CPU-s less)
        import torch

        torch.set_num_threads(1)
    policy = _policy(spec, config)
    if act != FIXED:
        policy.set_act(act)
    if uavs is not None:
        from pirl.evaluate.fleet import fleet_records

        base = {"method": spec.key, "label": spec.label, "sim": sim, "act": act, **where}
        ids = {"train_seed": spec.train_seed, "source": spec.source}
        return fleet_records(env_cfg.replace(uavs=uavs), policy, seeds, base, ids)
    records = []
    batch: list[dict[str, float]] = []
    if sim == "grid" and act != FIXED and batched and isinstance(policy, LearnedPolicy):
        batch = run_batch(env_cfg, policy, seeds)  # (a chooser of views plays episode by episode)
    env = VCPPEnv(env_cfg) if sim == "grid" and not batch else None
    for k, seed in enumerate(seeds):
        calls_before = getattr(policy, "calls", 0)
        if batch:
            metrics = batch[k]
        elif sim == Sim.PHYSICS:
            from pirl.physics import run_physics_episode

            metrics = run_physics_episode(env_cfg, policy, seed, config.physics)
        else:
            metrics = run_episode(env, policy, seed).metrics
        records.append(
            {
                "method": spec.key,
                "label": spec.label,
                "sim": sim,
                "act": act,
                **where,
                "seed": seed,
                "train_seed": spec.train_seed,
                "source": spec.source,
                **metrics,
                "llm_calls": getattr(policy, "calls", 0) - calls_before,
            }
        )
    return records


# -- driver side ---------------------------------------------------------------------------
def _tasks(plan: EvalPlan, workers: int) -> list[tuple]:
    groups = []
    for spec in plan.specs:
        for act, sim in _act_sims(plan, spec):
            episodes = plan.sim_episodes.get(sim, plan.episodes)
            episodes = min(episodes, plan.episodes_per_method.get(spec.key, episodes))
            batched = plan.batched and sim == "grid" and act != FIXED
            worlds: list[Any] = list(plan.sim_sizes.get(sim, plan.sizes))
            worlds += plan.sim_sites.get(sim, plan.sites)
            fleets: list[int | None] = [None] if plan.uavs == [1] else list(plan.uavs)
            for size in worlds:
                seeds = scenario_seeds(_grid_size(size), episodes)
                for uavs in fleets:
                    groups.append((spec, size, sim, seeds, act, uavs, batched and uavs is None))
    # A batched group plays all its scenarios with one policy forward per step, so it is
    # cheapest whole: it is split across the workers only when there are too few groups to
    # keep them all busy. Episode by episode, two chunks per worker balance the load.
    whole = sum(g[-1] for g in groups) >= 2 * workers
    tasks = []
    for spec, size, sim, seeds, act, uavs, batched in groups:
        parts = 1 if batched and whole else workers if batched else 2 * workers
        chunk = max(1, math.ceil(len(seeds) / max(1, parts)))
        for i in range(0, len(seeds), chunk):
            tasks.append((spec, size, sim, seeds[i : i + chunk], act, uavs))
    # Longest first, so no long episode starts last while the other workers idle: the
    # physics simulator's (seconds each), then the grid's largest worlds.
    tasks.sort(key=lambda t: (t[2] != Sim.PHYSICS, -_grid_size(t[1])[0] * _grid_size(t[1])[1]))
    return tasks


def _grid_size(world: tuple[int, int, int] | str) -> tuple[int, int, int]:
    """The grid size of a size or of a site folder."""
    if isinstance(world, str):
        from pirl.world.site import load_site

        return load_site(world).size
    return world


def _act_sims(plan: EvalPlan, spec: MethodSpec) -> list[tuple[str, str]]:
    if spec.source in BUILTIN:
        return [(FIXED, sim) for sim in plan.sims]
    return [(a, sim) for a in plan.acts for sim in plan.sims if a in plan.sim_acts.get(sim, [a])]


def check_fleet(plan: EvalPlan) -> None:
    """A plan's fleet sizes (:func:`pirl.evaluate.fleet.check_fleets`), refused in one line."""
    if plan.uavs != [1]:
        from pirl.evaluate.fleet import check_fleets

        names = [s.source if s.source in BUILTIN else s.key.split(":")[0] for s in plan.specs]
        check_fleets(plan.env, plan.uavs, plan.sims, names)


def check_workers(workers: int | None) -> None:
    """A worker count given by the user must be at least 1 (None: the default)."""
    if workers is not None and workers < 1:
        raise ConfigError(f"--workers {workers}: must be >= 1")


def evaluate(
    plan: EvalPlan,
    out: Path,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    executor_factory: Callable[[int], Any] | None = None,
    ray_address: str | None = None,
) -> Path:
    """Run the plan; write ``episodes.jsonl`` and ``summary.csv`` into ``out``.

    The episodes go to ``workers`` processes, or to an executor: ``executor_factory(workers)``,
    or Ray at ``ray_address`` (``pirl[distributed]``)."""
    if ray_address and executor_factory is None:
        import functools

        from pirl.evaluate.executors import ray_executor

        executor_factory = functools.partial(ray_executor, ray_address)
    for sim in plan.sims:
        if sim not in SIMS:
            raise ConfigError(f"--sim {sim!r}: available simulators are {', '.join(SIMS)}")
    if not plan.specs:
        raise ConfigError("nothing to evaluate: give --runs and/or --methods")
    plan.acts = parse_acts(plan.acts)
    check_fleet(plan)
    plan.specs = distinct_specs(plan.specs)
    _check_observations(plan)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tasks = _tasks(plan, workers)
    total = sum(len(t[3]) for t in tasks)
    env_dict, config_dict = plan.env.to_dict(), plan.config.to_dict()
    records: list[dict[str, Any]] = []
    done = 0
    if workers <= 1 and executor_factory is None:
        for spec, size, sim, seeds, act, uavs in tasks:
            records += run_chunk(
                spec, env_dict, config_dict, size, sim, seeds, act, plan.batched, uavs
            )
            done += len(seeds)
            if progress:
                progress(done, total)
    else:
        factory = executor_factory or process_pool
        with factory(workers) as pool:
            futures = {
                pool.submit(
                    run_chunk,
                    spec,
                    env_dict,
                    config_dict,
                    size,
                    sim,
                    seeds,
                    act,
                    plan.batched,
                    uavs,
                ): len(seeds)
                for spec, size, sim, seeds, act, uavs in tasks
            }
            for future in as_completed(futures):
                records += future.result()
                done += futures[future]
                if progress:
                    progress(done, total)
    records.sort(
        key=lambda r: (
            r["method"],
            r["sim"],
            r["act"],
            r["size"],
            r.get("uavs", 0),
            str(r["source"]),
            r["seed"],
        )  # fmt: skip
    )
    _write_jsonl(out / "episodes.jsonl", records)
    write_summary(records, out / "summary.csv")
    (out / "plan.json").write_text(
        json.dumps(
            {
                "specs": [asdict(s) for s in plan.specs],
                "sizes": [size_name(s) for s in plan.sizes],
                "episodes": plan.episodes,
                "episodes_per_method": plan.episodes_per_method,
                "sims": plan.sims,
                "acts": plan.acts,
                "uavs": plan.uavs,
                "env": env_dict,
                PhysicsConfig.section: config_dict[PhysicsConfig.section],
            },
            indent=2,
        )
    )
    return out / "summary.csv"


# Settings that do not make two runs different methods: how `reproduce` runs and evaluates them.
_SEED_ONLY = ("reproduce.", "physics.", "train.log_every_s", "train.checkpoint_every")


def distinct_specs(specs: list[MethodSpec]) -> list[MethodSpec]:
    """Check that results cannot mix, and give each label its own key.

    The same run twice (``--runs A A``) is refused; so are runs with the same label and seed
    (copies of one run). Runs with the same label are seeds of one row only when their
    configs match in everything but the seed; otherwise they are refused with the first
    difference. Runs that share a key (a method) but not a label get keys of their own, so
    their episodes never pool.
    """
    seen: dict[str, MethodSpec] = {}
    by_label: dict[str, MethodSpec] = {}
    for spec in specs:
        if spec.source in BUILTIN:
            where = spec.source + "|" + str(spec.advisor) + "|" + str(spec.max_calls)
        else:
            where = str(Path(spec.source).resolve())
        if where in seen:
            raise ConfigError(f"{spec.source} is given twice; each run counts once")
        seen[where] = spec
        if spec.source in BUILTIN:
            continue
        first = by_label.setdefault(spec.label, spec)
        if first is spec:
            continue
        # The differing setting first: two runs that differ are not copies of one run.
        diff = _config_difference(Path(first.source), Path(spec.source), spec.key)
        if diff is None and first.train_seed == spec.train_seed:
            raise ConfigError(
                f"{first.source} and {spec.source} are both {spec.label!r} with seed "
                f"{spec.train_seed}: copies of one run count once; give one of them"
            )
        if diff is not None:
            key, a, b = diff
            raise ConfigError(
                f"{first.source} and {spec.source} share the label {spec.label!r} but differ in "
                f"{key} ({a!r} vs {b!r}), not only in the seed: evaluate them separately"
            )
    labels_per_key: dict[str, set[str]] = {}
    for spec in specs:
        labels_per_key.setdefault(spec.key, set()).add(spec.label)
    out = []
    for spec in specs:
        if len(labels_per_key[spec.key]) > 1:
            spec = replace(spec, key=f"{spec.key}:{_slug(spec.label)}")
        out.append(spec)
    return out


def _slug(label: str) -> str:
    words = "".join(c.lower() if c.isalnum() or c == "." else " " for c in label).split()
    return "-".join(words)


def _config_difference(a: Path, b: Path, method: str) -> tuple[str, Any, Any] | None:
    """The first setting (section.key) in which two runs' config.yaml differ, seed aside and
    sections the method does not use (PARE and the advisor outside PIRL) aside."""
    entry = METHODS.get(method)
    unused = () if is_advised_key(method) else ("pare.", "advisor.")
    unused += ("train.",) if entry is not None and entry.training == TRAIN_IMITATION else ("il.",)

    def flat(run: Path) -> dict[str, Any]:
        folder = RunFolder(run)
        data = folder.config.to_dict() if folder.has_config else {}
        return {
            f"{section}.{key}": value
            for section, values in data.items()
            for key, value in (values.items() if isinstance(values, dict) else ())
        }

    fa, fb = flat(a), flat(b)
    for key in sorted(fa.keys() | fb.keys()):
        if not key.startswith(_SEED_ONLY + unused) and fa.get(key) != fb.get(key):
            return key, fa.get(key), fb.get(key)
    return None


def process_pool(workers: int) -> ProcessPoolExecutor:
    # spawn: workers must not inherit the parent's threads (torch, an LLM, numba).
    # ignore_sigint: Ctrl-C is the parent's to handle (one line, no worker tracebacks).
    return _quiet.QuietProcessPool(
        max_workers=workers, mp_context=mp.get_context("spawn"), initializer=_quiet.ignore_sigint
    )


def _check_observations(plan: EvalPlan) -> None:
    """A trained policy needs the observation layout it was trained with."""
    for spec in plan.specs:
        folder = RunFolder(Path(spec.source))
        if spec.source in BUILTIN or not folder.has_config:
            continue
        trained = folder.config.env
        for key in ("obs_window", "obs_global", *OBS_BLOCKS):
            if getattr(trained, key) != getattr(plan.env, key):
                raise ConfigError(
                    f"{spec.source} was trained with {key}={getattr(trained, key)}, "
                    f"the evaluation uses {getattr(plan.env, key)}: evaluate it with its own "
                    "env settings, or train it again (a new --out, or remove that folder)"
                )


def _write_jsonl(path: Path, records: Iterable[dict[str, Any]]) -> None:
    with replacing(path) as tmp, open(tmp, "w") as fh:
        for record in records:
            fh.write(json.dumps(record, sort_keys=True) + "\n")


def evaluate_runs(
    out: Path,
    runs: list[Path],
    builtins: list[str],
    sizes: list[str],
    episodes: int = 100,
    sims: list[str] | None = None,
    workers: int = 1,
    config: Path | None = None,
    advisor: str = DEFAULT_ADVISOR,
    act: str | list[str] = "both",
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
    ray_address: str | None = None,
    sites: list[Path] | None = None,
    uavs: list[int] | None = None,
) -> Path:
    """``pirl evaluate``: finished ``runs`` and ``builtins`` on the same scenarios of each of
    ``sizes`` and of each site folder of ``sites`` (zero-shot: a site's start cells, its
    map); returns the summary written into ``out``.

    The scenarios follow the env section of preset ``config``, else of the first run's
    config.yaml, else the defaults. Everything that can be refused is refused before ``out``
    is touched (it is locked while the episodes run): bad options, results already in
    ``out`` without ``overwrite``, a missing run, an unknown advisor or its missing key (for
    LLM-only), an impossible layout.
    """
    from pirl.advice.registry import advisor_kind
    from pirl.agents.run_folder import folder_contents, folder_lock
    from pirl.agents.runs import check_layouts
    from pirl.evaluate.scenarios import parse_size
    from pirl.world.seeable import with_site
    from pirl.world.site import site_folder

    acts = parse_acts(act)
    if episodes < 1:
        raise ConfigError(f"--episodes {episodes}: must be >= 1")
    check_workers(workers)
    if folder_contents(out) and not overwrite:
        raise ConfigError(
            f"--out {out} already holds results; pass --overwrite to replace them or choose "
            "another --out"
        )
    if config is not None:
        cfg = RunConfig.from_yaml(config)
    elif runs and RunFolder(runs[0]).has_config:
        cfg = RunFolder(runs[0]).judged_config
    else:
        cfg = RunConfig()
    for r in runs:
        if not r.is_dir():
            raise ConfigError(f"--runs {r}: no such run folder")
    specs = [spec_for_run(r) for r in runs]
    if any(asks(m) for m in builtins):
        advisor_kind(advisor).check_key(cfg)
    specs += [spec_for_builtin(m, advisor) for m in builtins]
    size_list = [parse_size(s) for s in sizes]
    check_layouts(cfg.env, size_list, episodes)  # batched: a chunk of worlds per worker
    site_list = [str(site_folder(s).resolve()) for s in sites or []]
    for site in site_list:  # refused here, in one line, before out is touched
        with_site(cfg.env, site)
    plan = EvalPlan(
        specs=specs,
        sizes=size_list,
        episodes=episodes,
        sims=list(sims or ["grid"]),
        env=cfg.env,
        config=cfg,
        acts=acts,
        sites=site_list,
        uavs=sorted(set(uavs or [1])),
    )
    check_fleet(plan)
    if plan.uavs != [1]:
        from pirl.evaluate.fleet import check_fleet_starts

        for site in site_list:
            check_fleet_starts(with_site(cfg.env, site), max(plan.uavs))
    with folder_lock(out):
        return evaluate(plan, out, workers, progress=progress, ray_address=ray_address)
