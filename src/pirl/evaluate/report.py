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
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pirl.evaluate.summary import read_summary

# The paper's results (DESIGN.md section 1): VCR BE RVC at 30x30x3, 45x45x3, 60x60x3.
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
PAPER_METHODS = ("ppo-sr", "ppo-ewri", "llm-only", "il", "pirl")
METRICS = ("vcr", "be", "rvc")
HIGHER_IS_BETTER = {"vcr": True, "be": True, "rvc": False}
SIM_TITLES = {"grid": "Table 1: grid simulator", "physics": "Table 2: physics simulator"}


def _cell(row: dict[str, Any], metric: str) -> str:
    mean, half = row[f"{metric}_mean"], row[f"{metric}_ci95"]
    return f"{mean:.2f} ± {half:.2f}" if not math.isnan(half) else f"{mean:.2f}"


def markdown_tables(rows: list[dict[str, Any]]) -> str:
    """Tables in the paper's layout: our mean ± 95% CI with the paper's value beside it.

    The best of the paper's five methods per column is bold; extras (planner, oracle-advised
    PIRL, random) follow under a rule and are not ranked.
    """
    parts = []
    for sim in ("grid", "physics"):
        sim_rows = [r for r in rows if r["sim"] == sim]
        if not sim_rows:
            continue
        sizes = sorted({r["size"] for r in sim_rows}, key=lambda s: [int(v) for v in s.split("x")])
        by = {(r["method"], r["size"]): r for r in sim_rows}
        methods = [m for m in PAPER_METHODS if any((m, s) in by for s in sizes)]
        extras = sorted({r["method"] for r in sim_rows} - set(PAPER_METHODS))
        best: dict[tuple[str, str], float] = {}
        for size in sizes:
            for metric in METRICS:
                values = [by[(m, size)][f"{metric}_mean"] for m in methods if (m, size) in by]
                if values:
                    pick = max if HIGHER_IS_BETTER[metric] else min
                    best[(size, metric)] = pick(values)
        head = ["method"] + [f"{s} {m.upper()}" for s in sizes for m in METRICS]
        lines = [
            f"### {SIM_TITLES[sim]} (ours: mean ± 95% CI; paper in brackets)",
            "",
            "| " + " | ".join(head) + " |",
            "|" + "---|" * len(head),
        ]
        for method in methods + extras:
            label = next((by[(method, s)]["label"] for s in sizes if (method, s) in by), method)
            cells = [label]
            for size in sizes:
                row = by.get((method, size))
                paper = PAPER.get(sim, {}).get(method, {}).get(size)
                for k, metric in enumerate(METRICS):
                    if row is None:
                        cells.append("—")
                        continue
                    text = _cell(row, metric)
                    if method in PAPER_METHODS and row[f"{metric}_mean"] == best.get(
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
        lines += ["", f"Episodes per cell: {', '.join(map(str, n))}.", ""]
        parts.append("\n".join(lines))
    return "\n".join(parts)


def bar_figure(rows: list[dict[str, Any]], path: Path, sim: str = "grid") -> Path:
    """Grouped bars of VCR, BE and RVC per method and size, with 95% CI error bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sim_rows = [r for r in rows if r["sim"] == sim]
    sizes = sorted({r["size"] for r in sim_rows}, key=lambda s: [int(v) for v in s.split("x")])
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
    fig.suptitle(f"{sim} simulator: mean ± 95% CI")
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
    order = [*PAPER_METHODS, "pirl-oracle", "boustrophedon", "random"]
    return (order.index(method) if method in order else len(order), method)


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
            cells = [_bold(c) for c in cells]
            rows.append(cells)
        elif line.startswith("|---"):
            continue
        else:
            flush()
            if line.startswith("### "):
                out.append(f"<h3>{html.escape(line[4:])}</h3>")
            elif line.strip():
                out.append(f"<p>{html.escape(line)}</p>")
    flush()
    return "\n".join(out)


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
) -> Path:
    """Write table.md, figure.png, learning_curves.png and the self-contained report.html."""
    folder.mkdir(parents=True, exist_ok=True)
    rows = read_summary(summary)
    table = markdown_tables(rows)
    (folder / "table.md").write_text(table + "\n")
    figures = {"grid": bar_figure(rows, folder / "figure.png", "grid")}
    if any(r["sim"] == "physics" for r in rows):
        figures["physics"] = bar_figure(rows, folder / "figure_physics.png", "physics")
    curves = learning_curves(runs, folder / "learning_curves.png")

    sections = [
        "<h1>PIRL reproduction report</h1>",
        f"<p>Code version: <code>{html.escape(code_version)}</code></p>",
        *(f"<p>{html.escape(n)}</p>" for n in notes),
        "<h2>Results</h2>",
        _md_table_to_html(table),
    ]
    for sim, path in figures.items():
        sections.append(f"<h2>Figure ({sim})</h2><img alt='{sim} bars' src='{_data_uri(path)}'>")
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
