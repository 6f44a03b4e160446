"""The report at a glance: the headline table, the findings and the summary of ``table.md``.

report.html opens with one table (method x world: VCR and steps against the planner's, with
intervals) and at most :data:`MAX_FINDINGS` one-line findings of at most :data:`MAX_WORDS`
words, methods called by their short names (:mod:`pirl.report.names`). ``table.md`` keeps the
longer summary of :func:`summary_lines`, with full labels.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from pirl.agents.methods import is_advised_key, is_planner, report_order
from pirl.evaluate.summary import BOOTSTRAP_REPS, size_key
from pirl.pare.stats import RunStats
from pirl.report.names import name_cell
from pirl.report.tables import Cell, Table

MAX_WORDS = 30
"""The longest finding, in words: each is read in one glance."""
MAX_FINDINGS = 3


def act_rows(rows: list[dict[str, Any]], act: str) -> list[dict[str, Any]]:
    """Rows of one act mode, with the built-ins (act ``fixed``), which act the same in both."""
    return [r for r in rows if r.get("act", "greedy") in (act, "fixed")]


def _vcr(row: Mapping[str, Any]) -> float:
    return float(row.get("vcr_iqm", row["vcr_mean"]))


def _interval(value: float, lo: float, hi: float, point: bool) -> str:
    return f"{value:.2f}" if point or math.isnan(lo) else f"{value:.2f} [{lo:.2f}, {hi:.2f}]"


def _steps_ratio(
    group: list[dict[str, Any]], planner: Mapping[int, float]
) -> tuple[float, float, float, bool] | None:
    """Steps over the planner's on the same scenarios, per training seed (its episodes'
    steps summed over the planner's on those scenarios), as (mean over seeds, its 95%
    interval, one seed); None when the planner flew none of these scenarios."""
    per_seed: dict[Any, list[float]] = defaultdict(lambda: [0.0, 0.0])
    for r in group:
        ref = planner.get(int(r["seed"]))
        if ref is None:
            continue
        pair = per_seed[r.get("train_seed")]
        pair[0] += float(r["steps"])
        pair[1] += ref
    ratios = np.array([s / p for s, p in per_seed.values() if p > 0], dtype=np.float64)
    if ratios.size == 0:
        return None
    lo, hi = _bootstrap_mean(ratios)
    return float(ratios.mean()), lo, hi, ratios.size < 2


def _bootstrap_mean(x: np.ndarray, reps: int = BOOTSTRAP_REPS) -> tuple[float, float]:
    """The percentile bootstrap 95% interval of the mean of ``x`` (seeds resampled with
    replacement, a fixed generator): rliable's interval for one task, in one array operation.
    rliable's resampling loop took as long for this table's cells as for the whole
    P(improvement) table."""
    rng = np.random.default_rng(0)
    means = x[rng.integers(0, x.size, size=(reps, x.size))].mean(axis=1)
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(lo), float(hi)


def headline_table(
    rows: list[dict[str, Any]],
    records: list[dict[str, Any]],
    act: str,
    names: Mapping[str, str],
) -> Table | None:
    """Method x world (grid sizes and sites, grid simulator, act ``act``): VCR (IQM over
    training seeds [95% interval]) and steps / planner's (on the same scenarios, mean over
    seeds [95% interval]); None without grid rows. Without episode records the step ratio is
    the rows' mean steps over the planner's, without an interval."""
    grid = [r for r in act_rows(rows, act) if r["sim"] == "grid"]
    if not grid:
        return None
    worlds = sorted({r["size"] for r in grid}, key=size_key)
    by = {(r["method"], r["size"]): r for r in grid}
    planners = {r["size"]: r for r in grid if is_planner(r["method"])}
    episodes: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        if r.get("sim") == "grid" and r.get("act", "greedy") in (act, "fixed"):
            episodes[(r["method"], r["size"])].append(r)
    head = ["method"]
    for world in worlds:
        head += [f"{world} VCR", f"{world} steps / planner's"]
    body: list[list[Cell]] = []
    for method in sorted({r["method"] for r in grid}, key=report_order):
        first = next(by[(method, w)] for w in worlds if (method, w) in by)
        cells: list[Cell] = [name_cell(first["label"], names.get(method))]
        for world in worlds:
            row = by.get((method, world))
            if row is None:
                cells += ["—", "—"]
                continue
            one_seed = int(row.get("seeds", 1)) < 2
            vcr = _vcr(row)
            lo, hi = row.get("vcr_iqm_lo", math.nan), row.get("vcr_iqm_hi", math.nan)
            cells.append(_interval(vcr, lo, hi, one_seed))
            cells.append(_ratio_cell(method, world, row, planners, episodes))
        body.append(cells)
    return Table(
        f"Headline: grid simulator, act {act}",
        head,
        body,
        notes=[
            "VCR: IQM over training seeds [95% interval]; steps / planner's: on the same "
            "scenarios, mean over seeds [95% interval]. Names: the Methods legend below."
        ],
        anchor="headline",
    )


def _ratio_cell(
    method: str,
    world: str,
    row: Mapping[str, Any],
    planners: Mapping[str, Mapping[str, Any]],
    episodes: Mapping[tuple[str, str], list[dict[str, Any]]],
) -> str:
    """One method's steps over the planner's on one world, from episodes where there are."""
    planner = planners.get(world)
    if planner is None:
        return "—"
    ref = {int(r["seed"]): float(r["steps"]) for r in episodes.get((planner["method"], world), [])}
    found = _steps_ratio(episodes.get((method, world), []), ref) if ref else None
    if found is not None:
        return _interval(*found)
    steps, planner_steps = row.get("steps_mean", math.nan), planner.get("steps_mean", math.nan)
    if not planner_steps or math.isnan(steps) or math.isnan(planner_steps):
        return "—"
    return f"{steps / planner_steps:.2f}"


def _words(line: str) -> int:
    return len(line.split())


def _most_detailed_fit(candidates: list[str]) -> str:
    """The first (most detailed) candidate within :data:`MAX_WORDS`, else the last."""
    return next((c for c in candidates if _words(c) <= MAX_WORDS), candidates[-1])


def _span(values: list[float], fmt: Callable[[float], str]) -> str:
    """``a`` or ``a-b``: the range of ``values`` as written."""
    lo, hi = fmt(min(values)), fmt(max(values))
    return lo if lo == hi else f"{lo}-{hi}"


def _judged(f: Mapping[str, Any]) -> bool:
    # One training run against one gives P of 0 or 1 with a point "interval": no claim.
    return f["sim"] == "grid" and f["n_pirl"] >= 2 and (f["n_other"] >= 2 or f["fixed"])


def _verdict_finding(
    rows: list[dict[str, Any]], found: list[dict[str, Any]], names: Mapping[str, str]
) -> str | None:
    """Which PIRL variants beat or lose to which methods (P(improvement) in VCR whose 95%
    interval excludes 0.5, grid)."""
    if not found:
        return None
    # pirl -> other -> the worlds judged, and per verdict the worlds it holds on
    judged_at: dict[str, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    held: dict[str, dict[str, dict[str, list[str]]]] = defaultdict(
        lambda: {"beats": defaultdict(list), "loses to": defaultdict(list)}
    )
    judged = [f for f in found if _judged(f)]
    for f in sorted(judged, key=lambda f: report_order(f["other_key"])):
        pirl = names.get(f["pirl_key"], f["pirl"])
        other = names.get(f["other_key"], f["other"])
        judged_at[pirl][other].append(f["size"])
        verdict = "beats" if f["lo"] > 0.5 else "loses to" if f["hi"] < 0.5 else None
        if verdict is not None:
            held[pirl][verdict][other].append(f["size"])
    if not any(at for per in held.values() for at in per.values()):
        if not judged:
            return (
                "No P(improvement) claim in VCR: one training run per PIRL row leaves no "
                "interval to judge; more seeds give one."
            )
        seeds = sorted({int(r.get("seeds", 1)) for r in rows if is_advised_key(r["method"])})
        return (
            "No PIRL variant beats or loses to another method in VCR: every P(improvement) "
            f"95% interval includes 0.5 ({'/'.join(map(str, seeds))} training seeds per row)."
        )
    tail = ": P(improvement) in VCR, 95% interval excludes 0.5."

    def named(pirl: str, verdict: str, how: str) -> str:
        """The methods ``pirl`` beats (or loses to): with the worlds where not all
        (``how="worlds"``), with their count (``"count"``), or bare."""
        out = []
        for other, at in held[pirl][verdict].items():
            everywhere = len(at) == len(judged_at[pirl][other])
            if everywhere or how == "bare":
                out.append(other)
            elif how == "worlds":
                out.append(f"{other} ({', '.join(sorted(at, key=size_key))})")
            else:
                out.append(f"{other} ({len(at)} of {len(judged_at[pirl][other])} worlds)")
        return f"{verdict} {', '.join(out)}" if out else ""

    def said(how: str) -> str:
        parts = []
        for pirl in held:
            verbs = [v for v in (named(pirl, "beats", how), named(pirl, "loses to", how)) if v]
            parts.append(f"{pirl} {' and '.join(verbs)}")
        return "; ".join(parts) + tail

    def beaten(pirl: str) -> int:
        """The methods ``pirl`` beats in every world it was compared with them."""
        return sum(len(at) == len(judged_at[pirl][o]) for o, at in held[pirl]["beats"].items())

    def counted(pirl: str) -> str:
        lost = named(pirl, "loses to", "bare")
        everywhere = f"{pirl} beats {beaten(pirl)} of {len(judged_at[pirl])} methods everywhere"
        return everywhere + (f", {lost}" if lost else "")

    wins = [beaten(pirl) for pirl in held]
    losses = [len(held[pirl]["loses to"]) for pirl in held]
    compared = max(len(per) for per in judged_at.values())
    overall = (
        f"The {len(held)} PIRL variants each beat {_span(wins, str)} of {compared} methods "
        f"everywhere and lose to {_span(losses, str)}{tail}"
    )
    return _most_detailed_fit([
        said("worlds"), said("count"), said("bare"),
        "; ".join(counted(pirl) for pirl in held) + tail, overall,
    ])  # fmt: skip


def _best_against_planner(
    rows: list[dict[str, Any]], act: str
) -> list[tuple[str, dict[str, Any], dict[str, Any]]]:
    """Per grid world with a planner row and a learned one: (world, the planner's row, the
    learned row with the highest VCR), in size order."""
    grid = [r for r in act_rows(rows, act) if r["sim"] == "grid"]
    out = []
    for world in sorted({r["size"] for r in grid}, key=size_key):
        here = [r for r in grid if r["size"] == world]
        planner = next((r for r in here if is_planner(r["method"])), None)
        learned = [r for r in here if r.get("act") != "fixed"]
        if planner is not None and learned:
            out.append((world, planner, max(learned, key=_vcr)))
    return out


def _planner_finding(rows: list[dict[str, Any]], act: str, names: Mapping[str, str]) -> str | None:
    """How close the best learned method comes to the planner, per world, in VCR and steps."""
    best: dict[str, str] = {}
    vcrs, planner_vcrs, ratios = [], [], []
    for world, planner, top in _best_against_planner(rows, act):
        best[world] = names.get(top["method"], top["label"])
        vcrs.append(_vcr(top))
        planner_vcrs.append(_vcr(planner))
        steps, ref = top.get("steps_mean", math.nan), planner.get("steps_mean", math.nan)
        if ref and not math.isnan(ref) and not math.isnan(steps):
            ratios.append(steps / ref)
    if not best:
        return None
    numbers = (
        f"VCR {_span(vcrs, '{:.2f}'.format)} against its {_span(planner_vcrs, '{:.2f}'.format)}"
    )
    if ratios:
        numbers += f", in {_span(ratios, '{:.1f}'.format)}x its steps"
    who: dict[str, list[str]] = defaultdict(list)
    for world, name in best.items():
        who[name].append(world)
    if len(who) == 1:
        name = next(iter(who))
        worlds = f"all {len(best)} worlds" if len(best) > 1 else next(iter(best))
        detailed = f"{name} comes closest to the planner on {worlds}: {numbers}."
    else:
        detailed = (
            "Closest to the planner: "
            + "; ".join(f"{n} on {', '.join(w)}" for n, w in who.items())
            + f"; {numbers}."
        )
    coarse = f"Best learned method per world against the planner: {numbers}."
    return _most_detailed_fit([detailed, coarse])


def _advice_finding(advisor_stats: Mapping[str, Any] | None) -> str | None:
    """How much of each PIRL run's training advice shaped."""
    runs = {n: s for n, s in (advisor_stats or {}).items() if isinstance(s, dict) and "steps" in s}
    if not runs:
        return None
    shares = {name: RunStats.of(st).shaped_share for name, st in sorted(runs.items())}
    per_run = ", ".join(f"{name} {share:.0%}" for name, share in shares.items())
    tail = "; an unshaped step trains as PPO-EWRI."
    ranged = _span(list(shares.values()), "{:.0%}".format)
    return _most_detailed_fit([
        f"Advice shaped {per_run} of training steps{tail}",
        f"Advice shaped {ranged} of each PIRL run's training steps ({len(shares)} runs: "
        f"advice table){tail}",
    ])  # fmt: skip


