"""The reproduction report: paper-layout tables, figures, animations and one HTML file.

Inputs are what evaluation and training wrote (``summary.csv``, ``episodes.jsonl``, run
folders); outputs land in the report folder: ``table.md``, ``figure.png``,
``intervals_<act>.png``, ``learning_curves.png`` and ``report.html`` (self-contained: every
image embedded). Each table is built once as rows (:class:`pirl.report.tables.Table`);
``table.md`` is rendered from the rows and ``report.html`` from the Jinja2 template
``templates/report.html.j2``.
"""

from __future__ import annotations

import base64
import functools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from jinja2 import Environment, PackageLoader, StrictUndefined, Template, select_autoescape

from pirl._atomic import write_atomic
from pirl.agents.methods import PAPER_METHODS, is_advised_key, report_order
from pirl.agents.run_folder import RunFolder
from pirl.config.choices import PareMode, Sim
from pirl.evaluate.summary import honest_label, read_summary, size_key
from pirl.pare.stats import RunStats
from pirl.report.figures import BAR_FIGURES, bar_figure, interval_figure, learning_curves
from pirl.report.glance import act_rows as _act_rows
from pirl.report.glance import findings, headline_table, summary_lines
from pirl.report.names import display_names, legend_table, name_cell
from pirl.report.physics import physics_gap_table
from pirl.report.tables import Cell, Span, Table, render_markdown

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
SIM_TITLES = {Sim.GRID: "Table 1: grid simulator", Sim.PHYSICS: "Table 2: physics simulator"}


ACT_NOTE = {
    "stochastic": "trained policies sample their actions (seeded per scenario)",
    "greedy": "trained policies take their most likely action",
}


def _stat(row: dict[str, Any], metric: str, stat: str = "iqm") -> str:
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


def paper_tables(
    rows: list[dict[str, Any]],
    act: str,
    stat: str = "iqm",
    names: Mapping[str, str] | None = None,
) -> list[Table]:
    """Tables in the paper's layout for one act mode (one per simulator), the paper's value
    beside ours.

    ``stat="iqm"``: IQM over training seeds with its stratified bootstrap 95% interval;
    ``stat="episode"``: the mean over all episodes ± the per-episode 95% CI (the spread over
    scenarios, seeds pooled). The best of the paper's five methods per column is bold; extras
    (planner, oracle-advised PIRL, PIRL variants, random) follow under a rule and are not
    ranked. ``names``: the page's short names (:func:`pirl.report.names.display_names` of
    ``rows`` when None).
    """
    names = display_names(rows) if names is None else names
    rows = _act_rows(rows, act)
    what = (
        "IQM over training seeds [stratified bootstrap 95% interval]"
        if stat == "iqm"
        else "mean over episodes ± 95% CI over episodes"
    )
    key = "iqm" if stat == "iqm" else "mean"
    tables = []
    for sim in Sim:
        sim_rows = [r for r in rows if r["sim"] == sim]
        if not sim_rows:
            continue
        sizes = sorted({r["size"] for r in sim_rows}, key=size_key)
        by = {(r["method"], r["size"]): r for r in sim_rows}
        methods = [m for m in PAPER_METHODS if any((m, s) in by for s in sizes)]
        extras = sorted({r["method"] for r in sim_rows} - set(PAPER_METHODS), key=report_order)
        best: dict[tuple[str, str], float] = {}
        for size in sizes:
            for metric in METRICS:
                values = [by[(m, size)][f"{metric}_{key}"] for m in methods if (m, size) in by]
                if values:
                    pick = max if HIGHER_IS_BETTER[metric] else min
                    best[(size, metric)] = pick(values)
        head = ["method", "seeds"] + [f"{s} {m.upper()}" for s in sizes for m in METRICS]
        rule = [Span("extras, not in the paper", italic=True), *[""] * (len(head) - 1)]
        body: list[list[Cell]] = []
        for method in methods + extras:
            if extras and method == extras[0]:
                body.append(rule)
            first = next(by[(method, s)] for s in sizes if (method, s) in by)
            cells: list[Cell] = [
                name_cell(first["label"], names.get(method)),
                str(int(first.get("seeds", 1))),
            ]
            for size in sizes:
                row = by.get((method, size))
                paper = PAPER.get(sim, {}).get(method, {}).get(size)
                for k, metric in enumerate(METRICS):
                    if row is None:
                        cells.append("—")
                        continue
                    ranked = method in PAPER_METHODS
                    bold = ranked and row[f"{metric}_{key}"] == best.get((size, metric))
                    value = Span(_stat(row, metric, stat), bold=bold)
                    cells.append(value if paper is None else (value, Span(f" ({paper[k]:.2f})")))
            body.append(cells)
        n = sorted({int(r["n"]) for r in sim_rows})
        note = (
            f"Act {act}: {ACT_NOTE.get(act, act)}; planners, LLM-only and random act by their "
            f"own rule (act fixed: the same episodes in every act table, one run). Episodes per "
            f"cell (all seeds): {', '.join(map(str, n))}."
        )
        title = f"{SIM_TITLES[sim]}, act {act} (ours: {what}; paper in brackets)"
        tables.append(Table(title, head, body, notes=[note]))
    return tables


