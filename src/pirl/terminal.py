"""The terminal side of the ``pirl`` command line: its consoles, the parsing of list options,
errors as one line, Ctrl-C with worker processes, and the tables and lines commands print.

:mod:`pirl.cli` declares the commands and calls the library; what they read from and show on
the terminal lives here, so the commands stay a page each.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from pirl.advice.registry import advisor_names
from pirl.agents.methods import PLAYED_ALONE
from pirl.config.errors import ConfigError
from pirl.config.presets import load_preset

if TYPE_CHECKING:
    from pirl.config.world import VCPPConfig


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


def uavs_option(help: str) -> Any:
    """``--uavs K[,K...]``: fleet sizes (whole numbers; their bounds are the env's)."""
    return list_option("--uavs", help, "K[,K...]", int, "a whole number of UAVs")


def bad_value(option: str, value: str, why: str) -> typer.Exit:
    """A wrong value of an option, seen while parsing: one line and exit 2 (the project's rule
    for a user's mistake; Typer's own error is a usage box)."""
    err.print(f"[bold red]error:[/] {escape(f'{option} {value!r}: {why}')}", soft_wrap=True)
    return typer.Exit(2)


def comma_parser(option: str, item: Callable[[str], T], what: str) -> Callable[[str], list[T]]:
    """Typer's parser of one value of a list option: ``30,45`` holds two, each read by
    ``item`` (a ValueError of one is ``not {what}``)."""

    def parse(text: str) -> list[T]:
        values: list[T] = []
        for part in (p.strip() for p in text.split(",")):
            if not part:
                raise bad_value(option, text, f"an empty value (write {option} A,B)")
            try:
                values.append(item(part))
            except ValueError:
                raise bad_value(option, text, f"{part!r} is not {what}") from None
        return values

    return parse


def flatten(values: list[list[T]] | None) -> list[T] | None:
    """Typer's callback of a list option: the values of every occurrence, in order."""
    return [v for group in values for v in group] if values else None


def list_option(
    option: str, help: str, metavar: str, item: Callable[[str], Any] = str, what: str = "valid"
) -> Any:
    """A list option that Typer parses: repeated (``--sizes 30 --sizes 45``), comma-separated
    (``--sizes 30,45``) or both. For names, sizes and numbers; a list of paths is a plain
    repeated option instead, since a path may hold a comma."""
    return typer.Option(
        option,
        help=f"{help} Comma-separated or repeated.",
        metavar=metavar,
        parser=comma_parser(option, item, what),
        callback=flatten,
    )


def clean_errors(fn: Callable[..., Any]) -> Callable[..., Any]:
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


def interrupted(message: str) -> typer.Exit:
    """Ctrl-C in a command with worker processes: one line, exit 130."""
    err.print(f"interrupted: {message}", soft_wrap=True, highlight=False, markup=False)
    return typer.Exit(130)


class StopWorkersOnCtrlC:
    """While active, Ctrl-C first stops this process's worker processes (they ignore it, so
    none prints a traceback; a pool then finds them gone instead of waiting for their
    work), then raises ``KeyboardInterrupt`` here as usual."""

    def __enter__(self) -> StopWorkersOnCtrlC:
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


def or_list(names: list[str] | tuple[str, ...]) -> str:
    """``a, b or c``, for help texts."""
    names = list(names)
    return ", ".join(names[:-1]) + f" or {names[-1]}" if len(names) > 1 else "".join(names)


ADVISORS = or_list(advisor_names())
"""The advisors --advisor takes: the built-ins and the installed plugins'."""


def env_settings(
    config: str | None,
    size: tuple[int, int, int],
    footprint: str | None,
    site: Path | None = None,
) -> VCPPConfig:
    """``--config``'s env section with ``--size`` and, when given, ``--footprint`` and
    ``--site`` applied."""
    env = load_preset(config).env.replace(size=tuple(size))
    env = env.replace(footprint=footprint) if footprint is not None else env
    if site is not None:
        from pirl.world.seeable import with_site

        env = with_site(env, str(site))
    return env


def make_policy(name: str, seed: int):
    from pirl.agents.loading import load_policy

    if name not in PLAYED_ALONE:
        raise ConfigError(f"--policy {name!r}: allowed values are {', '.join(PLAYED_ALONE)}")
    return load_policy(name, seed=seed)


def metrics_table(rows: list[tuple[str, dict[str, float]]], title: str) -> Table:
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


def command_line() -> str:
    """The command as typed (quoted for a shell), for a "run it again" hint."""
    import shlex
    import sys

    return "pirl " + shlex.join(sys.argv[1:])


def mean_ci(mean: float, half: float) -> str:
    """``mean ± half``, or the mean alone when there is no interval (n = 1)."""
    import math

    return f"{mean:.3f}" if math.isnan(half) else f"{mean:.3f} ± {half:.3f}"


def episode_progress(bar: Any, label: str) -> Any:
    """Evaluation progress on the command's bar (a plain line every 10 s off a terminal)."""
    from pirl.progress import Progress

    return Progress(
        label, line="{label}: {done}/{total} episodes", bar=bar, tty=console.is_terminal,
        final_at_total=True, out=lambda text: console.print(text, highlight=False),
    )  # fmt: skip


@contextlib.contextmanager
def episode_bar(label: str) -> Iterator[Any]:
    """:func:`episode_progress` on a bar of its own, with Ctrl-C stopping the worker
    processes first (:class:`StopWorkersOnCtrlC`)."""
    from rich.progress import Progress

    with StopWorkersOnCtrlC(), Progress(console=console, transient=True) as bar:
        yield episode_progress(bar, label)


def summary_table(path: Path) -> Table:
    from pirl.evaluate.summary import read_summary

    rows = read_summary(path)
    # A fleet's rows say their fleet size and speed-up (makespan to 0.99, over one UAV's).
    fleet = any(int(r.get("uavs", 1)) > 1 for r in rows)
    table = Table(title=f"{path} (mean ± 95% CI over episodes; IQM [interval] over seeds)")
    columns = ["method", "sim", "act", "size", *(["UAVs"] if fleet else []), "n", "seeds"]
    for col in (*columns, "VCR", "BE", "RVC", "VCR IQM", *(["speed-up"] if fleet else [])):
        table.add_column(col)
    for row in rows:
        cells = [mean_ci(row[m + "_mean"], row[m + "_ci95"]) for m in ("vcr", "be", "rvc")]
        seeds = int(row.get("seeds", 1))
        iqm = f"{row['vcr_iqm']:.3f}"
        if seeds > 1:
            iqm += f" [{row['vcr_iqm_lo']:.3f}, {row['vcr_iqm_hi']:.3f}]"
        uavs = [str(int(row.get("uavs", 1)))] if fleet else []
        speed = [mean_ci(row["speed_up_mean"], row["speed_up_ci95"])] if fleet else []
        table.add_row(
            row["label"], row["sim"], row.get("act", ""), row["size"], *uavs, str(int(row["n"])),
            str(seeds), *cells, iqm, *speed,
        )  # fmt: skip
    return table


def print_score(
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
    from rich.progress import Progress

    from pirl._atomic import write_json
    from pirl.advice.factory import make_advisor
    from pirl.evaluate.advice_score import price_run, score_advisor

    if n < 1:
        raise ConfigError(f"--score {n}: ask about at least 1 state")
    if out is not None and out.is_dir():
        raise ConfigError(f"--out {out} is a folder; give the JSON file to write")
    priced = load_preset(profile, "--profile").with_overrides(pare={"advisor": name})
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
        write_json(out, data)
        console.print(f"wrote {out}")


def copies_format_example(rec: Any, prompt: str) -> bool:
    """Whether the parsed answer is exactly the format example the prompt shows."""
    from pirl.advice.parser import parse_recommendation
    from pirl.advice.recommendation import FORMAT_EXAMPLE

    return (
        rec is not None and FORMAT_EXAMPLE in prompt and rec == parse_recommendation(FORMAT_EXAMPLE)
    )


def fly_and_print(folder: Path, physics: Any, wind: bool = True) -> None:
    from pirl.missions.fleet import FLEET_FILE, fly_fleet
    from pirl.missions.fly import fly_mission, read_flight

    if (folder / FLEET_FILE).is_file():
        console.print(
            f"flying the fleet in {folder} back from its files in PyFlyt, together in one "
            f"Aviary{' with wind' if wind else ', no wind'} ..."
        )
        f = fly_fleet(folder, physics, wind, log=lambda line: console.print(line, highlight=False))
        for m in f["members"]:
            console.print(
                f"{m['folder']}: VCR {m['vcr_own']:.3f} of its own flight (credited in the "
                f"grid {m['vcr_grid']:.3f}), energy {m['energy_used']:.3f} of a battery (grid "
                f"{m['energy_used_grid']:.3f}), end {m['end']}, {m['contacts']} contacts"
            )
        waiting = (
            "no drone waited for its take-off"
            if f["closest_to_waiting_m"] is None
            else f"{f['closest_to_waiting_m']} m to a drone waiting at home"
        )
        console.print(
            f"fleet flown: VCR {f['vcr']:.3f} (grid {f['vcr_grid']:.3f}), energy "
            f"{f['energy_used']:.3f} batteries, {f['contacts_between_drones']} contacts between "
            f"drones (closest {f['closest_approach_m']} m in flight, {waiting}); wrote "
            f"{folder / 'flown.json'}"
        )
        return

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


def show_prompt(prompt: str) -> None:
    """``pirl advise``: the prompt under a rule, as written (no markup)."""
    console.rule("prompt")
    console.print(prompt, markup=False, highlight=False)


def print_advice_check(check: Any, prompt_variant: str) -> bool:
    """``pirl advise``: the advisor's answer about one state and what it cost; whether it is
    advice (parsed, and not the prompt's own format example)."""
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
    copied = copies_format_example(rec, prompt)
    if copied:
        console.print(
            "[bold yellow]warning:[/] the answer is the prompt's own format example, not advice "
            f"for this state (prompt variant {prompt_variant!r}). The embedded model "
            "suits the compact prompt: pare.prompt_variant: compact (as in configs/quick.yaml, "
            "e.g. --config quick)."
        )
    return rec is not None and not copied


def print_site_report(report: dict[str, Any], reasons: dict[str, str]) -> None:
    """``pirl site check``: a site's size, cells and every reason a cell cannot be seen."""
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
            console.print(f"  {count:,} cannot be seen: {reasons[reason]}")
    lo, hi = report["elevation_m"]
    console.print(f"ground: {report['ground']}")
    if hi > lo:
        console.print(
            f"  {lo:g}-{hi:g} m above sea level, slope {report['slope_deg']['mean']:g} deg "
            f"mean, {report['slope_deg']['max']:g} max"
        )
    g0, g1 = report["gsd_cm_per_px"]
    h0, h1 = report["height_above_seen_ground_m"]
    console.print(
        f"ground sample distance {g0:.2f}-{g1:.2f} cm/px, {h0:g}-{h1:g} m above the ground seen"
    )
    if "picture" in report:
        console.print(f"wrote {report['picture']}")


def print_site_check(report: dict[str, Any], as_json: bool) -> bool:
    """``pirl site check``: the report as one JSON object or as lines; whether the site is
    usable (an unusable one is an error line on stderr, unless the JSON says it)."""
    import json

    from pirl.missions.site_check import REASON_TEXT

    if as_json:
        print(json.dumps(report, sort_keys=True))
    else:
        print_site_report(report, REASON_TEXT)
    if not report["usable"] and not as_json:
        err.print("[bold red]error:[/] no coverable cell can be seen: the site is unusable")
    return bool(report["usable"])


def print_plan_summary(out: Path, what: str, summary: dict[str, Any], speed_m_s: float) -> None:
    """``pirl plan``: the written mission in one line (coverage, sorties, distance, time),
    then its files."""
    console.print(
        f"{what}: VCR {summary['vcr']:.3f} over seeable cells; {summary['sorties']} sortie(s), "
        f"items {summary['items_per_sortie']} ({summary['items_before_merging']} before "
        f"merging legs), {summary['distance_m']:,.0f} m, {summary['flight_time_s'] / 60:.1f} min "
        f"at {speed_m_s:g} m/s, {summary['photos']} photos"
        + ("" if summary["real_place"] else "; NOT a real place (a generated world)")
    )
    console.print(f"wrote {out}: {', '.join(summary['files'])}")


def print_fleet_summary(out: Path, fleet: dict[str, Any]) -> None:
    """``pirl plan --uavs K``: the fleet's missions in three lines (coverage, time, distance)."""
    apart = fleet["separation"]
    delays = [max(m["takeoff_delay_s"], default=0.0) for m in fleet["members"]]
    console.print(
        f"{fleet['method']}, {fleet['uavs']} UAVs: fleet VCR {fleet['vcr']:.3f} over seeable "
        f"cells in {fleet['grid_steps']} grid steps (0.99 at step {fleet['makespan_99']}); "
        f"{fleet['flight_time_s'] / 60:.1f} min of flight, "
        f"{sum(m['distance_m'] for m in fleet['members']):,.0f} m in all"
    )
    console.print(
        f"separation {fleet['separation_m']:g} m held at {apart['samples']:,} instants: closest "
        f"approach {apart['closest_horizontal_m']} m horizontally within "
        f"{fleet['separation_m']:g} m of altitude, {apart['closest_3d_m']} m in 3-D; take-off "
        f"delays up to {', '.join(f'{d:g}' for d in delays)} s"
    )
    folders = ", ".join(f"{m['folder']}/ ({m['sorties']} sortie(s))" for m in fleet["members"])
    console.print(f"wrote {out}: {folders}, fleet.json")


def print_distilled(record: dict[str, Any], out: Path) -> None:
    """``pirl distill``: the student's agreement with its teacher, and where it was written."""
    from pirl.advice.student import STUDENT_FILE

    console.print(
        f"{record['label']}: agreement {record['agreement']:.3f} (majority "
        f"{record['majority']:.3f}) on {record['heldout']} held-out answers; "
        f"{record['dataset_size']} answers in the dataset"
    )
    console.print(f"wrote {out / STUDENT_FILE}; train with --student {out}")


def training_ended(stop: Exception) -> typer.Exit:
    """A training run that ended early, in one line: Ctrl-C (exit 130) or an advisor that
    kept failing (exit 3); both say where the checkpoint is and how to continue."""
    from pirl.agents.stops import TrainingInterrupted

    if isinstance(stop, TrainingInterrupted):
        err.print(
            f"interrupted: checkpoint saved at {stop.checkpoint}; continue with --resume",
            soft_wrap=True,
        )
        return typer.Exit(130)
    err.print(
        f"[bold red]stopped:[/] {escape(getattr(stop, 'reason', str(stop)))}; checkpoint: "
        f"{getattr(stop, 'checkpoint', '')}; "
        "fix the advisor, then continue with --resume",
        soft_wrap=True,  # one line whatever the width: logs and tests read it whole
    )
    return typer.Exit(3)


@contextlib.contextmanager
def count_progress(label: str, line: str, total: int) -> Iterator[Callable[[int, int], None]]:
    """A bar counting to ``total`` (off a terminal, ``line`` every 500 or so), and the
    ``progress(done, total)`` callback that moves it."""
    from rich.progress import Progress

    with Progress(console=console, transient=True) as bar:
        task = bar.add_task(label, total=total)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)
            if not console.is_terminal and (done == total or done % 500 < 32):
                console.print(line.format(done=done, total=total))

        yield progress
