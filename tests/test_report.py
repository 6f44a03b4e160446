"""The report: tables built once as rows, Markdown rendered from the rows, report.html from the
Jinja2 template (escaped, links kept), configs shown as written."""

from __future__ import annotations

import csv
import fnmatch
import json
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from pirl.report.document import write_report
from pirl.report.glance import MAX_WORDS, findings
from pirl.report.names import display_names
from pirl.report.tables import Span, Table, render_markdown
from report_view import check_first_screen, render

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
    # At a glance: the summary (headline table, then findings), the intervals, then the
    # tables of results (the intervals came before any table when the summary was bullets).
    assert (
        page.index("Summary")
        < page.index('id="headline-table"')
        < page.index('id="findings-list"')
        < page.index('alt="intervals')
        < page.index("<h2>Results</h2>")
    )


def test_the_template_ships_with_the_package():
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())
    globs = data["tool"]["setuptools"]["package-data"]["pirl"]
    package = ROOT / "src" / "pirl"
    templates = [p.relative_to(package).as_posix() for p in package.rglob("templates/*")]
    assert templates and all(any(fnmatch.fnmatch(t, g) for g in globs) for t in templates)


# -- the report read at a glance --------------------------------------------------------------
LLM_LABEL = "PIRL (student of local:SmolLM2-135M-Instruct.Q4_1; lam_cam 1, lam_move 2)"
ORACLE_LABEL = "PIRL (student of oracle (not an LLM); lam_cam 4, lam_move 2)"
# The demo's rows (`make demo`): every method, two seeds, three sizes and a site, both acts.
DEMO_METHODS = (
    # key, label, training seeds (0: played, act fixed), VCR, steps per cell
    ("ppo-sr", "PPO-SR", 2, 0.80, 0.60),
    ("ppo-ewri", "PPO-EWRI", 2, 0.90, 0.50),
    ("llm-only", "LLM-only (oracle, not an LLM)", 0, 0.30, 0.90),
    ("il", "IL", 2, 0.85, 0.55),
    ("pirl", LLM_LABEL, 2, 0.92, 0.48),
    ("pirl-oracle", ORACLE_LABEL, 2, 0.97, 0.45),
    ("boustrophedon", "boustrophedon (planner)", 0, 1.00, 0.25),
    ("random", "random", 0, 0.20, 1.00),
)
DEMO_WORLDS = ("30x30x3", "45x45x3", "60x60x3", "site:campus")


