"""The ``pirl`` command line. Thin: it parses options and calls the modules below it."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from pirl.advice.registry import DEFAULT_ADVISOR, advisor_kind, advisor_names
from pirl.agents.methods import BUILTIN, PLAYED_ALONE, TRAINED
from pirl.config.errors import ConfigError
from pirl.config.load import check_seed

if TYPE_CHECKING:
    from pirl.config.run import RunConfig
    from pirl.config.world import VCPPConfig

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="PIRL: prompt-informed RL for UAV visual coverage path planning.",
)
console = Console()
err = Console(stderr=True)

SizeOpt = Annotated[tuple[int, int, int], typer.Option(help="World size X Y Z (cells).")]
ConfigOpt = Annotated[
    str | None,
    typer.Option(
        "--config", help="Preset name (quick, paper, test) or YAML file: its env section."
    ),
]
RayOpt = Annotated[
    str | None,
    typer.Option(
        "--ray-address",
        help="Run on Ray (pip install 'pirl\\[distributed]'): HOST:PORT of a cluster's head, "
        "auto, or local (a Ray instance on this machine). Run folders must be on storage "
        "every node shares.",
    ),
]

T = TypeVar("T")


def _bad_value(option: str, value: str, why: str) -> typer.Exit:
    """A wrong value of an option, seen while parsing: one line and exit 2 (the project's rule
    for a user's mistake; Typer's own error is a usage box)."""
    err.print(f"[bold red]error:[/] {escape(f'{option} {value!r}: {why}')}", soft_wrap=True)
    return typer.Exit(2)


def _comma_parser(option: str, item: Callable[[str], T], what: str) -> Callable[[str], list[T]]:
    """Typer's parser of one value of a list option: ``30,45`` holds two, each read by
    ``item`` (a ValueError of one is ``not {what}``)."""

    def parse(text: str) -> list[T]:
        values: list[T] = []
        for part in (p.strip() for p in text.split(",")):
            if not part:
                raise _bad_value(option, text, f"an empty value (write {option} A,B)")
            try:
                values.append(item(part))
            except ValueError:
                raise _bad_value(option, text, f"{part!r} is not {what}") from None
        return values

    return parse


def _flatten(values: list[list[T]] | None) -> list[T] | None:
    """Typer's callback of a list option: the values of every occurrence, in order."""
    return [v for group in values for v in group] if values else None


def _list_option(
    option: str, help: str, metavar: str, item: Callable[[str], Any] = str, what: str = "valid"
) -> Any:
    """A list option that Typer parses: repeated (``--sizes 30 --sizes 45``), comma-separated
    (``--sizes 30,45``) or both. For names, sizes and numbers; a list of paths is a plain
    repeated option instead, since a path may hold a comma."""
    return typer.Option(
        option,
        help=f"{help} Comma-separated or repeated.",
        metavar=metavar,
        parser=_comma_parser(option, item, what),
        callback=_flatten,
    )


