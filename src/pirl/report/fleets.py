"""The report's fleet section: the Fleets table (method x fleet size) and the fleet's
coverage against time, from the rows and episodes ``pirl evaluate --uavs`` wrote
(:mod:`pirl.evaluate.fleet`)."""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pirl.agents.methods import report_order
from pirl.evaluate.fleet import CURVE
from pirl.evaluate.summary import size_key
from pirl.report.figures import style, width
from pirl.report.names import name_cell
from pirl.report.tables import Cell, Table

FIGURE_UAVS = (1, 2, 4)
"""Fleet sizes the coverage figure draws (those evaluated)."""


def single(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows (or episodes) of one UAV: what the paper's tables compare."""
    return [r for r in rows if int(r.get("uavs") or 1) <= 1]


def fleet_table(rows: list[dict[str, Any]], names: Mapping[str, str]) -> Table | None:
    """Method x fleet size per world and act mode: VCR (IQM over seeds, interval), makespan
    to 0.99 (mean steps over the episodes that reached it), speed-up over one UAV from the
    same scenarios (mean ± 95% CI), energy (batteries), overlap between UAVs and near misses;
    None when no fleet was evaluated."""
    fleet = [r for r in rows if int(r.get("uavs", 1)) > 1]
    if not fleet:
        return None
    keys = {(r["method"], r["sim"], r["size"], r.get("act", "")) for r in fleet}
    # A reproduction evaluates one UAV twice: with the paper's tables and with the fleets.
    # One row per fleet size: the fleet evaluation's, which has the fleet's figures.
    chosen: dict[tuple, dict[str, Any]] = {}
    for r in rows:
        key = (r["method"], r["sim"], r["size"], r.get("act", ""))
        if key not in keys:
            continue
        slot = (*key, r["label"], int(r.get("uavs") or 1))
        if slot not in chosen or _has_fleet_figures(r):
            chosen[slot] = r
    shown = list(chosen.values())
    shown.sort(
        key=lambda r: (
            size_key(r["size"]),
            r.get("act", ""),
            report_order(r["method"]),
            r["label"],
            int(r["uavs"]),
        )  # fmt: skip
    )
    head = ["world", "act", "method", "UAVs", "VCR (IQM)", "makespan 0.99 (steps)"]
    head += ["speed-up", "energy (batteries)", "overlap", "near misses"]
    body: list[list[Cell]] = []
    for r in shown:
        vcr = f"{r['vcr_iqm']:.2f}"
        if int(r.get("seeds", 1)) > 1:
            vcr += f" [{r['vcr_iqm_lo']:.2f}, {r['vcr_iqm_hi']:.2f}]"
        reached = int(r.get("reached_99", 0))
        makespan = "never" if not reached else f"{r['steps_to_99_mean']:.0f}"
        if reached and reached < int(r["n"]):
            makespan += f" ({reached} of {int(r['n'])})"
        body.append([
            r["size"], r.get("act", ""), name_cell(r["label"], names.get(r["method"])),
            str(int(r["uavs"])), vcr, makespan, _speed_up(r),
            f"{r.get('energy_used_mean', math.nan):.2f}",
            f"{r.get('uav_overlap_mean', math.nan):.2f}",
            f"{r.get('near_misses_mean', math.nan):.1f}",
        ])  # fmt: skip
    return Table(
        "Fleets (grid simulator)",
        head,
        body,
        intro=[
            "K UAVs cover each scenario together (docs/fleets.md). Speed-up: makespan to 0.99 "
            "of seeable cells with K UAVs over one UAV's, same scenarios (1/K: "
            "perfect sharing; 1: no gain). Overlap: ground cells seen by more than one UAV, over "
            "cells seen. Near misses: pairs of UAVs in adjacent cells, summed over steps."
        ],
    )


def _has_fleet_figures(row: dict[str, Any]) -> bool:
    """Whether a summary row comes from a fleet evaluation (its overlap is a number)."""
    try:
        return not math.isnan(float(row.get("uav_overlap_mean")))
    except (TypeError, ValueError):  # absent or empty
        return False


def _speed_up(row: Mapping[str, Any]) -> str:
    mean, half = row.get("speed_up_mean", math.nan), row.get("speed_up_ci95", math.nan)
    if _nan(mean):
        return "—"
    return f"{mean:.2f}" if _nan(half) else f"{mean:.2f} ± {half:.2f}"


def _nan(value: Any) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value))


def coverage_figure(
    records: list[dict[str, Any]], path: Path, names: Mapping[str, str]
) -> Path | None:
    """The fleet's coverage against its steps for K = 1, 2, 4, one panel per world (at most
    three), one colour per method and one line style per K: the median over scenarios of the
    step at which each share of the seeable cells was first covered. None without fleets."""
    curves: dict[tuple[str, str, int], list[list[int | None]]] = defaultdict(list)
    for r in records:
        if "coverage_steps" in r and r.get("uavs") in FIGURE_UAVS:
            curves[(r["size"], r["method"], r["uavs"])].append(r["coverage_steps"])
    if not any(k > 1 for _, _, k in curves):
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    worlds = sorted({w for w, _, _ in curves}, key=size_key)[:3]
    methods = sorted({m for _, m, _ in curves}, key=report_order)
    colours = {m: f"C{i}" for i, m in enumerate(methods)}
    dashes = {1: "-", 2: "--", 4: ":"}
    with style():
        fig, axes = plt.subplots(
            1, len(worlds), figsize=(width(len(worlds), 3.8, 1.0), 3.6), squeeze=False
        )
        for ax, world in zip(axes[0], worlds, strict=True):
            for (w, m, k), runs in sorted(curves.items()):
                if w != world:
                    continue
                steps = np.array([[math.inf if s is None else s for s in c] for c in runs])
                median = np.median(steps, axis=0)
                shown = np.isfinite(median)
                ax.plot(
                    np.concatenate([[0], median[shown]]),
                    np.concatenate([[0], np.asarray(CURVE)[shown]]),
                    dashes[k], color=colours[m], label=f"{names.get(m, m)}, K={k}",
                )  # fmt: skip
            ax.set_title(world)
            ax.set_xlabel("fleet steps")
            ax.set_ylim(0, 1.02)
            ax.grid(alpha=0.3)
        axes[0][0].set_ylabel("share of seeable cells covered")
        axes[0][-1].legend(loc="lower right")
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)
    return path


__all__ = ["coverage_figure", "fleet_table", "single"]
