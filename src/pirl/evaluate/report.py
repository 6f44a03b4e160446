"""The reproduction report: paper-layout tables, figures, animations and one HTML file.

Inputs are what evaluation and training wrote (``summary.csv``, run folders); outputs land in
the report folder: ``table.md``, ``figure.png``, ``learning_curves.png``, ``gifs/*.gif`` and
``report.html`` (self-contained: every image embedded).
"""

from __future__ import annotations

import base64
import csv
import html
import json
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pirl.agents.methods import PAPER_METHODS, is_advised_key, report_order
from pirl.evaluate.physics_report import physics_gap_table
from pirl.evaluate.summary import honest_label, read_summary, size_key

# The paper's results (its tables): VCR BE RVC at 30x30x3, 45x45x3, 60x60x3.
_PAPER_TEXT = """
grid     ppo-sr   0.64 0.55 0.22  0.61 0.56 0.24  0.63 0.48 0.26
grid     ppo-ewri 0.61 0.59 0.24  0.59 0.62 0.25  0.62 0.36 0.27
grid     llm-only 0.56 0.42 0.28  0.53 0.40 0.31  0.55 0.39 0.27
grid     il       0.48 0.21 0.40  0.44 0.15 0.47  0.41 0.11 0.49
grid     pirl     0.73 0.74 0.18  0.71 0.58 0.21  0.70 0.23 0.24
physics  ppo-sr   0.61 0.47 0.21  0.62 0.52 0.26  0.65 0.30 0.22
physics  ppo-ewri 0.63 0.44 0.19  0.65 0.57 0.24  0.60 0.32 0.24
physics  llm-only 0.59 0.40 0.26  0.57 0.43 0.24  0.58 0.36 0.23
physics  il       0.36 0.29 0.39  0.29 0.22 0.41  0.37 0.30 0.44
physics  pirl     0.70 0.42 0.14  0.79 0.60 0.22  0.71 0.35 0.17
"""


def _parse_paper(text: str) -> dict[str, dict[str, dict[str, tuple[float, float, float]]]]:
    table: dict[str, dict[str, dict[str, tuple[float, float, float]]]] = {}
    for line in text.strip().splitlines():
        sim, method, *values = line.split()
        nums = [float(v) for v in values]
        table.setdefault(sim, {})[method] = {
            size: (nums[3 * k], nums[3 * k + 1], nums[3 * k + 2])
            for k, size in enumerate(("30x30x3", "45x45x3", "60x60x3"))
        }
    return table


PAPER = _parse_paper(_PAPER_TEXT)
METRICS = ("vcr", "be", "rvc")
HIGHER_IS_BETTER = {"vcr": True, "be": True, "rvc": False}
SIM_TITLES = {"grid": "Table 1: grid simulator", "physics": "Table 2: physics simulator"}


ACT_NOTE = {
    "stochastic": "trained policies sample their actions (seeded per scenario)",
    "greedy": "trained policies take their most likely action",
}


def _cell(row: dict[str, Any], metric: str, stat: str = "iqm") -> str:
    """``IQM [lo, hi]`` over runs (seeds), or ``mean ± per-episode CI`` for ``stat="episode"``."""
    if stat == "episode":
        mean, half = row[f"{metric}_mean"], row[f"{metric}_ci95"]
        return f"{mean:.2f} ± {half:.2f}" if not math.isnan(half) else f"{mean:.2f}"
    value = row.get(f"{metric}_{stat}", row[f"{metric}_mean"])
    lo, hi = row.get(f"{metric}_{stat}_lo", math.nan), row.get(f"{metric}_{stat}_hi", math.nan)
    if math.isnan(lo) or int(row.get("seeds", 1)) < 2:
        return f"{value:.2f}"
    return f"{value:.2f} [{lo:.2f}, {hi:.2f}]"


def acts_of(rows: list[dict[str, Any]], headline: str = "stochastic") -> list[str]:
    """The act modes of trained policies in ``rows``, the headline mode first."""
    acts = sorted({r.get("act", "greedy") for r in rows} - {"fixed"})
    return sorted(acts, key=lambda a: a != headline) or ["fixed"]


def _act_rows(rows: list[dict[str, Any]], act: str) -> list[dict[str, Any]]:
    """Rows of one act mode, with the built-ins (act ``fixed``), which act the same in both."""
    return [r for r in rows if r.get("act", "greedy") in (act, "fixed")]