def _clean_errors(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn configuration, input and OS errors into one readable line and exit code 2."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (ConfigError, FileNotFoundError) as exc:
            # One line whatever the width: a log or a test reads it whole.
            err.print(f"[bold red]error:[/] {escape(str(exc))}", soft_wrap=True)
            raise typer.Exit(2) from None
        except OSError as exc:
            # A read-only or full disk, a folder without permission: the path and the cause.
            line = os_error_line(exc, kwargs.get("out"))
            err.print(f"[bold red]error:[/] {escape(line)}", soft_wrap=True)
            raise typer.Exit(2) from None

    return wrapper


def os_error_line(exc: OSError, out: Any = None) -> str:
    """``PATH: No space left on device (what to do)``: one line for an OS error. A failed
    write names no file (the OS does not say which); then the command's ``out`` is named."""
    import errno

    if exc.filename is not None:
        path = str(exc.filename)
    else:
        path = f"writing in {out}" if out is not None else "(unknown path)"
    reason = exc.strerror or type(exc).__name__
    hint = {
        errno.ENOSPC: "free some space, then run the same command again",
        errno.EROFS: "the file system is read-only; choose another --out",
        errno.EACCES: "no permission; choose another --out or fix the folder's permissions",
        errno.EPERM: "no permission; choose another --out or fix the folder's permissions",
        errno.EDQUOT: "disk quota exceeded; free some space, then run the same command again",
    }.get(exc.errno or 0, "")
    return f"{path}: {reason}" + (f" ({hint})" if hint else "")


def _interrupted(message: str) -> typer.Exit:
    """Ctrl-C in a command with worker processes: one line, exit 130."""
    err.print(f"interrupted: {message}", soft_wrap=True, highlight=False, markup=False)
    return typer.Exit(130)


class _StopWorkersOnCtrlC:
    """While active, Ctrl-C first stops this process's worker processes (they ignore it, so
    none prints a traceback; a pool then finds them gone instead of waiting for their
    work), then raises ``KeyboardInterrupt`` here as usual."""

    def __enter__(self) -> _StopWorkersOnCtrlC:
        import signal

        self._old = signal.signal(signal.SIGINT, self._handler)
        return self

    def _handler(self, signum: int, frame: Any) -> None:
        import multiprocessing as mp

        for child in mp.active_children():
            child.terminate()
        raise KeyboardInterrupt

    def __exit__(self, *exc: object) -> None:
        import signal

        signal.signal(signal.SIGINT, self._old)


def _names(names: list[str] | tuple[str, ...]) -> str:
    """``a, b or c``, for help texts."""
    names = list(names)
    return ", ".join(names[:-1]) + f" or {names[-1]}" if len(names) > 1 else "".join(names)


ADVISORS = _names(advisor_names())
"""The advisors --advisor takes: the built-ins and the installed plugins'."""


def _run_config(config: str | Path | None) -> RunConfig:
    """What every ``--config`` reads: a preset by name (quick, paper, test) or a YAML file,
    all its sections; none: the defaults."""
    from pirl.config.run import RunConfig

    if not config:
        return RunConfig()
    path = _preset(config, "--config")
    try:
        return RunConfig.from_yaml(path)
    except ConfigError:
        _refuse_env_only(path)
        raise


def _refuse_env_only(path: Path) -> None:
    """Say where the settings of an env-only file go (render and webots-world once read such
    files): under ``env:``, as in every preset."""
    import dataclasses

    from pirl.config.load import read_yaml
    from pirl.config.world import VCPPConfig

    data = read_yaml(path)
    env_keys = {f.name for f in dataclasses.fields(VCPPConfig)}
    if isinstance(data, dict) and data and set(data) <= env_keys:
        raise ConfigError(
            f"--config {path}: {', '.join(map(str, data))} are env settings; a preset holds "
            "them under 'env:' (see configs/quick.yaml)"
        )


def _env(config: str | None, size: tuple[int, int, int], footprint: str | None) -> VCPPConfig:
    """``--config``'s env section with ``--size`` and, when given, ``--footprint`` applied."""
    env = _run_config(config).env.replace(size=tuple(size))
    return env.replace(footprint=footprint) if footprint is not None else env


def _make_policy(name: str, seed: int):
    from pirl.agents.loading import load_policy

    if name not in PLAYED_ALONE:
        raise ConfigError(f"--policy {name!r}: allowed values are {', '.join(PLAYED_ALONE)}")
    return load_policy(name, seed=seed)


def _metrics_table(rows: list[tuple[str, dict[str, float]]], title: str) -> Table:
    table = Table(title=title)
    for col in ("policy", "VCR", "BE", "RVC", "overlap", "steps", "collisions", "battery left"):
        table.add_column(col, justify="right" if col != "policy" else "left")
    for name, m in rows:
        table.add_row(
            name,
            f"{m['vcr']:.3f}",
            f"{m['be']:.3f}",
            f"{m['rvc']:.3f}",
            f"{m['overlap']:.3f}",
            str(m["steps"]),
            str(m["collisions"]),
            f"{m['battery_left']:.3f}",
        )
    return table


@app.command()
@_clean_errors
def render(
    policy: Annotated[str, typer.Option(help=f"{_names(PLAYED_ALONE)}.")] = "random",
    size: SizeOpt = (30, 30, 3),
    seed: Annotated[int, typer.Option(help="Scenario seed.")] = 0,
    out: Annotated[Path, typer.Option(help="GIF to write.")] = Path("episode.gif"),
    footprint: Annotated[str | None, typer.Option(help="paper or frustum.")] = None,
    config: ConfigOpt = None,
    fps: Annotated[int, typer.Option(help="Frames per second of the GIF.")] = 12,
    site: Annotated[
        Path | None, typer.Option(help="A site folder to fly instead of a generated world.")
    ] = None,
) -> None:
    """Fly one episode with a simple policy and write it as an animated GIF."""
    from pirl.env import VCPPEnv
    from pirl.env.render import cell_pixels
    from pirl.evaluate import run_episode, save_gif
    from pirl.evaluate.rollout import check_gif_target
    from pirl.world.memory import check_memory

    check_seed(seed)
    check_gif_target(out, fps)
    cfg = _env(config, size, footprint)
    if site is not None:
        from pirl.world.seeable import with_site

        cfg = with_site(cfg, str(site))
    px = cell_pixels(cfg.size, cfg.render_cell_px)
    check_memory(cfg, 1, per_step_bytes=cfg.size[0] * cfg.size[1] * px * px * 3)
    env = VCPPEnv(cfg, render_mode="rgb_array")
    result = run_episode(env, _make_policy(policy, seed), seed, record=True)
    path = save_gif(result.frames, out, fps=fps)
    console.print(_metrics_table([(policy, result.metrics)], f"{cfg.size} seed {seed}"))
    console.print(f"wrote {path} ({len(result.frames)} frames)")


@app.command()
@_clean_errors
def reproduce(
    profile: Annotated[str, typer.Option(help="quick (the demo) or paper (full budgets).")] = (
        "quick"
    ),
    advisor: Annotated[
        str | None,
        typer.Option(help=f"PIRL's advisor: {ADVISORS} (default: the preset's)."),
    ] = None,
    seeds: Annotated[
        list[int] | None,
        _list_option(
            "--seeds", "Training seeds per method.", "SEED[,SEED...]", int, "a whole number"
        ),
    ] = None,
    workers: Annotated[int | None, typer.Option(help="Evaluation worker processes.")] = None,
    out: Annotated[Path | None, typer.Option(help="Output folder (default results/<profile>).")] = (
        None
    ),
    config: Annotated[
        Path | None, typer.Option(help="A preset file instead of configs/<profile>.yaml.")
    ] = None,
    ray_address: RayOpt = None,
) -> None:
    """Train every method not yet trained in --out, evaluate all of them, write the report."""
    from rich.progress import Progress

    from pirl.agents.run_folder import folder_lock
    from pirl.agents.stops import TrainingInterrupted
    from pirl.config.run import RunConfig
    from pirl.reproduce.pipeline import run_reproduction
    from pirl.reproduce.plan import check_reproduce, make_plan

    path = _preset(config, "--config") if config else _preset(profile)
    cfg = RunConfig.from_yaml(path)
    if seeds:
        cfg = cfg.with_overrides(reproduce={"seeds": list(seeds)})
    advisor = advisor or cfg.pare.advisor
    checked = check_reproduce(cfg, advisor, workers)  # refused before any folder is made
    out = out or Path("results") / profile
    console.print(f"reproduce: profile {path}, advisor {advisor}, output {out}")
    try:
        with (
            folder_lock(out),
            _StopWorkersOnCtrlC(),
            Progress(console=console, transient=True) as bar,
        ):
            progress = _episode_progress(bar, "evaluation")
            # The plan reads the run folders already in --out: made under the folder's lock.
            report = run_reproduction(
                make_plan(checked, out),
                log=lambda m: console.print(m),
                progress=progress,
                ray_address=ray_address,
            )
    except (KeyboardInterrupt, TrainingInterrupted):
        raise _interrupted(
            f"finished runs and the last checkpoint of each run in progress are kept in {out}; "
            f"run the same command to resume: {_command_line()}"
        ) from None
    console.print(f"[bold]report:[/] {report}")
    console.print(f"tables: {report.parent / 'table.md'}")


def _command_line() -> str:
    """The command as typed (quoted for a shell), for a "run it again" hint."""
    import shlex
    import sys

    return "pirl " + shlex.join(sys.argv[1:])


BUNDLED_CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def _preset(profile: str | Path, option: str = "--profile") -> Path:
    """A preset by name (quick, paper, test) or path: a file that exists, else
    ``configs/<name>.yaml`` here, else the bundled one (whatever the working directory)."""
    given = Path(profile)
    if given.is_file():
        return given
    name = given.name if given.suffix in (".yaml", ".yml") else f"{given.name}.yaml"
    for candidate in (Path("configs") / name, BUNDLED_CONFIGS / name):
        if candidate.is_file() and (given.parent in (Path("."), Path("configs"))):
            return candidate
    known = ", ".join(sorted(p.stem for p in BUNDLED_CONFIGS.glob("*.yaml"))) or "quick, paper"
    raise ConfigError(f"{option} {str(profile)!r}: no such file or bundled preset (try {known})")


@app.command()
@_clean_errors
def demo(
    out: Annotated[Path, typer.Option(help="Output folder.")] = Path("results/quick"),
    advisor: Annotated[str | None, typer.Option(help="PIRL's advisor (default: quick's).")] = None,
) -> None:
    """The main job on the embedded defaults: ``pirl reproduce --profile quick``."""
    reproduce(profile="quick", advisor=advisor, seeds=None, workers=None, out=out, config=None)


@app.command()
@_clean_errors
def train(
    method: Annotated[str, typer.Option(help=f"{_names(TRAINED)}.")],
    out: Annotated[Path, typer.Option(help="Run folder to create (or resume).")],
    config: Annotated[
        str | None,
        typer.Option(
            help="Preset name (quick, paper, test) or YAML file; default quick, or with "
            "--resume the run's own config.yaml."
        ),
    ] = None,
    steps: Annotated[
        int | None, typer.Option(help="Override train.total_steps (--resume: extend).")
    ] = None,
    seed: Annotated[
        int | None, typer.Option(help="Training seed (default 0, or the resumed run's).")
    ] = None,
    advisor: Annotated[
        str | None, typer.Option(help=f"pirl: {ADVISORS} (default: the config's).")
    ] = None,
    expert: Annotated[Path | None, typer.Option(help="il: a finished ppo-ewri run.")] = None,
    resume: Annotated[bool, typer.Option(help="Continue the run in --out.")] = False,
    student: Annotated[
        Path | None,
        typer.Option(help="pirl, student mode: start from a student made by pirl distill."),
    ] = None,
    site: Annotated[
        Path | None, typer.Option(help="Train on a site folder (docs/sites.md): its seeded starts.")
    ] = None,
) -> None:
    """Train one method into a run folder (checkpoints, TensorBoard logs, metrics CSV)."""
    from pirl.agents.runs import train_run
    from pirl.agents.stops import TrainingInterrupted, TrainingStopped

    try:
        result = train_run(
            method, out, _preset(config, "--config") if config else None, _preset("quick"),
            steps=steps, seed=seed, advisor=advisor, expert=expert, resume=resume,
            student=student, site=site,
        )  # fmt: skip
    except TrainingInterrupted as stop:
        err.print(
            f"interrupted: checkpoint saved at {stop.checkpoint}; continue with --resume",
            soft_wrap=True,
        )
        raise typer.Exit(130) from None
    except TrainingStopped as stop:
        err.print(
            f"[bold red]stopped:[/] {escape(stop.reason)}; checkpoint: {stop.checkpoint}; "
            "fix the advisor, then continue with --resume",
            soft_wrap=True,  # one line whatever the width: logs and tests read it whole
        )
        raise typer.Exit(3) from None
    console.print(f"done: {result}")


@app.command()
@_clean_errors
def distill(
    teacher: Annotated[str, typer.Option(help=f"The advisor to imitate: {ADVISORS}.")],
    out: Annotated[Path, typer.Option(help="Student folder to create, e.g. students/NAME.")],
    states: Annotated[int, typer.Option(help="States to ask the teacher about.")] = 2000,
    config: Annotated[
        str, typer.Option(help="Preset name or YAML file (env, pare and advisor settings).")
    ] = "quick",
    policy: Annotated[
        list[str] | None,
        typer.Option(
            metavar="POLICY",
            help=f"Where states come from: {', '.join(PLAYED_ALONE)} or a run folder; repeat "
            f"--policy for several (default: {', '.join(PLAYED_ALONE)}).",
        ),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the state sampling.")] = 0,
    fit_steps: Annotated[int, typer.Option(help="Adam steps of the student's fit.")] = 2000,
) -> None:
    """Distil a teacher advisor into a student offline (for pirl train --student)."""
    from rich.progress import Progress

    from pirl.advice.student import STUDENT_FILE
    from pirl.agents.distill import distill as run_distill

    cfg = _run_config(config)
    advisor_kind(teacher).check_key(cfg)
    sources = policy or list(PLAYED_ALONE)
    with Progress(console=console, transient=True) as bar:
        task = bar.add_task("teacher answers", total=states)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)
            if not console.is_terminal and (done == total or done % 500 < 32):
                console.print(f"distill: {done}/{total} answers")

        record = run_distill(
            cfg, teacher, states, out, sources, seed=seed, fit_steps=fit_steps, progress=progress,
        )  # fmt: skip
    console.print(
        f"{record['label']}: agreement {record['agreement']:.3f} (majority "
        f"{record['majority']:.3f}) on {record['heldout']} held-out answers; "
        f"{record['dataset_size']} answers in the dataset"
    )
    console.print(f"wrote {out / STUDENT_FILE}; train with --student {out}")


@app.command()
@_clean_errors
def evaluate(
    runs: Annotated[
        list[Path] | None,
        typer.Option(
            metavar="RUN",
            help="A finished run folder; repeat --runs for several (--runs A --runs B). Each "
            "value is one path, whatever it holds (spaces, commas, any character).",
        ),
    ] = None,
    methods: Annotated[
        list[str] | None,
        _list_option("--methods", f"Built-in methods: {', '.join(BUILTIN)}.", "NAME[,NAME...]"),
    ] = None,
    sizes: Annotated[
        list[str] | None,
        _list_option("--sizes", "N (NxNx3) or XxYxZ, default 30,45,60.", "SIZE[,SIZE...]"),
    ] = None,
    site: Annotated[
        list[Path] | None,
        typer.Option(
            metavar="SITE",
            help="A site folder (docs/sites.md) evaluated beside the sizes, zero-shot; repeat "
            "--site for several.",
        ),
    ] = None,
    episodes: Annotated[int, typer.Option(help="Scenarios per size.")] = 100,
    sim: Annotated[
        list[str] | None, _list_option("--sim", "Simulators: grid, physics.", "SIM[,SIM...]")
    ] = None,
    out: Annotated[Path, typer.Option(help="Results folder.")] = Path("results/eval"),
    workers: Annotated[int, typer.Option(help="Worker processes.")] = 1,
    config: Annotated[
        str | None,
        typer.Option(
            help="Preset name (quick, paper, test) or YAML file whose env section defines the "
            "scenarios."
        ),
    ] = None,
    advisor: Annotated[str, typer.Option(help=f"Advisor of llm-only: {ADVISORS}.")] = (
        DEFAULT_ADVISOR
    ),
    act: Annotated[
        str,
        typer.Option(
            help="How trained policies act: stochastic (sampled, seeded per scenario), greedy "
            "or both. Built-ins act by their own rule (act 'fixed')."
        ),
    ] = "both",
    ray_address: RayOpt = None,
    overwrite: Annotated[
        bool, typer.Option(help="Replace the results already in --out (refused otherwise).")
    ] = False,
) -> None:
    """Evaluate trained runs and built-in methods on the same scenarios of each size."""
    from rich.progress import Progress

    from pirl.evaluate.runner import evaluate_runs

    try:
        with _StopWorkersOnCtrlC(), Progress(console=console, transient=True) as bar:
            summary = evaluate_runs(
                out, list(runs or []), methods or [],
                sizes if sizes is not None else ([] if site else ["30", "45", "60"]),
                episodes, sim or ["grid"],
                workers, _preset(config, "--config") if config is not None else None, advisor,
                act, overwrite, progress=_episode_progress(bar, "episodes"),
                ray_address=ray_address, sites=list(site or []),
            )  # fmt: skip
    except KeyboardInterrupt:
        raise _interrupted(
            f"no results written to {out} (they are written once every episode is done); "
            f"run the same command to start again: {_command_line()}"
        ) from None
    console.print(_summary_table(summary))
    console.print(f"wrote {out / 'episodes.jsonl'} and {summary}")


def _mean_ci(mean: float, half: float) -> str:
    """``mean ± half``, or the mean alone when there is no interval (n = 1)."""
    import math

    return f"{mean:.3f}" if math.isnan(half) else f"{mean:.3f} ± {half:.3f}"


def _episode_progress(bar: Any, label: str) -> Any:
    """Evaluation progress on the command's bar (a plain line every 10 s off a terminal)."""
    from pirl.progress import Progress

    return Progress(
        label, line="{label}: {done}/{total} episodes", bar=bar, tty=console.is_terminal,
        final_at_total=True, out=lambda text: console.print(text, highlight=False),
    )  # fmt: skip


def _summary_table(path: Path) -> Table:
    from pirl.evaluate.summary import read_summary

    table = Table(title=f"{path} (mean ± 95% CI over episodes; IQM [interval] over seeds)")
    for col in ("method", "sim", "act", "size", "n", "seeds", "VCR", "BE", "RVC", "VCR IQM"):
        table.add_column(col)
    for row in read_summary(path):
        cells = [_mean_ci(row[m + "_mean"], row[m + "_ci95"]) for m in ("vcr", "be", "rvc")]
        seeds = int(row.get("seeds", 1))
        iqm = f"{row['vcr_iqm']:.3f}"
        if seeds > 1:
            iqm += f" [{row['vcr_iqm_lo']:.3f}, {row['vcr_iqm_hi']:.3f}]"
        table.add_row(
            row["label"], row["sim"], row.get("act", ""), row["size"], str(int(row["n"])),
            str(seeds), *cells, iqm,
        )  # fmt: skip
    return table


@app.command()
@_clean_errors
def advise(
    advisor: Annotated[str, typer.Option(help=f"{ADVISORS}.")] = DEFAULT_ADVISOR,
    size: SizeOpt = (15, 15, 3),
    seed: Annotated[int, typer.Option(help="Scenario seed.")] = 0,
    config: Annotated[
        str | None,
        typer.Option(help="Preset name or YAML file with advisor settings (e.g. base_url)."),
    ] = None,
    model: Annotated[str | None, typer.Option(help="openai model, or local model folder.")] = None,
    base_url: Annotated[str | None, typer.Option(help="OpenAI-compatible server URL.")] = None,
    cache: Annotated[bool, typer.Option(help="Use the persistent answer cache.")] = True,
    score: Annotated[
        int | None,
        typer.Option(
            help="Score the advisor against the oracle on N validation states (agreement, "
            "kappa, alignment, latency, tokens, the price of a run)."
        ),
    ] = None,
    out: Annotated[Path | None, typer.Option(help="--score: write the score as JSON.")] = None,
    price_in: Annotated[
        float | None, typer.Option(help="--score: price per million prompt tokens.")
    ] = None,
    price_out: Annotated[
        float | None, typer.Option(help="--score: price per million completion tokens.")
    ] = None,
    profile: Annotated[
        str, typer.Option(help="--score: the profile whose PIRL run is priced.")
    ] = "quick",
) -> None:
    """Ask the advisor about one scenario's first state: the check to run first on a new LLM.
    With --score N: how good its advice is, scored against the oracle, and what a run costs."""
    from pirl.advice.health import check_advisor
    from pirl.config.run import RunConfig

    check_seed(seed)
    kind = advisor_kind(advisor)
    if config:
        cfg = _run_config(config)
    else:  # no config: the prompt this advisor suits (the embedded model: compact)
        cfg = RunConfig().with_overrides(pare={"prompt_variant": kind.prompt_variant})
    if base_url is None:
        kind.check_key(cfg)
    changes: dict[str, Any] = {}
    if model is not None and kind.model_setting:
        changes[kind.model_setting] = model
    if base_url is not None:
        changes["openai_base_url"] = base_url
    if changes:
        cfg = cfg.with_overrides(advisor=changes)
    if score is not None:
        _score(cfg, advisor, score, out, price_in, price_out, profile, cache, seed)
        return

    def show_prompt(prompt: str) -> None:
        console.rule("prompt")
        console.print(prompt, markup=False, highlight=False)

    check = check_advisor(
        cfg, advisor, tuple(size), seed, cache, show_prompt, log=lambda m: console.print(m)
    )
    answer, prompt, loaded = check.answer, check.prompt, check.setup_s
    console.rule(f"answer from {check.label}")
    if answer.cut:
        console.print(answer.text[:300], markup=False, highlight=False)
        console.print(
            f"(reply of {answer.reply_chars:,} characters or bytes; only its head is kept, and "
            "a reply that long counts as unparseable)",
            markup=False,
        )
    else:
        console.print(answer.text or "(no text)", markup=False, highlight=False)
    console.rule("result")
    rec = answer.recommendation
    console.print(f"parsed:      {rec if rec is not None else 'could not parse'}", markup=False)
    console.print(f"latency:     {answer.latency_s:.2f} s (advisor set-up {loaded:.1f} s)")
    console.print(f"tokens:      {answer.prompt_tokens} in, {answer.completion_tokens} out")
    console.print(f"from cache:  {answer.from_cache}")
    if answer.error:
        console.print(f"[bold red]error:[/] {answer.error}")
    copied = _copies_format_example(rec, prompt)
    if copied:
        console.print(
            "[bold yellow]warning:[/] the answer is the prompt's own format example, not advice "
            f"for this state (prompt variant {cfg.pare.prompt_variant!r}). The embedded model "
            "suits the compact prompt: pare.prompt_variant: compact (as in configs/quick.yaml, "
            "e.g. --config quick)."
        )
    if rec is None or copied:
        raise typer.Exit(1)


def _score(
    cfg: Any,
    name: str,
    n: int,
    out: Path | None,
    price_in: float | None,
    price_out: float | None,
    profile: str,
    cache: bool,
    seed: int,
) -> None:
    """``pirl advise --score``: the advisor scored against the oracle, and the price of a run."""
    import json

    from rich.progress import Progress

    from pirl.advice.factory import make_advisor
    from pirl.config.run import RunConfig
    from pirl.evaluate.advice_score import price_run, score_advisor

    if n < 1:
        raise ConfigError(f"--score {n}: ask about at least 1 state")
    if out is not None and out.is_dir():
        raise ConfigError(f"--out {out} is a folder; give the JSON file to write")
    priced = RunConfig.from_yaml(_preset(profile, "--profile")).with_overrides(
        pare={"advisor": name}
    )
    advisor = make_advisor(name, cfg, cache=cache)
    try:
        with Progress(console=console, transient=True) as bar:
            task = bar.add_task("scoring", total=n)
            result = score_advisor(
                advisor, cfg, n, seed, progress=lambda d, t: bar.update(task, completed=d)
            )
    finally:
        advisor.close()
    price = price_run(priced, name, profile, result.tokens_in, result.tokens_out,
                      price_in, price_out)  # fmt: skip
    table = Table(title=f"{result.advisor} against the oracle on {result.states} states")
    for col in ("measure", "value", "kappa"):
        table.add_column(col)
    rows = [
        ("parse rate", result.parse_rate, None),
        ("agreement: move", result.agreement_move, result.kappa_move),
        ("agreement: position", result.agreement_position, result.kappa_position),
        ("agreement: camera", result.agreement_camera, result.kappa_camera),
        ("alignment (PARE pays)", result.alignment_mean, None),
        ("alignment of the oracle", result.alignment_oracle, None),
    ]
    for label_, value, kappa in rows:
        table.add_row(label_, f"{value:.3f}", "" if kappa is None else f"{kappa:.3f}")
    console.print(table)
    console.print(
        f"latency p50 {result.latency_p50_s:.3f} s, p95 {result.latency_p95_s:.3f} s; tokens "
        f"per answer {result.tokens_in:.0f} in, {result.tokens_out:.0f} out "
        f"({result.tokens_counted_by})"
    )
    console.print(price.line(), markup=False)
    if out is not None:
        data = {**result.to_dict(), "price": price.to_dict(), "seed": seed,
                "prompt_variant": cfg.pare.prompt_variant}  # fmt: skip
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + ".tmp")
        tmp.write_text(json.dumps(data, indent=2))
        tmp.replace(out)
        console.print(f"wrote {out}")


