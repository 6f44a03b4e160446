"""The ``pirl`` command line. Thin: it parses options and calls the modules below it."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from pirl.advice.registry import DEFAULT_ADVISOR, advisor_kind
from pirl.agents.methods import BUILTIN, PLAYED_ALONE, TRAINED
from pirl.config.choices import Sim
from pirl.config.errors import ConfigError
from pirl.config.load import check_seed
from pirl.config.presets import load_preset, preset_path
from pirl.terminal import (
    ADVISORS,
    ConfigOpt,
    RayOpt,
    SizeOpt,
    clean_errors,
    command_line,
    console,
    count_progress,
    env_settings,
    episode_bar,
    fly_and_print,
    interrupted,
    list_option,
    make_policy,
    metrics_table,
    or_list,
    print_advice_check,
    print_distilled,
    print_fleet_summary,
    print_plan_summary,
    print_score,
    print_site_check,
    show_prompt,
    summary_table,
    training_ended,
    uavs_option,
)

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="PIRL: prompt-informed RL for UAV visual coverage path planning.",
)


@app.command()
@clean_errors
def render(
    policy: Annotated[str, typer.Option(help=f"{or_list(PLAYED_ALONE)}.")] = "random",
    size: SizeOpt = (30, 30, 3),
    seed: Annotated[int, typer.Option(help="Scenario seed.")] = 0,
    out: Annotated[Path, typer.Option(help="GIF to write.")] = Path("episode.gif"),
    footprint: Annotated[str | None, typer.Option(help="paper or frustum.")] = None,
    config: ConfigOpt = None,
    fps: Annotated[int, typer.Option(help="Frames per second of the GIF.")] = 12,
    site: Annotated[
        Path | None, typer.Option(help="A site folder to fly instead of a generated world.")
    ] = None,
    uavs: Annotated[int, typer.Option(help="A fleet of K UAVs (docs/fleets.md).")] = 1,
) -> None:
    """Fly one episode with a simple policy and write it as an animated GIF."""
    from pirl.evaluate.rollout import check_gif_target, record_gif

    check_seed(seed)
    check_gif_target(out, fps)
    cfg = env_settings(config, size, footprint, site).replace(uavs=uavs)
    result, path = record_gif(cfg, make_policy(policy, seed), seed, out, fps)
    console.print(metrics_table([(policy, result.metrics)], f"{cfg.size} seed {seed}"))
    console.print(f"wrote {path} ({len(result.frames)} frames)")


@app.command()
@clean_errors
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
        list_option(
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
    from pirl.agents.stops import TrainingInterrupted
    from pirl.reproduce.pipeline import reproduce as run
    from pirl.reproduce.pipeline import reproduce_settings

    path, cfg, out, advisor = reproduce_settings(profile, config, seeds, out, advisor)
    console.print(f"reproduce: profile {path}, advisor {advisor}, output {out}")
    try:
        with episode_bar("evaluation") as progress:
            report = run(
                cfg, out, advisor, workers, log=lambda m: console.print(m), progress=progress,
                ray_address=ray_address,
            )  # fmt: skip
    except (KeyboardInterrupt, TrainingInterrupted):
        raise interrupted(
            f"finished runs and the last checkpoint of each run in progress are kept in {out}; "
            f"run the same command to resume: {command_line()}"
        ) from None
    console.print(f"[bold]report:[/] {report}")
    console.print(f"tables: {report.parent / 'table.md'}")


@app.command()
@clean_errors
def demo(
    out: Annotated[Path, typer.Option(help="Output folder.")] = Path("results/quick"),
    advisor: Annotated[str | None, typer.Option(help="PIRL's advisor (default: quick's).")] = None,
) -> None:
    """The main job on the embedded defaults: ``pirl reproduce --profile quick``."""
    reproduce(profile="quick", advisor=advisor, seeds=None, workers=None, out=out, config=None)


@app.command()
@clean_errors
def train(
    method: Annotated[str, typer.Option(help=f"{or_list(TRAINED)}.")],
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
    uavs: Annotated[
        list[int] | None,
        uavs_option(
            "Fleet sizes to train with (train.uavs; PPO methods and PIRL): one policy shared "
            "by every UAV of worlds of each size (docs/fleets.md)."
        ),
    ] = None,
) -> None:
    """Train one method into a run folder (checkpoints, TensorBoard logs, metrics CSV)."""
    from pirl.agents.runs import train_run
    from pirl.agents.stops import TrainingInterrupted, TrainingStopped

    try:
        result = train_run(
            method, out, config, "quick",
            steps=steps, seed=seed, advisor=advisor, expert=expert, resume=resume,
            student=student, site=site, uavs=uavs,
        )  # fmt: skip
    except (TrainingInterrupted, TrainingStopped) as stop:
        raise training_ended(stop) from None
    console.print(f"done: {result}")


@app.command()
@clean_errors
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
    from pirl.agents.distill import distill as run_distill

    cfg = load_preset(config)
    advisor_kind(teacher).check_key(cfg)
    sources = policy or list(PLAYED_ALONE)
    with count_progress("teacher answers", "distill: {done}/{total} answers", states) as progress:
        record = run_distill(
            cfg, teacher, states, out, sources, seed=seed, fit_steps=fit_steps, progress=progress,
        )  # fmt: skip
    print_distilled(record, out)


@app.command()
@clean_errors
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
        list_option("--methods", f"Built-in methods: {', '.join(BUILTIN)}.", "NAME[,NAME...]"),
    ] = None,
    sizes: Annotated[
        list[str] | None,
        list_option("--sizes", "N (NxNx3) or XxYxZ, default 30,45,60.", "SIZE[,SIZE...]"),
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
        list[str] | None, list_option("--sim", "Simulators: grid, physics.", "SIM[,SIM...]")
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
    uavs: Annotated[
        list[int] | None,
        uavs_option(
            "Fleet sizes (docs/fleets.md): each scenario flown by K UAVs, K = 1 included, with "
            "makespans and speed-ups; default one UAV."
        ),
    ] = None,
) -> None:
    """Evaluate trained runs and built-in methods on the same scenarios of each size."""
    from pirl.evaluate.runner import evaluate_runs

    try:
        with episode_bar("episodes") as progress:
            summary = evaluate_runs(
                out, list(runs or []), methods or [],
                sizes if sizes is not None else ([] if site else ["30", "45", "60"]),
                episodes, sim or ["grid"],
                workers, preset_path(config) if config is not None else None, advisor,
                act, overwrite, progress=progress,
                ray_address=ray_address, sites=list(site or []), uavs=uavs or [1],
            )  # fmt: skip
    except KeyboardInterrupt:
        raise interrupted(
            f"no results written to {out} (they are written once every episode is done); "
            f"run the same command to start again: {command_line()}"
        ) from None
    console.print(summary_table(summary))
    console.print(f"wrote {out / 'episodes.jsonl'} and {summary}")


@app.command()
@clean_errors
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
    from pirl.advice.health import advise_settings, check_advisor

    check_seed(seed)
    cfg = advise_settings(config, advisor, model, base_url)
    if score is not None:
        print_score(cfg, advisor, score, out, price_in, price_out, profile, cache, seed)
        return
    check = check_advisor(
        cfg, advisor, tuple(size), seed, cache, show_prompt, log=lambda m: console.print(m)
    )
    if not print_advice_check(check, cfg.pare.prompt_variant):
        raise typer.Exit(1)


def main() -> None:
    """Console entry point: Typer parses the command line as given."""
    from pirl import _quiet

    _quiet.install()
    app(prog_name="pirl")


@app.command()
@clean_errors
def plan(
    out: Annotated[Path, typer.Option(help="The mission folder to write (must not exist).")],
    site: Annotated[Path | None, typer.Option(help="A site folder (docs/sites.md).")] = None,
    size: Annotated[
        tuple[int, int, int] | None, typer.Option(help="A generated world X Y Z instead.")
    ] = None,
    seed: Annotated[int, typer.Option(help="Scenario seed (start cell; obstacles).")] = 0,
    policy: Annotated[Path | None, typer.Option(help="A trained run folder to fly.")] = None,
    method: Annotated[
        str | None, typer.Option(help=f"A built-in instead: {or_list(PLAYED_ALONE)}.")
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
    uavs: Annotated[
        int,
        typer.Option(
            help="A fleet of K UAVs: a mission folder per UAV (uav-1/, ...) and fleet.json, "
            "kept apart in time (docs/fleets.md)."
        ),
    ] = 1,
) -> None:
    """Write one episode as missions a drone can fly (QGroundControl .plan, QGC WPL 110,
    GeoJSON, KML), split into battery-sized sorties (docs/missions.md)."""
    from pirl.missions.fleet import plan_missions

    check_seed(seed)
    if fly not in (None, Sim.PHYSICS):
        raise ConfigError(f"--fly {fly!r}: allowed value is physics")
    cfg = load_preset(config)
    what, summary = plan_missions(
        out, cfg, seed, policy, method, act, site, size, gimbal, uavs, bool(fly)
    )
    if uavs != 1:
        print_fleet_summary(out, summary)
    else:
        print_plan_summary(out, what, summary, cfg.mission.speed_m_s)
    if fly:
        fly_and_print(out, cfg.physics)


@app.command()
@clean_errors
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
    cfg = load_preset(config)
    fly_and_print(mission, cfg.physics, wind)


site_app = typer.Typer(no_args_is_help=True, help="Bring your own site (docs/sites.md).")
app.add_typer(site_app, name="site")


@site_app.command("check")
@clean_errors
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
    from pirl.missions.site_check import site_report

    env = load_preset(config).env if config else None
    if not print_site_check(site_report(site, env, picture), as_json):
        raise typer.Exit(1)


@site_app.command("import-uavsim")
@clean_errors
def site_import_uavsim(
    map_png: Annotated[Path, typer.Argument(help="A uavSim map PNG (res/*.png).")],
    out: Annotated[Path, typer.Option(help="The site folder to write (must not exist).")],
) -> None:
    """Turn a uavSim map (red no-fly, green obstacle, blue start) into a site folder."""
    from pirl.world.uavsim import import_uavsim

    folder = import_uavsim(map_png, out)
    console.print(f"wrote {folder}; check it with: pirl site check {folder}")


@app.command("webots-world")
@clean_errors
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
    from pirl.physics.webots.world import write_mavic_world

    cfg = env_settings(config, size, footprint)
    written = write_mavic_world(out, cfg, seed, policy, cell_size, bool(config), controller)
    for path in written:
        console.print(f"wrote {path}")
    console.print("open the world in Webots (R2023b or later); see docs/physics.md")