CAMERA = (
    ("camera_share", "camera actions"), ("mean_footprint", "mean footprint (cells)"),
    ("final_tilt", "final tilt (deg)"), ("final_zoom", "final zoom"), ("steps", "steps"),
)  # fmt: skip


def camera_table(
    rows: list[dict[str, Any]], sim: str = "grid", names: Mapping[str, str] | None = None
) -> Table | None:
    """Camera use beside coverage: per method, size and act mode, the share of camera
    actions, mean footprint, final tilt and zoom, steps, steps relative to the planner's on
    the same scenarios (mean steps over mean planner steps), VCR per 100 steps and the episodes
    that ended in a loop (their last 60 steps in fewer than 10 cells), and where the env's stall
    guard chose any action, the share of steps it chose; None without rows of ``sim``.
    ``names``: the page's short names (of ``rows`` when None)."""
    from pirl.agents.boustrophedon import BoustrophedonPolicy

    names = display_names(rows) if names is None else names
    sim_rows = [r for r in rows if r["sim"] == sim]
    if not sim_rows:
        return None
    planner = {
        r["size"]: r.get("steps_mean") for r in sim_rows if r["method"] == BoustrophedonPolicy.name
    }
    near_ref = {
        r["size"]: r.get("steps_to_99_mean")
        for r in sim_rows
        if r["method"] == BoustrophedonPolicy.name
    }
    head = ["method", "act", "size", "VCR (IQM)"] + [name for _, name in CAMERA]
    head += ["steps to 0.99 / planner's", "steps / planner's", "VCR per 100 steps"]
    head += ["episodes ending in a loop"]
    guard = any(r.get("guarded_share_mean", 0.0) > 0 for r in sim_rows)
    if guard:  # the env's stall guard chose some actions: say how many, per row
        head.append("steps chosen by the stall guard")
    order = sorted(
        sim_rows,
        key=lambda r: (
            report_order(r["method"]), r["label"], r.get("act", ""), size_key(r["size"]),
        ),
    )  # fmt: skip
    body = []
    for r in order:
        cells: list[Cell] = [name_cell(r["label"], names.get(r["method"]))]
        cells += [r.get("act", ""), r["size"], _stat(r, "vcr")]
        cells += [f"{r.get(f'{k}_mean', math.nan):.2f}" for k, _ in CAMERA]
        steps = r.get("steps_mean", math.nan)
        ref = planner.get(r["size"])
        cells.append(_near_complete(r, near_ref.get(r["size"])))
        cells.append(f"{steps / ref:.2f}" if ref and steps and steps > 0 else "—")
        cells.append(f"{100 * r['vcr_mean'] / steps:.2f}" if steps and steps > 0 else "—")
        loops = r.get("loop_episodes")  # absent from a summary written before it was counted
        cells.append("—" if loops is None else f"{int(loops)} of {int(r['n'])}")
        if guard:
            cells.append(f"{r.get('guarded_share_mean', 0.0):.1%}")
        body.append(cells)
    return Table(f"Camera use ({sim} simulator; means over episodes)", head, body)