def _copies_format_example(rec: Any, prompt: str) -> bool:
    """Whether the parsed answer is exactly the format example the prompt shows."""
    from pirl.advice.parser import parse_recommendation
    from pirl.advice.recommendation import FORMAT_EXAMPLE

    return (
        rec is not None and FORMAT_EXAMPLE in prompt and rec == parse_recommendation(FORMAT_EXAMPLE)
    )


def main() -> None:
    """Console entry point: Typer parses the command line as given."""
    from pirl import _quiet

    _quiet.install()
    app(prog_name="pirl")


@app.command()
@_clean_errors
def plan(
    out: Annotated[Path, typer.Option(help="The mission folder to write (must not exist).")],
    site: Annotated[Path | None, typer.Option(help="A site folder (docs/sites.md).")] = None,
    size: Annotated[
        tuple[int, int, int] | None, typer.Option(help="A generated world X Y Z instead.")
    ] = None,
    seed: Annotated[int, typer.Option(help="Scenario seed (start cell; obstacles).")] = 0,
    policy: Annotated[Path | None, typer.Option(help="A trained run folder to fly.")] = None,
    method: Annotated[
        str | None, typer.Option(help=f"A built-in instead: {_names(PLAYED_ALONE)}.")
    ] = None,
    act: Annotated[str, typer.Option(help="A trained policy: greedy or stochastic.")] = "greedy",
    gimbal: Annotated[
        str, typer.Option(help="v2: DO_GIMBAL_MANAGER_PITCHYAW; v1: DO_MOUNT_CONTROL.")
    ] = "v2",
    config: Annotated[
        str | None,
        typer.Option(help="Preset name or YAML file whose mission section sets speeds and limits."),
    ] = None,
    fly: Annotated[
        str | None,
        typer.Option(help="physics: then read the written files back and fly them in PyFlyt."),
    ] = None,
) -> None:
    """Write one episode as missions a drone can fly (QGroundControl .plan, QGC WPL 110,
    GeoJSON, KML), split into battery-sized sorties (docs/missions.md)."""
    from pirl.missions.write import mission_source, write_mission

    check_seed(seed)
    if fly not in (None, "physics"):
        raise ConfigError(f"--fly {fly!r}: allowed value is physics")
    cfg = _run_config(config)
    env, chosen, what = mission_source(cfg.env, seed, policy, method, act, site, size)
    summary = write_mission(out, env, cfg.mission, chosen, seed, what, gimbal)
    console.print(
        f"{what}: VCR {summary['vcr']:.3f} over seeable cells; {summary['sorties']} sortie(s), "
        f"items {summary['items_per_sortie']} ({summary['items_before_merging']} before "
        f"merging legs), {summary['distance_m']:,.0f} m, {summary['flight_time_s'] / 60:.1f} min "
        f"at {cfg.mission.speed_m_s:g} m/s, {summary['photos']} photos"
        + ("" if summary["real_place"] else "; NOT a real place (a generated world)")
    )
    console.print(f"wrote {out}: {', '.join(summary['files'])}")
    if fly:
        _fly_and_print(out, cfg.physics)