def markdown_tables(rows: list[dict[str, Any]], act: str | None = None, stat: str = "iqm") -> str:
    """Tables in the paper's layout for one act mode, the paper's value beside ours.

    ``stat="iqm"``: IQM over training seeds with its stratified bootstrap 95% interval;
    ``stat="episode"``: the mean over all episodes ± the per-episode 95% CI (the spread over
    scenarios, seeds pooled). The best of the paper's five methods per column is bold; extras
    (planner, oracle-advised PIRL, PIRL variants, random) follow under a rule and are not
    ranked.
    """
    act = act or acts_of(rows)[0]
    rows = _act_rows(rows, act)
    what = (
        "IQM over training seeds [stratified bootstrap 95% interval]"
        if stat == "iqm"
        else "mean over episodes ± 95% CI over episodes"
    )
    key = "iqm" if stat == "iqm" else "mean"
    parts = []
    for sim in ("grid", "physics"):
        sim_rows = [r for r in rows if r["sim"] == sim]
        if not sim_rows:
            continue
        sizes = sorted({r["size"] for r in sim_rows}, key=size_key)
        by = {(r["method"], r["size"]): r for r in sim_rows}
        methods = [m for m in PAPER_METHODS if any((m, s) in by for s in sizes)]
        extras = sorted({r["method"] for r in sim_rows} - set(PAPER_METHODS), key=_method_order)
        best: dict[tuple[str, str], float] = {}
        for size in sizes:
            for metric in METRICS:
                values = [by[(m, size)][f"{metric}_{key}"] for m in methods if (m, size) in by]
                if values:
                    pick = max if HIGHER_IS_BETTER[metric] else min
                    best[(size, metric)] = pick(values)
        head = ["method", "seeds"] + [f"{s} {m.upper()}" for s in sizes for m in METRICS]
        lines = [
            f"### {SIM_TITLES[sim]}, act {act} (ours: {what}; paper in brackets)",
            "",
            "| " + " | ".join(head) + " |",
            "|" + "---|" * len(head),
        ]
        for method in methods + extras:
            first = next(by[(method, s)] for s in sizes if (method, s) in by)
            cells = [first["label"], str(int(first.get("seeds", 1)))]
            for size in sizes:
                row = by.get((method, size))
                paper = PAPER.get(sim, {}).get(method, {}).get(size)
                for k, metric in enumerate(METRICS):
                    if row is None:
                        cells.append("—")
                        continue
                    text = _cell(row, metric, stat)
                    if method in PAPER_METHODS and row[f"{metric}_{key}"] == best.get(
                        (size, metric)
                    ):
                        text = f"**{text}**"
                    if paper is not None:
                        text += f" ({paper[k]:.2f})"
                    cells.append(text)
            if extras and method == extras[0]:
                lines.append("| *extras, not in the paper* |" + " |" * (len(head) - 1))
            lines.append("| " + " | ".join(cells) + " |")
        n = sorted({int(r["n"]) for r in sim_rows})
        lines += [
            "",
            f"Act {act}: {ACT_NOTE.get(act, act)}; planners, LLM-only and random act by their "
            f"own rule (act fixed: the same episodes in every act table, one run). Episodes per "
            f"cell (all seeds): {', '.join(map(str, n))}.",
            "",
        ]
        parts.append("\n".join(lines))
    return "\n".join(parts)


CAMERA = (
    ("camera_share", "camera actions"), ("mean_footprint", "mean footprint (cells)"),
    ("final_tilt", "final tilt (deg)"), ("final_zoom", "final zoom"), ("steps", "steps"),
)  # fmt: skip


