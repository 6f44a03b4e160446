"""The report: tables built once as rows, Markdown rendered from the rows, report.html from the
Jinja2 template (escaped, links kept), configs shown as written."""

from __future__ import annotations

import csv
import fnmatch
import re
import tomllib
from pathlib import Path

import numpy as np

from pirl.report.document import write_report
from pirl.report.tables import Span, Table, render_markdown

ROOT = Path(__file__).resolve().parents[1]
EVIL = "PPO-SR <script>alert(1)</script> & co"


def test_markdown_is_rendered_from_the_rows():
    table = Table(
        "A title",
        ["method", "30x30x3 VCR", "files"],
        [
            ["PPO-SR", (Span("0.70 [0.60, 0.80]", bold=True), Span(" (0.64)")), ""],
            [Span("extras, not in the paper", italic=True), "", ""],
            ["random | walk", "0.20", (Span("a b.plan", href="../m/a b.plan"),)],
        ],
        intro=["Before."],
        notes=["After."],
        bullets=["one", "two"],
    )
    assert render_markdown([Table(intro=["Top."]), table]) == "\n".join(
        [
            "Top.",
            "",
            "### A title",
            "",
            "Before.",
            "",
            "| method | 30x30x3 VCR | files |",
            "|---|---|---|",
            "| PPO-SR | **0.70 [0.60, 0.80]** (0.64) | |",
            "| *extras, not in the paper* | | |",
            r"| random \| walk | 0.20 | [a b.plan](<../m/a b.plan>) |",
            "",
            "After.",
            "",
            "- one",
            "- two",
            "",
        ]
    )


def _summary(path: Path) -> Path:
    """A summary.csv of two grid rows: a paper method (with an unsafe label) and the planner."""
    rows = []
    for method, label, act, vcr, steps in (
        ("ppo-sr", EVIL, "stochastic", 0.7, 300.0),
        ("boustrophedon", "boustrophedon (planner)", "fixed", 1.0, 200.0),
    ):
        row = {"method": method, "sim": "grid", "size": "30x30x3", "act": act, "label": label,
               "n": 4, "seeds": 2, "steps_mean": steps}  # fmt: skip
        for metric in ("vcr", "be", "rvc"):
            for stat in ("mean", "iqm"):
                row |= {f"{metric}_{stat}": vcr, f"{metric}_{stat}_lo": vcr - 0.1,
                        f"{metric}_{stat}_hi": vcr + 0.1}  # fmt: skip
            row[f"{metric}_ci95"] = 0.05
        rows.append(row)
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return path


def _png(path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.imsave(path, np.zeros((4, 4, 3)))
    return path


def test_report_html_comes_from_the_same_rows_escaped_with_links_and_configs(tmp_path):
    summary = _summary(tmp_path / "summary.csv")
    run = tmp_path / "ppo-sr-s0"
    run.mkdir()
    config = "# written by pirl train <as is>\nppo:\n  n_envs: 4  # kept\n"
    (run / "config.yaml").write_text(config)
    link = Span("mission.plan", href="../missions/site-planner/mission.plan")
    extra = Table("Missions flown", ["site", "files"], [["site", (link,)]], level=2)
    report = write_report(
        tmp_path / "report", summary, [run], extras=[("Missions", extra, _png(tmp_path / "m.png"))]
    )
    table = (tmp_path / "report" / "table.md").read_text()
    page = report.read_text()

    assert table.startswith("## Summary\n")
    assert f"| {EVIL} | 2 | **0.70 [0.60, 0.80]** (0.64) |" in table
    assert "[mission.plan](../missions/site-planner/mission.plan)" in table
    # Every heading of table.md is a heading of the page, in the same order.
    headings = re.findall(r"^#+ (.*)$", table, re.M)
    shown = re.findall(r"<h[23][^>]*>([^<]*)</h[23]>", page)
    assert [h for h in shown if h in headings] == headings
    assert '<h2 id="summary">Summary</h2>' in page
    # Text is escaped once; the markup the rows ask for is markup.
    assert "<script>alert" not in page and "&lt;script&gt;alert(1)&lt;/script&gt; &amp; co" in page
    assert "<td><b>0.70 [0.60, 0.80]</b> (0.64)</td>" in page
    assert "<td><i>extras, not in the paper</i></td>" in page
    assert '<a href="../missions/site-planner/mission.plan">mission.plan</a>' in page
    assert "&amp;lt;" not in page
    # The run's config.yaml as written, comments and all.
    assert "<pre># written by pirl train &lt;as is&gt;\nppo:\n  n_envs: 4  # kept\n</pre>" in page
    # Intervals, the extra's figure, bars, learning curves: every image embedded.
    assert page.count('src="data:image/png;base64,') == 4
    assert page.index("Summary") < page.index('alt="intervals') < page.index("<table")


def test_the_template_ships_with_the_package():
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())
    globs = data["tool"]["setuptools"]["package-data"]["pirl"]
    package = ROOT / "src" / "pirl"
    templates = [p.relative_to(package).as_posix() for p in package.rglob("templates/*")]
    assert templates and all(any(fnmatch.fnmatch(t, g) for g in globs) for t in templates)