def _fly_and_print(folder: Path, physics: Any, wind: bool = True) -> None:
    from pirl.missions.fly import fly_mission, read_flight

    files = read_flight(folder)
    for line in files.warnings:
        err.print(f"[bold yellow]warning:[/] {escape(line)}", soft_wrap=True)
    console.print(
        f"flying {folder} back from {', '.join(files.plans)} ({len(files.ops)} waypoints and "
        f"camera settings) in PyFlyt{' with wind' if wind else ', no wind'} ..."
    )
    if files.skipped:
        named = ", ".join(f"{name} x{count}" for name, count in sorted(files.skipped.items()))
        console.print(
            f"not flown: {sum(files.skipped.values())} item(s) pirl fly does not fly: {named} "
            "(docs/missions.md)",
            highlight=False,
            soft_wrap=True,
        )
    f = fly_mission(files, physics, wind, log=lambda line: console.print(line, highlight=False))
    console.print(
        f"flown: VCR {f['vcr']:.3f} (grid episode {f['vcr_grid']:.3f}), energy "
        f"{f['energy_used']:.3f} of a battery (grid {f['energy_used_grid']:.3f}), end "
        f"{f['end']}, {f['steps']} steps ({f['grid_steps']} in the grid), "
        f"{f['ops_skipped']} waypoints given up, {f['sim_seconds']:.0f} simulated s in "
        f"{f['wall_seconds']:.0f} s; wrote {folder / 'flown.json'}"
    )