def _near_complete(row: dict[str, Any], ref: float | None) -> str:
    """Steps to 0.99 of coverable cells over the planner's on the same scenarios (means over
    the episodes that got there), and how many did when not all."""
    steps, n = row.get("steps_to_99_mean", math.nan), int(row.get("reached_99", 0) or 0)
    if not n or not ref or math.isnan(ref) or math.isnan(steps):
        return "never" if "reached_99" in row and row.get("n") else "—"
    text = f"{steps / ref:.2f}"
    return text if n >= int(row["n"]) else f"{text} ({n} of {int(row['n'])} got there)"


_ADVICE_HEAD = (
    "run", "label", "shaped by the student", "by the teacher", "unshaped",
    "mean staleness (steps)", "teacher calls per env-step", "student agreement (majority)",
    "budget spent at step",
)  # fmt: skip


def advice_table(
    advisor_stats: dict[str, Any] | None, short_of_label: Mapping[str, str] | None = None
) -> Table | None:
    """How much of each PIRL run the advice really shaped (from its ``advisor_stats.json``),
    and a line per run whose stats are damaged; None when there is neither.
    ``short_of_label``: a full label's short name on the page.

    A PIRL row in the tables above is PPO-EWRI wherever its steps were unshaped (the student
    below its gate, failed answers, a spent budget): this table says how often.
    """
    title = "How much advice shaped each PIRL run (training)"
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
        return Table(title, notes=missing) if missing else None
    body = []
    for name, s in sorted(runs.items()):
        run = RunStats.of(s)
        label = s.get("label", "")
        if "source" in s:
            label = honest_label(label, [s["source"]])
        agreement = (
            f"{s['student_agreement']:.2f} ({s['student_majority']:.2f})"
            if s.get("mode") == PareMode.STUDENT
            else "-"
        )
        spent = s.get("budget_exhausted_at_step", -1)
        body.append([
            name, name_cell(label, (short_of_label or {}).get(label)),
            f"{run.share(run.student):.0%}", f"{run.share(run.teacher):.0%}",
            f"{run.share(run.unshaped):.0%}", f"{s.get('mean_staleness', 0.0):.1f}",
            f"{s.get('teacher_calls_per_step', 0.0):.4f}", agreement,
            str(spent) if spent >= 0 else "not spent",
        ])  # fmt: skip
    return Table(title, _ADVICE_HEAD, body, notes=missing)


def improvements(records: list[dict[str, Any]], act: str) -> list[dict[str, Any]]:
    """P(each PIRL variant improves on each other method) in VCR, runs (seeds) as the unit,
    per sim and size, with its stratified bootstrap 95% interval (rliable): one dict per
    comparison (``pirl``, ``other`` labels and their keys ``pirl_key``, ``other_key``, ``sim``,
    ``size``, ``p``, ``lo``, ``hi``, the runs on each side ``n_pirl``, ``n_other``, and
    ``fixed`` for a method without training runs)."""
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
    pirls = sorted({m for m, _, _ in groups if is_advised_key(m)}, key=report_order)
    others = sorted({m for m, _, _ in groups if not is_advised_key(m)}, key=report_order)
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
                out.append({"pirl": labels[pirl], "other": labels[other], "pirl_key": pirl,
                            "other_key": other, "sim": sim, "size": size, "p": p, "lo": lo,
                            "hi": hi, "n_pirl": x.shape[0], "n_other": y.shape[0],
                            "fixed": fixed})  # fmt: skip
    return out