def demo_eval(folder: Path) -> tuple[Path, dict[str, dict]]:
    """episodes.jsonl and summary.csv of a demo-like evaluation, and its PIRL runs' advisor
    statistics. The summary's intervals are the spread of the seeds' means, not rliable's
    bootstrap: the same columns in a fraction of the time."""
    from pirl.evaluate.summary import COLUMNS, mean_ci95

    rng = np.random.default_rng(0)
    records = []
    for method, label, seeds, vcr, per_cell in DEMO_METHODS:
        for act in ("fixed",) if seeds == 0 else ("stochastic", "greedy"):
            for seed in range(max(1, seeds)):
                for world in DEMO_WORLDS:
                    cells = 900 if world.startswith("site") else int(world.split("x")[0]) ** 2
                    for scenario in range(1 if method == "llm-only" else 4):
                        v = float(np.clip(vcr + rng.normal(0, 0.03), 0, 1))
                        records.append({
                            "method": method, "label": label, "sim": "grid", "size": world,
                            "act": act, "seed": 1000 + scenario,
                            "train_seed": seed if seeds else None, "vcr": v, "be": v * 0.6,
                            "rvc": 1 - v * 0.7, "steps": int(cells * per_cell * (1 + seed / 20)),
                            "source": method if seeds == 0 else f"{method}-s{seed}",
                        })  # fmt: skip
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "episodes.jsonl", "w") as fh:
        fh.writelines(json.dumps(r) + "\n" for r in records)
    groups: dict[tuple, list[dict]] = {}
    for r in records:
        groups.setdefault((r["method"], r["sim"], r["size"], r["act"], r["label"]), []).append(r)
    rows = []
    for (method, sim, size, act, label), group in groups.items():
        row = {"method": method, "sim": sim, "size": size, "act": act, "label": label,
               "n": len(group), "steps_mean": np.mean([g["steps"] for g in group])}  # fmt: skip
        by_seed: dict = {}
        for g in group:
            by_seed.setdefault(g["train_seed"], []).append(g)
        row["seeds"] = len(by_seed)
        for metric in ("vcr", "be", "rvc"):
            row[f"{metric}_mean"], row[f"{metric}_ci95"] = mean_ci95(g[metric] for g in group)
            means = [np.mean([g[metric] for g in s]) for s in by_seed.values()]
            for stat in ("iqm", "mean"):
                row[f"{metric}_{stat}_lo"], row[f"{metric}_{stat}_hi"] = min(means), max(means)
            row[f"{metric}_iqm"] = float(np.mean(means))
        rows.append(row)
    with open(folder / "summary.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, restval=0)
        writer.writeheader()
        writer.writerows(rows)
    stats = {
        f"{method}-s{seed}": {
            "label": label,
            "mode": "student",
            "steps": 409600,
            "steps_unshaped": 40960 * (seed + 1),
            "steps_student": 300000,
            "student_agreement": 0.9,
            "student_majority": 0.8,
        }  # fmt: skip
        for method, label in (("pirl", LLM_LABEL), ("pirl-oracle", ORACLE_LABEL))
        for seed in (0, 1)
    }
    return folder / "summary.csv", stats


@pytest.fixture(scope="module")
def demo_report(tmp_path_factory) -> Path:
    """report.html of the demo-like evaluation."""
    tmp = tmp_path_factory.mktemp("demo")
    summary, stats = demo_eval(tmp / "eval")
    return write_report(tmp / "report", summary, advisor_stats=stats)


def test_methods_get_short_names_that_stay_honest():
    assert display_names([{"method": "pirl", "label": LLM_LABEL}]) == {"pirl": "PIRL-LLM"}
    # Runs of one key with two labels are two keys, pirl:<slug> (pirl.evaluate.runner).
    rows = [
        {"method": "pirl-oracle", "label": ORACLE_LABEL[:-1] + "; unshaped 60%)"},
        {"method": "pirl:pirl-a", "label": "PIRL (a)"},
        {"method": "pirl:pirl-b", "label": "PIRL (b)"},
        {"method": "llm-only", "label": "LLM-only (oracle, not an LLM)"},
        {"method": "boustrophedon", "label": "boustrophedon (planner)"},
        {"method": "ppo-ewri", "label": "PPO-EWRI"},
        {"method": "mystery", "label": "something else"},
    ]
    assert display_names(rows) == {
        "pirl-oracle": "PIRL-oracle (unshaped 60%)",  # never plain PIRL when mostly unshaped
        "pirl:pirl-a": "PIRL-LLM 1",
        "pirl:pirl-b": "PIRL-LLM 2",
        "llm-only": "LLM-only (oracle)",  # not an LLM: said in the short name too
        "boustrophedon": "Planner",
        "ppo-ewri": "PPO-EWRI",
        "mystery": "mystery",
    }


def test_the_page_gives_each_full_label_once_and_table_md_keeps_them(demo_report):
    page = demo_report.read_text()
    table = (demo_report.parent / "table.md").read_text()
    # The page's text: a short name's full label is also its hover title, and the raw
    # advisor statistics at the end (<pre>) hold each run's record as written.
    shown = re.sub(r' title="[^"]*"|<pre>.*?</pre>', "", page, flags=re.S)
    for label in (LLM_LABEL, ORACLE_LABEL, "LLM-only (oracle, not an LLM)"):
        assert shown.count(label) == 1, label  # in the legend
        assert f"| {label} |" in table  # table.md's rows keep the full label
    assert '<span title="PIRL (student of local:SmolLM2-135M-Instruct.Q4_1; lam_cam 1' in page
    # The short names in the tables and findings
    assert "<td><span title" in page and ">PIRL-LLM</span></td>" in page
    said = re.findall(r"<li>(.*?)</li>", page.split('id="findings-list"')[1].split("</ul>")[0])
    assert 1 <= len(said) <= 3 and all(len(line.split()) <= MAX_WORDS for line in said)
    assert "PIRL-LLM beats" in said[0] and "loses to Planner" in said[0]
    assert "closest to the planner" in said[1] and "pirl-s0 90%" in said[2]


def test_findings_stay_short_with_many_variants():
    """Ten PIRL variants, each beating every method in every world: the line falls back to
    counts, and stays within the words a glance takes."""
    others = ["ppo-sr", "ppo-ewri", "il", "llm-only", "boustrophedon", "random"]
    found = [
        {"pirl": f"PIRL ({k})", "pirl_key": f"pirl:v{k}", "other": o, "other_key": o,
         "sim": "grid", "size": size, "p": 0.9, "lo": 0.8, "hi": 1.0, "n_pirl": 3,
         "n_other": 3, "fixed": False}
        for k in range(10) for o in others for size in DEMO_WORLDS
    ]  # fmt: skip
    rows = [{"method": f["pirl_key"], "label": f["pirl"]} for f in found]
    rows += [{"method": o, "label": o} for o in others]
    stats = {f"pirl-v{k}-s{s}": {"steps": 100, "steps_unshaped": k} for k in range(10)
             for s in range(3)}  # fmt: skip
    said = findings(rows, found, stats, "stochastic", display_names(rows))
    assert len(said) == 2  # no grid rows with steps: no planner line
    assert all(len(line.split()) <= MAX_WORDS for line in said), said
    assert said[0].startswith("The 10 PIRL variants each beat 6 of 6 methods")
    assert "of each PIRL run's training steps (30 runs" in said[1]


def test_every_figure_fits_the_page_column(demo_report):
    from PIL import Image

    from pirl.report.figures import MAX_WIDTH_IN

    for png in demo_report.parent.glob("*.png"):
        with Image.open(png) as image:
            # Shown at its own size in the 1200 px column: its fonts as drawn (11 pt or more).
            assert image.width <= MAX_WIDTH_IN * 100 + 1, png.name


def test_the_first_screen_at_1280_px_holds_the_headline_and_the_findings(demo_report, tmp_path):
    dom = render(demo_report, tmp_path, measure=True)
    match = re.search(r'data-images="(\d+)/(\d+)"', dom)
    assert match and match.group(1) == match.group(2) != "0"
    seen = check_first_screen(dom)
    assert seen["words"] and seen["findings"]["top"] > seen["headline"]["bottom"]
