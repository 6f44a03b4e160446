"""The report's figures (intervals, bars, learning curves), each readable in a 1280 px window.

report.html's column is 1200 px wide (``templates/report.html.j2``); a figure no wider than
:data:`MAX_WIDTH_IN` at :data:`DPI` is shown at its own size, so its text is as large on
screen as it was drawn (:data:`FONT_PT` points at 100 dpi: about 15 px). A wider figure
would be shrunk by the browser, and its labels with it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import numpy as np

from pirl.agents.methods import report_order
from pirl.agents.run_folder import RunFolder
from pirl.config.choices import Sim
from pirl.evaluate.summary import HEADLINE, size_key
from pirl.report.glance import act_rows
from pirl.report.names import display_names

DPI = 100
MAX_WIDTH_IN = 11.5
"""1150 px at :data:`DPI`: inside the page's 1200 px column."""
FONT_PT = 11
"""The smallest text of a figure (tick labels, legends, annotations)."""


def width(panels: int, panel_in: float, extra_in: float = 0.0) -> float:
    """A figure's width for ``panels`` side by side of ``panel_in`` inches (plus
    ``extra_in``), capped at :data:`MAX_WIDTH_IN`."""
    return min(MAX_WIDTH_IN, panels * panel_in + extra_in)


def style() -> AbstractContextManager[Any]:
    """Matplotlib settings for a report figure: no text below :data:`FONT_PT`."""
    import matplotlib.pyplot as plt

    return plt.rc_context({
        "font.size": FONT_PT, "axes.titlesize": FONT_PT + 1, "axes.labelsize": FONT_PT,
        "xtick.labelsize": FONT_PT, "ytick.labelsize": FONT_PT, "legend.fontsize": FONT_PT,
        "figure.titlesize": FONT_PT + 1, "savefig.dpi": DPI,
    })  # fmt: skip