def improvement_table(
    records: list[dict[str, Any]],
    act: str,
    found: list[dict[str, Any]] | None = None,
    names: Mapping[str, str] | None = None,
) -> Table | None:
    """P(PIRL improves on each baseline) in VCR, runs (seeds) as the unit, per sim and size,
    with the stratified bootstrap 95% interval (rliable); None without a comparison.
    ``found``: :func:`improvements`, when already computed; ``names``: the page's short
    names (of ``records`` when None)."""
    found = improvements(records, act) if found is None else found
    if not found:
        return None
    names = display_names(records) if names is None else names
    short = {f[side]: names.get(f[f"{side}_key"]) for f in found for side in ("pirl", "other")}
    others = list(dict.fromkeys(f["other"] for f in found))
    cells: dict[tuple[str, str, str], dict[str, str]] = {}
    for f in found:
        cell = cells.setdefault((f["pirl"], f["sim"], f["size"]), {})
        cell[f["other"]] = f"{f['p']:.2f} [{f['lo']:.2f}, {f['hi']:.2f}]"
    return Table(
        f"Probability of improvement in VCR (act {act}; runs = training seeds)",
        ["PIRL", "sim", "size", *(name_cell(o, short[o]) for o in others)],
        [
            [name_cell(pirl, short[pirl]), sim, size, *(row.get(o, "—") for o in others)]
            for (pirl, sim, size), row in cells.items()
        ],
        intro=[
            "P(a run of the row's PIRL scores a higher mean VCR than a run of the column's "
            "method) [stratified bootstrap 95% interval]; 0.5 = no difference."
        ],
    )


def _data_uri(path: Path) -> str:
    mime = {"png": "image/png", "gif": "image/gif"}[path.suffix.lstrip(".").lower()]
    return f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode()


@dataclass(frozen=True)
class _Image:
    """An image of the page: its heading (or caption), alt text and data URI."""

    title: str
    alt: str
    src: str


def _image(title: str, alt: str, path: Path) -> _Image:
    return _Image(title, alt, _data_uri(path))


def result_tables(
    rows: list[dict[str, Any]],
    records: list[dict[str, Any]],
    acts: list[str],
    advisor_stats: dict[str, Any] | None = None,
    extras: Sequence[Table] = (),
    found: list[dict[str, Any]] | None = None,
    names: Mapping[str, str] | None = None,
) -> list[Table]:
    """The report's results in reading order: for each act mode (``acts``, the headline
    first) the IQM tables over seeds; how much advice shaped each PIRL run; ``extras``; the
    probability of improvement of PIRL over each baseline (headline mode; ``found``:
    :func:`improvements`, when already computed), camera use, physics beside grid; then the
    per-episode tables (the secondary spread). Methods carry their full labels (table.md)
    and their short names (``names``, of ``rows`` when None: the page)."""
    names = display_names(rows) if names is None else names
    short_of_label = {r["label"]: names[r["method"]] for r in rows if r["method"] in names}
    headline = (
        f"Headline act mode: {acts[0]} (the same for every trained method; see docs/results.md)."
    )
    optional = [
        advice_table(advisor_stats, short_of_label),
        *extras,
        improvement_table(records, acts[0], found, names),
        camera_table(rows, names=names),
        physics_gap_table(records),
    ]
    return [
        Table(intro=[headline]),
        *(table for act in acts for table in paper_tables(rows, act, names=names)),
        *(table for table in optional if table is not None),
        Table("Secondary: spread over episodes", level=2),
        *(t for act in acts for t in paper_tables(rows, act, stat="episode", names=names)),
    ]


