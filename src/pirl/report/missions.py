"""The missions of a reproduction (``reproduce.missions``): for each evaluation site, the
planner's mission and the best learned policy's, written by ``pirl plan``'s writer into
``<out>/missions/<site>-<planner|learned>/``, flown back from their files in PyFlyt
(``pirl fly``), and the report's table and figure of them.

"Best learned policy": the trained run with the highest mean VCR on that site in the grid
evaluation in the headline act mode, written acting in that same mode (stochastic: one seeded
episode, as fixed as a greedy one once written): a choice for display, named as such in the
table, not a result.
"""

from __future__ import annotations

import json
import shutil
import textwrap
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pirl.agents.methods import PLANNER
from pirl.config.run import RunConfig
from pirl.report.tables import Cell, Span, Table

SCENARIO_SEED = 0
"""The scenario (the site's start draw) every reproduction mission is written from."""

_HEADER = (
    "site", "mission", "items (before merging)", "sorties", "distance m", "flight min",
    "photos", "VCR grid", "VCR flown", "energy flown / grid", "end", "files",
)  # fmt: skip


def best_run(records: list[dict[str, Any]], site: str, act: str) -> tuple[Path, float] | None:
    """The trained run with the highest mean grid VCR on ``site`` acting ``act``, and that
    mean; None when no trained run was evaluated there. Runs of equal mean VCR are told
    apart by their mean steps, fewer first (the same coverage in a shorter flight)."""
    by_run: dict[str, list[tuple[float, int]]] = defaultdict(list)
    for r in records:
        trained = r.get("train_seed") is not None and r.get("act") == act
        if trained and r.get("site") == site and r.get("sim") == "grid":
            by_run[str(r["source"])].append((float(r["vcr"]), int(r["steps"])))
    if not by_run:
        return None

    def merit(source: str) -> tuple[float, float]:
        vcr, steps = np.mean(by_run[source], axis=0)
        return float(vcr), -float(steps)

    source = max(sorted(by_run), key=merit)
    return Path(source), merit(source)[0]


def _mission(
    cfg: RunConfig,
    folder: Path,
    site: str,
    log: Callable[[str], Any],
    policy: Path | None = None,
    method: str | None = None,
) -> dict[str, Any]:
    """Write (unless already written and flown) and fly one mission; its summary and flight."""
    from pirl.missions.fly import fly_mission
    from pirl.missions.write import mission_source, write_mission

    done = folder / "flown.json"
    if (folder / "summary.json").is_file() and done.is_file():
        summary = json.loads((folder / "summary.json").read_text())
    else:
        shutil.rmtree(folder, ignore_errors=True)  # a half-made one from an interrupted run
        act = cfg.reproduce.headline_act  # the act mode the run was chosen by
        env, chosen, what = mission_source(cfg.env, SCENARIO_SEED, policy, method, act, site)
        summary = write_mission(folder, env, cfg.mission, chosen, SCENARIO_SEED, what)
    log(f"missions: flying {folder.name} back from its files in PyFlyt")
    flown = fly_mission(folder, cfg.physics, log=lambda line: log(f"missions: {line}"))
    return {"folder": folder, "summary": summary, "flown": flown}


def _mission_in_worker(
    cfg: RunConfig, folder: Path, site: str, policy: Path | None, method: str | None
) -> tuple[dict[str, Any], list[str]]:
    """:func:`_mission` in a pool's worker: its entry and the lines it would have logged."""
    import torch

    torch.set_num_threads(1)
    lines: list[str] = []
    return _mission(cfg, folder, site, lines.append, policy, method), lines


def reproduction_missions(
    cfg: RunConfig,
    out: Path,
    sites: list[str],
    records: list[dict[str, Any]],
    log: Callable[[str], Any] = print,
) -> tuple[str, Table, Path] | None:
    """Write and fly the planner's and the best learned policy's mission on every site, in up
    to ``reproduce.workers`` processes (each flight is one PyFlyt process's work); the
    report's (title, table, figure)."""
    if not sites:
        return None
    act = cfg.reproduce.headline_act
    # (site, folder, policy, method, why this policy) per mission, in the table's order
    jobs: list[tuple[str, Path, Path | None, str | None, str | None]] = []
    for site in sites:
        name = Path(site).name
        jobs.append((site, out / "missions" / f"{name}-planner", None, PLANNER.name, None))
        best = best_run(records, name, act)
        if best is not None:
            chosen = f"best mean grid VCR on {name} acting {act}: {best[1]:.3f}"
            jobs.append((site, out / "missions" / f"{name}-learned", best[0], None, chosen))
    workers = min(cfg.reproduce.workers, len(jobs))
    if workers > 1:
        from pirl.evaluate.runner import process_pool

        names = ", ".join(folder.name for _, folder, *_ in jobs)
        log(f"missions: writing and flying {names} in {workers} processes")
        with process_pool(workers) as pool:
            futures = [pool.submit(_mission_in_worker, cfg, f, s, p, m) for s, f, p, m, _ in jobs]
            entries = []
            for future in futures:
                entry, lines = future.result()
                for line in lines:
                    log(line)
                entries.append(entry)
    else:
        entries = [_mission(cfg, f, s, log, p, m) for s, f, p, m, _ in jobs]
    rows: dict[str, tuple[str, str, list[dict[str, Any]]]] = {}
    for (site, _, _, _, chosen), entry in zip(jobs, entries, strict=True):
        if chosen is not None:
            entry["chosen"] = chosen
        rows.setdefault(site, (Path(site).name, site, []))[2].append(entry)
    table_rows = list(rows.values())
    report = out / "report"
    return "Missions", section(table_rows, report), figure(table_rows, report / "missions.png")