def camera_table(rows: list[dict[str, Any]], sim: str = "grid") -> str:
    """Camera use beside coverage: per method, size and act mode, the share of camera
    actions, mean footprint, final tilt and zoom, steps, steps relative to the planner's on
    the same scenarios (mean steps over mean planner steps), and VCR per 100 steps."""
    from pirl.agents.boustrophedon import BoustrophedonPolicy

    sim_rows = [r for r in rows if r["sim"] == sim]
    if not sim_rows:
        return ""
    planner = {
        r["size"]: r.get("steps_mean") for r in sim_rows if r["method"] == BoustrophedonPolicy.name
    }
    head = ["method", "act", "size", "VCR (IQM)"] + [name for _, name in CAMERA]
    head += ["steps / planner's", "VCR per 100 steps"]
    lines = [
        f"### Camera use ({sim} simulator; means over episodes)",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    order = sorted(
        sim_rows,
        key=lambda r: (
            _method_order(r["method"]), r["label"], r.get("act", ""),
            size_key(r["size"]),
        ),
    )  # fmt: skip
    for r in order:
        cells = [r["label"], r.get("act", ""), r["size"], _cell(r, "vcr")]
        cells += [f"{r.get(f'{k}_mean', math.nan):.2f}" for k, _ in CAMERA]
        steps = r.get("steps_mean", math.nan)
        ref = planner.get(r["size"])
        cells.append(f"{steps / ref:.2f}" if ref and steps and steps > 0 else "—")
        cells.append(f"{100 * r['vcr_mean'] / steps:.2f}" if steps and steps > 0 else "—")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def advice_table(advisor_stats: dict[str, Any] | None) -> str:
    """How much of each PIRL run the advice really shaped (from its ``advisor_stats.json``).

    A PIRL row in the tables above is PPO-EWRI wherever its steps were unshaped (the student
    below its gate, failed answers, a spent budget): this table says how often.
    """
    runs = {
        name: s for name, s in (advisor_stats or {}).items() if isinstance(s, dict) and "steps" in s
    }
    damaged = sorted(
        (name, s["damaged"])
        for name, s in (advisor_stats or {}).items()
        if isinstance(s, dict) and "damaged" in s
    )
    missing = [f"Stats missing for run {name}: {why}." for name, why in damaged]
    if not runs:
        head = ["### How much advice shaped each PIRL run (training)", ""]
        return "\n".join([*head, *missing]) + "\n" if missing else ""
    lines = [
        "### How much advice shaped each PIRL run (training)",
        "",
        "| run | label | shaped by the student | by the teacher | unshaped | mean staleness "
        "(steps) | teacher calls per env-step | student agreement (majority) | budget spent "
        "at step |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, s in sorted(runs.items()):
        steps = max(1, int(s["steps"]))
        label = s.get("label", "")
        if "source" in s:
            label = honest_label(label, [s["source"]])
        teacher = s.get("steps_teacher", s.get("steps_fresh", 0) + s.get("steps_stale", 0))
        unshaped = s.get("steps_unshaped", s.get("steps_missing", 0))
        agreement = (
            f"{s['student_agreement']:.2f} ({s['student_majority']:.2f})"
            if s.get("mode") == "student"
            else "-"
        )
        spent = s.get("budget_exhausted_at_step", -1)
        lines.append(
            f"| {name} | {label} | {s.get('steps_student', 0) / steps:.0%} | "
            f"{teacher / steps:.0%} | {unshaped / steps:.0%} | "
            f"{s.get('mean_staleness', 0.0):.1f} | {s.get('teacher_calls_per_step', 0.0):.4f} | "
            f"{agreement} | {spent if spent >= 0 else 'not spent'} |"
        )
    if missing:
        lines += ["", *missing]
    return "\n".join(lines) + "\n"


def improvements(records: list[dict[str, Any]], act: str) -> list[dict[str, Any]]:
    """P(each PIRL variant improves on each other method) in VCR, runs (seeds) as the unit,
    per sim and size, with its stratified bootstrap 95% interval (rliable): one dict per
    comparison (``pirl``, ``other`` labels, ``sim``, ``size``, ``p``, ``lo``, ``hi``, the runs
    on each side ``n_pirl``, ``n_other``, and ``fixed`` for a method without training runs)."""
    from pirl.evaluate.summary import probability_of_improvement, seed_scores

    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    labels: dict[str, str] = {}
    sources: dict[str, set[str]] = {}
    for r in records:
        if r.get("act", "greedy") not in (act, "fixed"):
            continue
        groups.setdefault((r["method"], r["sim"], r["size"]), []).append(r)
        labels[r["method"]] = r.get("label", r["method"])
        if r.get("source"):
            sources.setdefault(r["method"], set()).add(str(r["source"]))
    labels = {m: honest_label(lab, sources.get(m, ())) for m, lab in labels.items()}
    pirls = sorted({m for m, _, _ in groups if is_advised_key(m)}, key=_method_order)
    others = sorted({m for m, _, _ in groups if not is_advised_key(m)}, key=_method_order)
    keys = sorted({(s, z) for _, s, z in groups}, key=lambda k: (k[0], size_key(k[1])))
    out = []
    for pirl in pirls:
        for sim, size in keys:
            if (pirl, sim, size) not in groups:
                continue
            x = seed_scores(groups[(pirl, sim, size)], "vcr")
            for other in others:
                if (other, sim, size) not in groups:
                    continue
                y = seed_scores(groups[(other, sim, size)], "vcr")
                p, lo, hi = probability_of_improvement(x, y)
                fixed = all(r.get("act") == "fixed" for r in groups[(other, sim, size)])
                out.append({"pirl": labels[pirl], "other": labels[other], "sim": sim,
                            "size": size, "p": p, "lo": lo, "hi": hi, "n_pirl": x.shape[0],
                            "n_other": y.shape[0], "fixed": fixed})  # fmt: skip
    return out


def improvement_table(
    records: list[dict[str, Any]], act: str, found: list[dict[str, Any]] | None = None
) -> str:
    """P(PIRL improves on each baseline) in VCR, runs (seeds) as the unit, per sim and size,
    with the stratified bootstrap 95% interval (rliable). ``found``: :func:`improvements`,
    when already computed."""
    found = improvements(records, act) if found is None else found
    if not found:
        return ""
    others = list(dict.fromkeys(f["other"] for f in found))
    lines = [
        f"### Probability of improvement in VCR (act {act}; runs = training seeds)",
        "",
        "P(a run of the row's PIRL scores a higher mean VCR than a run of the column's "
        "method) [stratified bootstrap 95% interval]; 0.5 = no difference.",
        "",
        "| PIRL | sim | size | " + " | ".join(others) + " |",
        "|" + "---|" * (3 + len(others)),
    ]
    cells: dict[tuple[str, str, str], dict[str, str]] = {}
    for f in found:
        cell = cells.setdefault((f["pirl"], f["sim"], f["size"]), {})
        cell[f["other"]] = f"{f['p']:.2f} [{f['lo']:.2f}, {f['hi']:.2f}]"
    for (pirl, sim, size), row in cells.items():
        values = [row.get(o, "—") for o in others]
        lines.append("| " + " | ".join([pirl, sim, size, *values]) + " |")
    return "\n".join(lines) + "\n"


def summary_lines(
    rows: list[dict[str, Any]],
    found: list[dict[str, Any]],
    advisor_stats: dict[str, Any] | None,
    act: str,
) -> list[str]:
    """A few sentences generated from the numbers, for the top of the report: which PIRL
    variants beat (or lose to) which methods with a P(improvement) interval that excludes
    0.5, how far the best learned method is from the planner in VCR and steps, and how much
    of each PIRL run advice shaped."""
    lines = []
    # pirl -> "beats"/"loses to" -> other -> [("30x30x3", "0.90 [0.75, 1.00]"), ...]
    verdicts: dict[str, dict[str, dict[str, list[tuple[str, str]]]]] = {}
    judged = False
    for f in found:
        # One training run against one gives P of 0 or 1 with a point "interval": no claim.
        if f["sim"] != "grid" or f["n_pirl"] < 2 or (f["n_other"] < 2 and not f["fixed"]):
            continue
        judged = True
        verdict = "beats" if f["lo"] > 0.5 else "loses to" if f["hi"] < 0.5 else None
        if verdict is not None:
            where = (f["size"], f"{f['p']:.2f} [{f['lo']:.2f}, {f['hi']:.2f}]")
            per = verdicts.setdefault(f["pirl"], {}).setdefault(verdict, {})
            per.setdefault(f["other"], []).append(where)

    def sizes(where: list[tuple[str, str]]) -> str:
        if len({p for _, p in where}) == 1:  # the same P everywhere: say it once
            return f"{', '.join(z for z, _ in where)}: {where[0][1]}"
        return ", ".join(f"{z} {p}" for z, p in where)

    for pirl, per in verdicts.items():
        parts = [
            f"{verdict} " + "; ".join(f"{other} ({sizes(where)})" for other, where in o.items())
            for verdict, o in per.items()
        ]
        lines.append(
            f"{pirl} {' and '.join(parts)}: P(improvement) in VCR [95% interval] excludes 0.5."
        )
    if found and not verdicts:
        seeds = sorted({int(r.get("seeds", 1)) for r in rows if is_advised_key(r["method"])})
        why = "" if judged else " (one training run per row: no interval to judge)"
        lines.append(
            "No PIRL variant beats or loses to another method in VCR with a P(improvement) "
            f"interval that excludes 0.5{why}; training seeds per PIRL row: "
            f"{', '.join(map(str, seeds))}, more seeds narrow the intervals."
        )
    grid = [r for r in _act_rows(rows, act) if r["sim"] == "grid"]
    sizes = sorted({r["size"] for r in grid}, key=size_key)
    gaps = []
    for size in sizes:
        here = [r for r in grid if r["size"] == size]
        planner = next((r for r in here if r["method"] == "boustrophedon"), None)
        learned = [r for r in here if r.get("act") != "fixed"]
        if planner is None or not learned:
            continue
        best = max(learned, key=lambda r: r.get("vcr_iqm", r["vcr_mean"]))
        vcr = best.get("vcr_iqm", best["vcr_mean"])
        gaps.append(
            f"on {size} {best['label']} reaches VCR {vcr:.2f} (IQM over seeds) in "
            f"{best.get('steps_mean', math.nan):.0f} steps, the planner "
            f"{planner.get('vcr_iqm', planner['vcr_mean']):.2f} in "
            f"{planner.get('steps_mean', math.nan):.0f}"
        )
    if gaps:
        lines.append(
            f"Best learned method against the boustrophedon planner (act {act}): "
            + "; ".join(gaps) + "."
        )  # fmt: skip
    runs = {n: s for n, s in (advisor_stats or {}).items() if isinstance(s, dict) and "steps" in s}
    if runs:
        parts = []
        for name, st in sorted(runs.items()):
            steps = max(1, int(st["steps"]))
            unshaped = int(st.get("steps_unshaped", st.get("steps_missing", 0)))
            parts.append(f"{name} {1 - unshaped / steps:.0%}")
        lines.append(
            "Share of training steps shaped by advice (student or teacher) per PIRL run: "
            + ", ".join(parts) + "; an unshaped step trains as PPO-EWRI."
        )  # fmt: skip
    return lines


def interval_figure(rows: list[dict[str, Any]], path: Path, act: str, sim: str = "grid") -> Path:
    """Aggregate intervals: per size, each method's VCR IQM over seeds with its stratified
    bootstrap 95% interval (the rliable style), for one act mode."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sim_rows = [r for r in _act_rows(rows, act) if r["sim"] == sim]
    sizes = sorted({r["size"] for r in sim_rows}, key=size_key)
    methods = sorted({r["method"] for r in sim_rows}, key=_method_order)
    labels = {r["method"]: f"{r['label']} ({int(r.get('seeds', 1))} seeds)" for r in sim_rows}
    by = {(r["method"], r["size"]): r for r in sim_rows}
    fig, axes = plt.subplots(
        1, max(1, len(sizes)), figsize=(4.2 * max(1, len(sizes)) + 3, 0.45 * len(methods) + 1.6),
        sharey=True, squeeze=False,
    )  # fmt: skip
    for ax, size in zip(axes[0], sizes, strict=False):
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
        ax.set_xlabel("VCR (IQM over seeds)")
        ax.grid(axis="x", alpha=0.3)
    axes[0][0].set_yticks(range(len(methods)), [labels[m] for m in methods], fontsize=8)
    fig.suptitle(f"{sim} simulator, act {act}: IQM with stratified bootstrap 95% intervals")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def bar_figure(
    rows: list[dict[str, Any]], path: Path, sim: str = "grid", act: str | None = None
) -> Path:
    """Grouped bars of VCR, BE and RVC per method and size for one act mode, with per-episode
    95% CI error bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    act = act or acts_of(rows)[0]
    sim_rows = [r for r in _act_rows(rows, act) if r["sim"] == sim]
    sizes = sorted({r["size"] for r in sim_rows}, key=size_key)
    methods = sorted({r["method"] for r in sim_rows}, key=_method_order)
    labels = {r["method"]: r["label"] for r in sim_rows}
    by = {(r["method"], r["size"]): r for r in sim_rows}
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    width = 0.8 / max(1, len(methods))
    x = np.arange(len(sizes))
    for ax, metric in zip(axes, METRICS, strict=True):
        for k, method in enumerate(methods):
            means = [by[(method, s)][f"{metric}_mean"] if (method, s) in by else 0 for s in sizes]
            errs = [
                np.nan_to_num(by[(method, s)][f"{metric}_ci95"]) if (method, s) in by else 0
                for s in sizes
            ]
            ax.bar(x + k * width, means, width, yerr=errs, capsize=3, label=labels[method])
        ax.set_xticks(x + width * (len(methods) - 1) / 2, sizes)
        ax.set_title(metric.upper() + (" (lower is better)" if metric == "rvc" else ""))
        ax.set_ylim(0, 1.05)
    handles, names = axes[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncol=min(4, len(names)), fontsize=8)
    fig.suptitle(f"{sim} simulator, act {act}: mean over episodes ± 95% CI over episodes")
    rows_of_legend = math.ceil(len(names) / 4)
    fig.tight_layout(rect=(0, 0.06 * rows_of_legend, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def learning_curves(runs: Sequence[Path], path: Path) -> Path:
    """VCR of training episodes against steps, one line per run (rolling mean of 20)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for run in runs:
        csv_path = Path(run) / "episodes.csv"
        if not csv_path.is_file():
            continue
        with open(csv_path, newline="") as fh:
            data = [(int(r["timesteps"]), float(r["vcr"])) for r in csv.DictReader(fh)]
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
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _method_order(method: str) -> tuple[int, str]:
    return report_order(method)


def _data_uri(path: Path) -> str:
    mime = {"png": "image/png", "gif": "image/gif"}[path.suffix.lstrip(".").lower()]
    return f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode()


def _md_table_to_html(markdown: str) -> str:
    out, rows = [], []

    def flush() -> None:
        if rows:
            head, body = rows[0], rows[1:]
            out.append("<table><thead><tr>" + "".join(f"<th>{c}</th>" for c in head) + "</tr>")
            out.append("</thead><tbody>")
            for r in body:
                out.append("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>")
            out.append("</tbody></table>")
            rows.clear()

    for line in markdown.splitlines():
        if line.startswith("|") and not line.startswith("|---"):
            cells = [html.escape(c.strip()) for c in line.strip("|").split("|")]
            cells = [_links(_bold(c)) for c in cells]
            rows.append(cells)
        elif line.startswith("|---"):
            continue
        else:
            flush()
            if line.startswith("### "):
                out.append(f"<h3>{html.escape(line[4:])}</h3>")
            elif line.startswith("## "):
                out.append(f"<h2>{html.escape(line[3:])}</h2>")
            elif line.strip():
                out.append(f"<p>{html.escape(line)}</p>")
    flush()
    return "\n".join(out)


_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")


def _links(cell: str) -> str:
    """Markdown links ``[text](href)`` of an escaped cell as anchors (a run's mission files)."""
    return _LINK.sub(lambda m: f"<a href='{m.group(2)}'>{m.group(1)}</a>", cell)


def _bold(cell: str) -> str:
    if cell.startswith("**") and "**" in cell[2:]:
        end = cell.index("**", 2)
        return f"<b>{cell[2:end]}</b>{cell[end + 2 :]}"
    if cell.startswith("*") and cell.endswith("*"):
        return f"<i>{cell.strip('*')}</i>"
    return cell


def write_report(
    folder: Path,
    summary: Path,
    runs: Sequence[Path] = (),
    gifs: dict[str, Path] | None = None,
    advisor_stats: dict[str, Any] | None = None,
    code_version: str = "unknown",
    notes: Sequence[str] = (),
    headline_act: str = "stochastic",
    extras: Sequence[tuple[str, str, Path]] = (),
) -> Path:
    """Write table.md, figure.png, intervals.png, learning_curves.png and report.html.

    ``extras``: further (title, markdown section, figure) to show after the advice table (the
    advice-quality curve of ``pirl reproduce --profile study-advice``, the missions of
    ``reproduce.missions``).

    table.md and report.html open with a summary generated from the numbers
    (:func:`summary_lines`); report.html shows the interval figures next. table.md then holds,
    for the headline act mode first and then the other, the IQM tables over seeds; then the
    probability of improvement of PIRL over each baseline (headline mode), camera use, and the
    per-episode tables (the secondary spread).
    """
    folder.mkdir(parents=True, exist_ok=True)
    rows = read_summary(summary)
    acts = acts_of(rows, headline_act)
    episodes_path = Path(summary).with_name("episodes.jsonl")
    records = [json.loads(line) for line in episodes_path.open()] if episodes_path.is_file() else []
    blocks = [markdown_tables(rows, act) for act in acts]
    found = improvements(records, acts[0]) if records else []
    improvement = improvement_table(records, acts[0], found)
    summary_text = summary_lines(rows, found, advisor_stats, acts[0])
    camera = camera_table(rows)
    spread = [markdown_tables(rows, act, stat="episode") for act in acts]
    results = "\n".join(
        [
            f"Headline act mode: {acts[0]} (the same for every trained method; see "
            "docs/results.md).",
            "",
            *blocks,
            advice_table(advisor_stats),
            *(markdown for _, markdown, _ in extras),
            improvement,
            camera,
            physics_gap_table(records),
            "## Secondary: spread over episodes",
            "",
            *spread,
        ]
    )
    table = "\n".join(["## Summary", "", *(f"- {line}" for line in summary_text), "", results])
    (folder / "table.md").write_text(table + "\n")
    figures = {"grid": bar_figure(rows, folder / "figure.png", "grid", acts[0])}
    if any(r["sim"] == "physics" for r in rows):
        figures["physics"] = bar_figure(rows, folder / "figure_physics.png", "physics", acts[0])
    intervals = {
        act: interval_figure(rows, folder / f"intervals_{act}.png", act)
        for act in acts
        if any(r["sim"] == "grid" for r in rows)
    }
    curves = learning_curves(runs, folder / "learning_curves.png")

    # At a glance first: what the numbers say, then the intervals, then the tables.
    sections = [
        "<h1>PIRL reproduction report</h1>",
        "<h2 id='summary'>Summary</h2><ul>",
        *(f"<li>{html.escape(line)}</li>" for line in summary_text),
        "</ul>",
    ]
    for act, path in intervals.items():
        sections.append(
            f"<h2>Aggregate intervals over seeds (grid, act {act})</h2>"
            f"<img alt='intervals {act}' src='{_data_uri(path)}'>"
        )
    for title, _, figure in extras:
        sections.append(
            f"<h2>{html.escape(title)}</h2><img alt='{html.escape(title)}' "
            f"src='{_data_uri(figure)}'>"
        )
    sections += [
        f"<p>Code version: <code>{html.escape(code_version)}</code></p>",
        *(f"<p>{html.escape(n)}</p>" for n in notes),
        "<h2>Results</h2>",
        _md_table_to_html(results),
    ]
    for sim, path in figures.items():
        sections.append(
            f"<h2>Figure ({sim}, act {acts[0]}; per-episode spread)</h2>"
            f"<img alt='{sim} bars' src='{_data_uri(path)}'>"
        )
    sections.append(f"<h2>Learning curves</h2><img alt='curves' src='{_data_uri(curves)}'>")
    if gifs:
        sections.append("<h2>One episode per method (same 30x30x3 scenario)</h2><div class='g'>")
        for label, gif in gifs.items():
            sections.append(
                f"<figure><img alt='{html.escape(label)}' src='{_data_uri(gif)}'>"
                f"<figcaption>{html.escape(label)}</figcaption></figure>"
            )
        sections.append("</div>")
    if advisor_stats:
        sections.append("<h2>Advisor statistics</h2><pre>")
        sections.append(html.escape(json.dumps(advisor_stats, indent=2, sort_keys=True)))
        sections.append("</pre>")
    sections.append("<h2>Configurations</h2>")
    for run in runs:
        cfg_path = Path(run) / "config.yaml"
        if cfg_path.is_file():
            text = yaml.safe_dump(yaml.safe_load(cfg_path.read_text()), sort_keys=False)
            sections.append(f"<h3>{html.escape(Path(run).name)}</h3><pre>{html.escape(text)}</pre>")
    page = _PAGE.replace("{body}", "\n".join(sections))
    out = folder / "report.html"
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(page)
    tmp.replace(out)
    return out


_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>PIRL reproduction report</title>
<style>
body{font-family:sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;font-size:12px;margin:1em 0}
td,th{border:1px solid #ccc;padding:3px 6px;text-align:right}
td:first-child,th:first-child{text-align:left}
img{max-width:100%}.g{display:flex;flex-wrap:wrap;gap:1em}
figure{margin:0}figcaption{font-size:12px;text-align:center}
pre{background:#f6f6f6;padding:.5em;font-size:11px;overflow:auto}
</style></head>
<body>
{body}
<script>
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var ok = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length;
  document.body.setAttribute('data-images', ok + '/' + imgs.length);
});
</script>
</body></html>
"""