@functools.cache
def _page_template() -> Template:
    env = Environment(
        loader=PackageLoader("pirl.report", "templates"),
        # The default extensions (html, htm, xml) miss a ``.html.j2`` name: escaping off.
        autoescape=select_autoescape(("html.j2",)),
        undefined=StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    return env.get_template("report.html.j2")


def write_report(
    folder: Path,
    summary: Path,
    runs: Sequence[Path] = (),
    gifs: dict[str, Path] | None = None,
    advisor_stats: dict[str, Any] | None = None,
    code_version: str = "unknown",
    notes: Sequence[str] = (),
    headline_act: str = "stochastic",
    extras: Sequence[tuple[str, Table, Path]] = (),
    fleet_summary: Path | None = None,
) -> Path:
    """Write table.md, figure.png, intervals_<act>.png, learning_curves.png and report.html;
    returns the path of report.html.

    ``fleet_summary``: the summary of fleets evaluated apart, whose Fleets table and figure
    the report adds (fleet rows in ``summary`` itself are shown the same way).

    ``extras``: further (title, table, figure) to show after the advice table (the
    advice-quality curve of ``pirl reproduce --profile study-advice``, the missions of
    ``reproduce.missions``); report.html shows their figures at the top.

    table.md opens with a summary generated from the numbers (:func:`summary_lines`, full
    labels); report.html with what its first screen at 1280 px holds: the headline table and
    at most three one-line findings (:mod:`pirl.report.glance`), then the legend of the short
    names it calls methods by (:mod:`pirl.report.names`) and the interval figures. Then both
    hold the tables of :func:`result_tables`; report.html ends with the bar figures, learning
    curves, animations, advisor statistics and each run's config.yaml as written.
    """
    from pirl.report.fleets import coverage_figure, fleet_table, single

    folder.mkdir(parents=True, exist_ok=True)
    every_row = read_summary(summary)
    episodes = Path(summary).with_name("episodes.jsonl")
    every_record = [json.loads(line) for line in episodes.open()] if episodes.is_file() else []
    # The paper's tables compare single UAVs; fleets (--uavs) get their own table and figure.
    rows, records = single(every_row), single(every_record)
    acts = acts_of(rows, headline_act)
    if fleet_summary is not None:  # fleets evaluated apart (pirl reproduce's reproduce.uavs)
        every_row += read_summary(fleet_summary)
        with Path(fleet_summary).with_name("episodes.jsonl").open() as fh:
            every_record += [json.loads(line) for line in fh]
    every_name = display_names(every_row)
    fleets = fleet_table(every_row, every_name)
    figure = coverage_figure(every_record, folder / "fleet_coverage.png", every_name)
    fleet_figures = [("Fleet coverage against time (median over scenarios)", figure)]
    found = improvements(records, acts[0]) if records else []
    said = summary_lines(rows, found, advisor_stats, acts[0])
    top = Table("Summary", bullets=said, level=2, anchor="summary")
    names = display_names(rows)
    results = result_tables(
        rows, records, acts, advisor_stats,
        [t for _, t, _ in extras] + ([fleets] if fleets else []), found, names,
    )  # fmt: skip
    (folder / "table.md").write_text(render_markdown([top, *results]))
    glance_tables = [
        Table("Summary", level=2, anchor="summary"),
        headline_table(rows, records, acts[0], names),
        Table(bullets=findings(rows, found, advisor_stats, acts[0], names), anchor="findings"),
        legend_table(rows, names),
    ]

    glance = [
        _image(f"Aggregate intervals over seeds (grid, act {act})", f"intervals {act}",
               interval_figure(rows, folder / f"intervals_{act}.png", act, names=names))
        for act in acts
        if any(r["sim"] == "grid" for r in rows)
    ]  # fmt: skip
    glance += [_image(title, title, figure) for title, _, figure in extras]
    glance += [_image(title, title, figure) for title, figure in fleet_figures if figure]
    sims = [Sim.GRID] + ([Sim.PHYSICS] if any(r["sim"] == Sim.PHYSICS for r in rows) else [])
    bars = [
        _image(f"Figure ({sim}, act {acts[0]}; per-episode spread)", f"{sim} bars",
               bar_figure(rows, folder / BAR_FIGURES[sim], sim, acts[0], names))
        for sim in sims
    ]  # fmt: skip
    bars.append(
        _image("Learning curves", "curves", learning_curves(runs, folder / "learning_curves.png"))
    )
    configs = [(Path(r).name, RunFolder(Path(r)).config_file) for r in runs]
    page = _page_template().render(
        glance_tables=[t for t in glance_tables if t is not None],
        glance=glance,
        code_version=code_version,
        notes=notes,
        results=results,
        figures=bars,
        gifs=[_image(label, label, gif) for label, gif in (gifs or {}).items()],
        advisor_stats=json.dumps(advisor_stats, indent=2, sort_keys=True) if advisor_stats else "",
        configs=[(name, path.read_text()) for name, path in configs if path.is_file()],
    )
    out = folder / "report.html"
    write_atomic(out, page)
    return out