@app.command()
@_clean_errors
def fly(
    mission: Annotated[Path, typer.Argument(help="A folder written by pirl plan.")],
    config: Annotated[
        str | None,
        typer.Option(
            help="Preset name or YAML file whose physics section sets wind and the drone."
        ),
    ] = None,
    wind: Annotated[bool, typer.Option(help="Fly with the physics section's wind.")] = True,
) -> None:
    """Fly a written mission in PyFlyt: its .plan files read back from disk, every sortie in
    order; flown coverage and energy beside the grid episode's, in flown.json."""

    cfg = _run_config(config)
    _fly_and_print(mission, cfg.physics, wind)


site_app = typer.Typer(no_args_is_help=True, help="Bring your own site (docs/sites.md).")
app.add_typer(site_app, name="site")


@site_app.command("check")
@_clean_errors
def site_check(
    site: Annotated[Path, typer.Argument(help="The site folder (or its site.yaml).")],
    picture: Annotated[
        Path | None, typer.Option(help="Write a top-down PNG of the site and its reasons.")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    config: Annotated[
        str | None,
        typer.Option(help="Preset name or YAML file whose env section sets the camera model."),
    ] = None,
) -> None:
    """Load and check a site: its size, coverable cells and every reason a cell cannot be seen.

    Exits 0 when at least one coverable cell can be seen, 1 otherwise."""
    import json

    from pirl.missions import site_check as sc

    env = _run_config(config).env if config else None
    found, seen, report = sc.check_site(site, env)
    if picture is not None:
        report["picture"] = str(sc.picture(found, seen, picture))
    if as_json:
        print(json.dumps(report, sort_keys=True))
    else:
        x, y, z = report["size"]
        console.print(
            f"site {report['site']}: {x} x {y} x {z} cells of {report['cell_size_m']:g} m "
            f"(levels {report['level_height_m']:g} m), "
            + ("georeferenced" if report["georeferenced"] else "not georeferenced")
            + f"; camera {report['footprint']}"
            + (", occlusion" if report["occlusion"] else "")
        )
        console.print(
            f"coverable {report['coverable']:,}, seeable {report['seeable']:,}, blocked "
            f"{report['blocked_share']:.1%} of cells, {report['starts']:,} start cell(s)"
        )
        for reason, count in report["unseeable"].items():
            if count:
                console.print(f"  {count:,} cannot be seen: {sc.REASON_TEXT[reason]}")
        if picture is not None:
            console.print(f"wrote {report['picture']}")
    if not report["usable"]:
        if not as_json:
            err.print("[bold red]error:[/] no coverable cell can be seen: the site is unusable")
        raise typer.Exit(1)


@site_app.command("import-uavsim")
@_clean_errors
def site_import_uavsim(
    map_png: Annotated[Path, typer.Argument(help="A uavSim map PNG (res/*.png).")],
    out: Annotated[Path, typer.Option(help="The site folder to write (must not exist).")],
) -> None:
    """Turn a uavSim map (red no-fly, green obstacle, blue start) into a site folder."""
    from pirl.world.uavsim import import_uavsim

    folder = import_uavsim(map_png, out)
    console.print(f"wrote {folder}; check it with: pirl site check {folder}")


@app.command("webots-world")
@_clean_errors
def webots_world(
    size: SizeOpt = (30, 30, 3),
    seed: Annotated[int, typer.Option(help="Scenario seed (obstacles and start).")] = 0,
    out: Annotated[Path, typer.Option(help=".wbt file to write (project/worlds/x.wbt).")] = Path(
        "world.wbt"
    ),
    policy: Annotated[
        str, typer.Option(help="Run folder or built-in method the controller flies.")
    ] = "boustrophedon",
    cell_size: Annotated[
        float,
        typer.Option(
            help="Cell size and level height, metres: the Mavic's scale (a preset's physics "
            "section is PyFlyt's drone)."
        ),
    ] = 2.0,
    footprint: Annotated[str | None, typer.Option(help="paper or frustum.")] = None,
    config: Annotated[
        str | None,
        typer.Option(
            help="Preset name (quick, paper, test) or YAML file: its env section (written "
            "beside the world as <world>.env.yaml for the controller)."
        ),
    ] = None,
    controller: Annotated[
        bool, typer.Option(help="Also write controllers/pirl_mavic/ next to the world.")
    ] = True,
) -> None:
    """Write a Webots world of one scenario (Mavic 2 Pro, zoom camera, sphere obstacles)."""
    from pirl.config.physics import PhysicsConfig
    from pirl.physics.webots.world import write_world

    cfg = _env(config, size, footprint)
    physics = PhysicsConfig(cell_size_m=cell_size, level_height_m=cell_size, body_radius_m=0.25)
    # The controller reads env settings alone (its own --config), so it gets the preset's env
    # section as a file of its own, by absolute path (Webots runs it in its own folder).
    env_file = out.with_name(f"{out.stem}.env.yaml").resolve() if config else None
    written = write_world(out, cfg, seed, physics, policy, env_file, controller)
    if env_file is not None:
        import yaml

        env_file.write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))
        written.append(env_file)
    for path in written:
        console.print(f"wrote {path}")
    console.print("open the world in Webots (R2023b or later); see docs/physics.md")