def interval_figure(
    rows: list[dict[str, Any]],
    path: Path,
    act: str,
    sim: str = "grid",
    names: Mapping[str, str] | None = None,
) -> Path:
    """Aggregate intervals: per size, each method's VCR IQM over seeds with its stratified
    bootstrap 95% interval (the rliable style), for one act mode; methods by their short
    names (``names``, of ``rows`` when None), at most four sizes to a row of panels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = display_names(rows) if names is None else names
    sim_rows = [r for r in act_rows(rows, act) if r["sim"] == sim]
    sizes = sorted({r["size"] for r in sim_rows}, key=size_key)
    methods = sorted({r["method"] for r in sim_rows}, key=report_order)
    labels = {
        r["method"]: f"{names.get(r['method'], r['label'])} ({int(r.get('seeds', 1))})"
        for r in sim_rows
    }
    by = {(r["method"], r["size"]): r for r in sim_rows}
    ncols = min(4, max(1, len(sizes)))
    nrows = math.ceil(max(1, len(sizes)) / ncols)
    with style():
        fig, axes = plt.subplots(
            nrows, ncols, sharey=True, squeeze=False,
            figsize=(width(ncols, 2.3, 2.3), nrows * (0.32 * len(methods) + 1.1) + 0.4),
        )  # fmt: skip
        for ax, size in zip(axes.flat, sizes, strict=False):
            for k, method in enumerate(methods):
                row = by.get((method, size))
                if row is None:
                    continue
                iqm = row.get("vcr_iqm", row["vcr_mean"])
                lo, hi = row.get("vcr_iqm_lo", iqm), row.get("vcr_iqm_hi", iqm)
                ax.plot([lo, hi], [k, k], lw=6, alpha=0.5, color=f"C{k % 10}")
                ax.plot([iqm], [k], "|", ms=14, mew=2, color="k")
            ax.set_title(size)
            ax.set_xlim(0, 1.02)
            ax.set_xlabel("VCR (IQM)")
            ax.grid(axis="x", alpha=0.3)
        for ax in list(axes.flat)[len(sizes) :]:
            ax.set_visible(False)
        for row_axes in axes:
            row_axes[0].set_yticks(range(len(methods)), [labels[m] for m in methods])
        axes[0][0].invert_yaxis()  # the reports' order, top to bottom
        fig.suptitle(f"{sim}, act {act}: VCR IQM over training seeds (their number), 95% intervals")
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)
    return path


BAR_FIGURES = {Sim.GRID: "figure.png", Sim.PHYSICS: "figure_physics.png"}


def bar_figure(
    rows: list[dict[str, Any]],
    path: Path,
    sim: str,
    act: str,
    names: Mapping[str, str] | None = None,
) -> Path:
    """Grouped bars of VCR, BE and RVC per method and size for one act mode, with per-episode
    95% CI error bars; methods by their short names (``names``, of ``rows`` when None)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = display_names(rows) if names is None else names
    sim_rows = [r for r in act_rows(rows, act) if r["sim"] == sim]
    sizes = sorted({r["size"] for r in sim_rows}, key=size_key)
    methods = sorted({r["method"] for r in sim_rows}, key=report_order)
    labels = {r["method"]: names.get(r["method"], r["label"]) for r in sim_rows}
    by = {(r["method"], r["size"]): r for r in sim_rows}
    ncol = min(5, max(1, len(methods)))
    legend_rows = math.ceil(len(methods) / ncol)
    with style():
        fig, axes = plt.subplots(1, 3, figsize=(MAX_WIDTH_IN, 3.9 + 0.3 * legend_rows))
        bar_w = 0.8 / max(1, len(methods))
        x = np.arange(len(sizes))
        for ax, metric in zip(axes, HEADLINE, strict=True):
            for k, method in enumerate(methods):
                means = [
                    by[(method, s)][f"{metric}_mean"] if (method, s) in by else 0 for s in sizes
                ]
                errs = [
                    np.nan_to_num(by[(method, s)][f"{metric}_ci95"]) if (method, s) in by else 0
                    for s in sizes
                ]
                ax.bar(x + k * bar_w, means, bar_w, yerr=errs, capsize=2, label=labels[method])
            # Sites have long names: the sizes' labels turn rather than overlap.
            ax.set_xticks(x + bar_w * (len(methods) - 1) / 2, sizes, rotation=20, ha="right")
            ax.set_title(metric.upper() + (" (lower is better)" if metric == "rvc" else ""))
            ax.set_ylim(0, 1.05)
        handles, shown = axes[0].get_legend_handles_labels()
        fig.legend(handles, shown, loc="lower center", ncol=ncol)
        fig.suptitle(f"{sim}, act {act}: mean over episodes, 95% CI over episodes")
        fig.tight_layout(rect=(0, 0.075 * legend_rows, 1, 1))
        fig.savefig(path)
        plt.close(fig)
    return path


def learning_curves(runs: Sequence[Path], path: Path) -> Path:
    """VCR of training episodes against steps, one line per run (rolling mean of 20)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with style():
        fig, ax = plt.subplots(figsize=(9, 4.8))
        for run in runs:
            data = [(row["timesteps"], row["vcr"]) for row in RunFolder(Path(run)).episodes()]
            if not data:
                continue
            steps, vcr = np.array(data).T
            window = min(20, len(vcr))
            smooth = np.convolve(vcr, np.ones(window) / window, mode="valid")
            ax.plot(steps[window - 1 :], smooth, label=Path(run).name)
        ax.set_xlabel("training steps")
        ax.set_ylabel("episode VCR (rolling mean of 20)")
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
        if ax.lines:
            # Beside the axes: ten runs' names would hide the curves inside them.
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)
    return path


__all__ = [
    "BAR_FIGURES", "DPI", "FONT_PT", "MAX_WIDTH_IN", "bar_figure", "interval_figure",
    "learning_curves", "style", "width",
]  # fmt: skip