def section(rows: list[tuple[str, str, list[dict[str, Any]]]], report: Path) -> Table:
    """The table: written mission figures, flown figures, links to the files (relative to
    the ``report`` folder)."""
    body: list[list[Cell]] = []
    for name, _site, entries in rows:
        for e in entries:
            s, f = e["summary"], e["flown"]
            rel = Path("..") / e["folder"].relative_to(report.parent)
            links = [Span(p, href=(rel / p).as_posix()) for p in [*f["plans"], "path.kml"]]
            chosen = f" ({e['chosen']})" if "chosen" in e else ""
            body.append([
                name, f"{s['method']}{chosen}",
                f"{s['items_after_merging']} ({s['items_before_merging']})", str(s["sorties"]),
                f"{s['distance_m']:,.0f}", f"{s['flight_time_s'] / 60:.1f}", str(s["photos"]),
                f"{s['vcr']:.3f}", f"{f['vcr']:.3f}",
                f"{f['energy_used']:.3f} / {f['energy_used_grid']:.3f}", str(f["end"]),
                tuple(part for link in links for part in (Span(" "), link))[1:],
            ])  # fmt: skip
    return Table(
        "Missions: written, then flown back from the files",
        _HEADER,
        body,
        intro=[
            f"Each mission is one episode of scenario {SCENARIO_SEED} (wind off) written by "
            "`pirl plan`, then read back from its .plan files and flown in PyFlyt with the "
            "physics section's wind (`pirl fly`). Learned: the trained run named, acting in the "
            "act mode it was chosen by."
        ],
        level=2,
    )


def figure(rows: list[tuple[str, str, list[dict[str, Any]]]], path: Path) -> Path:
    """Per site and mission: the map (buildings by height), the ground cells the flight saw
    and the written waypoints' line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pirl.report.figures import style, width

    n = sum(len(e) for _, _, e in rows)
    with style():
        fig, axes = plt.subplots(1, n, figsize=(width(n, 4.2), 4.4), squeeze=False)
        _panels(axes[0], rows)
        fig.suptitle(
            "Missions flown from their files (green: ground seen in flight; red: waypoints)"
        )
        fig.tight_layout(rect=(0, 0, 1, 0.95))  # the panels' titles below the figure's
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path)
        plt.close(fig)
    return path


def _panels(axes: Any, rows: list[tuple[str, str, list[dict[str, Any]]]]) -> None:
    """One panel per site and mission: map, ground seen in flight, waypoints."""
    from pirl.missions.fly import read_flight
    from pirl.world.site import load_site

    k = 0
    for name, site_path, entries in rows:
        site = load_site(site_path)
        for e in entries:
            ax = axes[k]
            k += 1
            ax.imshow(site.heights.T, origin="lower", cmap="Greys", interpolation="nearest")
            seen = np.ma.masked_where(~e["flown"]["covered"].T, e["flown"]["covered"].T)
            ax.imshow(seen, origin="lower", cmap="summer", alpha=0.45, interpolation="nearest")
            cells = [op.cell for op in read_flight(e["folder"]).ops if op.kind == "goto"]
            xy = np.array([(c[0], c[1]) for c in cells if c is not None])
            if len(xy):
                ax.plot(xy[:, 0], xy[:, 1], color="tab:red", lw=0.8)
            # Wrapped, not cut: a learned mission's title names its run and act mode.
            what = textwrap.wrap(f"{name}: {e['summary']['method']}", 44)
            ax.set_title(
                "\n".join(what) + f"\nflown VCR {e['flown']['vcr']:.3f} "
                f"(grid {e['summary']['vcr']:.3f})",
            )
            ax.set_xticks([])
            ax.set_yticks([])


__all__ = ["best_run", "figure", "reproduction_missions", "section"]