def findings(
    rows: list[dict[str, Any]],
    found: list[dict[str, Any]],
    advisor_stats: Mapping[str, Any] | None,
    act: str,
    names: Mapping[str, str],
) -> list[str]:
    """At most :data:`MAX_FINDINGS` one-line findings of at most :data:`MAX_WORDS` words, from
    the numbers: the PIRL verdicts whose P(improvement) interval excludes 0.5, how close the
    best learned method comes to the planner, and how much advice shaped each PIRL run."""
    said = [
        _verdict_finding(rows, found, names),
        _planner_finding(rows, act, names),
        _advice_finding(advisor_stats),
    ]
    return [line for line in said if line is not None][:MAX_FINDINGS]


def summary_lines(
    rows: list[dict[str, Any]],
    found: list[dict[str, Any]],
    advisor_stats: dict[str, Any] | None,
    act: str,
) -> list[str]:
    """The summary at the top of ``table.md``, in full labels: which PIRL variants beat (or
    lose to) which methods with a P(improvement) interval that excludes 0.5, how far the best
    learned method is from the planner in VCR and steps, and how much of each PIRL run advice
    shaped."""
    lines = []
    # pirl -> "beats"/"loses to" -> other -> [("30x30x3", "0.90 [0.75, 1.00]"), ...]
    verdicts: dict[str, dict[str, dict[str, list[tuple[str, str]]]]] = {}
    judged = False
    for f in found:
        if not _judged(f):
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
    gaps = []
    for size, planner, top in _best_against_planner(rows, act):
        gaps.append(
            f"on {size} {top['label']} reaches VCR {_vcr(top):.2f} (IQM over seeds) in "
            f"{top.get('steps_mean', math.nan):.0f} steps, the planner "
            f"{_vcr(planner):.2f} in {planner.get('steps_mean', math.nan):.0f}"
        )
    if gaps:
        lines.append(
            f"Best learned method against the boustrophedon planner (act {act}): "
            + "; ".join(gaps) + "."
        )  # fmt: skip
    runs = {n: s for n, s in (advisor_stats or {}).items() if isinstance(s, dict) and "steps" in s}
    if runs:
        parts = [f"{name} {RunStats.of(st).shaped_share:.0%}" for name, st in sorted(runs.items())]
        lines.append(
            "Share of training steps shaped by advice (student or teacher) per PIRL run: "
            + ", ".join(parts) + "; an unshaped step trains as PPO-EWRI."
        )  # fmt: skip
    return lines


__all__ = ["MAX_FINDINGS", "MAX_WORDS", "act_rows", "findings", "headline_table", "summary_lines"]
