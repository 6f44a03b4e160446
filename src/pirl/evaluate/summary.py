"""Per method x simulator x size x act summaries, with training seeds as the unit.

Each row's episodes are first averaged per training seed (a run); the seed-level scores are
then aggregated with ``rliable``: mean and interquartile mean (IQM) with stratified bootstrap
95% intervals over runs (``*_mean_lo/hi``, ``*_iqm``, ``*_iqm_lo/hi``, ``seeds`` runs). The
per-episode mean and its Student-t 95% half-width (``*_mean``, ``*_ci95``) stay as the
secondary spread. Built-in methods have no training seed: they count as one run, so their
interval over runs is a point.
"""

from __future__ import annotations

import contextlib
import csv
import logging
import math
from collections import defaultdict
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from pirl._atomic import replacing
from pirl.config.errors import ConfigError
from pirl.config.run import PareSettings
from pirl.pare.stats import RunStats
from pirl.world.metrics import LOOP_CELLS

log = logging.getLogger(__name__)

HEADLINE = ("vcr", "be", "rvc")
BOOTSTRAP_REPS = 1000
POI_REPS = 1000
OTHER = (
    "overlap", "views_per_cell", "steps", "collisions", "battery_left", "camera_share",
    "mean_footprint", "final_tilt", "final_zoom", "llm_calls", "guarded_share",
)  # fmt: skip
FLEET = ("makespan_95", "energy_used", "uav_overlap", "near_misses")
"""A fleet's own metrics (:mod:`pirl.evaluate.fleet`), averaged where reached (nan for a
single UAV's rows)."""
COLUMNS = (
    ["method", "sim", "size", "n"]
    + [f"{m}_{s}" for m in HEADLINE for s in ("mean", "ci95")]
    + ["act", "seeds"]
    + [f"{m}_{s}" for m in HEADLINE for s in ("iqm", "iqm_lo", "iqm_hi", "mean_lo", "mean_hi")]
    + [f"{m}_mean" for m in OTHER]
    + ["steps_to_99_mean", "reached_99", "loop_episodes", "uavs"]
    + [f"{m}_mean" for m in FLEET]
    + ["speed_up_mean", "speed_up_ci95", "label"]
)
SITE_PREFIX = "site:"
"""The ``size`` of a site's episode rows: ``site:<name>`` (its grid size is ``grid``)."""
TEXT_COLUMNS = ("method", "sim", "size", "act", "label")


def mean_ci95(values: Iterable[float]) -> tuple[float, float]:
    """Mean and half-width of the 95% Student-t confidence interval (nan for n < 2)."""
    x = np.asarray(list(values), dtype=np.float64)
    if x.size == 0:
        return math.nan, math.nan
    if x.size == 1:
        return float(x[0]), math.nan
    from scipy import stats  # half a second to import: only where intervals are computed

    half = stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size)
    return float(x.mean()), float(half)


def seed_scores(group: list[dict[str, Any]], metric: str) -> np.ndarray:
    """Per training seed, the mean of ``metric`` over its episodes: shape (seeds, 1), the
    runs x tasks matrix rliable takes (one task: this row's size)."""
    by_seed: dict[Any, list[float]] = defaultdict(list)
    for r in group:
        by_seed[r.get("train_seed")].append(float(r[metric]))
    keys = sorted(by_seed, key=lambda s: (s is None, s))
    return np.array([[np.mean(by_seed[k])] for k in keys], dtype=np.float64)


@contextlib.contextmanager
def _bootstrap_seed(seed: int = 0) -> Iterator[None]:
    """Seed NumPy's global generator for one rliable call, then put it back.

    rliable 1.2 draws its stratified resamples with ``np.random.choice`` (the global
    generator) and never with the ``random_state`` it is given, so the same scores gave other
    intervals from one call to the next."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


def _quiet_rliable():
    import warnings

    warnings.filterwarnings("ignore", category=FutureWarning, module="arch")
    from rliable import library, metrics

    return library, metrics


def interval_estimates(scores: np.ndarray, reps: int = BOOTSTRAP_REPS) -> dict[str, float]:
    """Mean and IQM of a (runs, tasks) score matrix with stratified bootstrap 95% intervals
    (rliable; fixed generator, so a summary is reproducible)."""
    if scores.shape[0] == 1:  # one run: no spread over runs to resample (and no rliable
        # import, ~4 CPU-s with arch's pandas and scipy, for a planner's or one run's summary)
        value = float(scores.mean())
        return dict(mean=value, mean_lo=value, mean_hi=value, iqm=value, iqm_lo=value,
                    iqm_hi=value)  # fmt: skip
    library, metrics = _quiet_rliable()

    def both(x: np.ndarray) -> np.ndarray:
        return np.array([metrics.aggregate_mean(x), metrics.aggregate_iqm(x)])

    with _bootstrap_seed():
        point, ci = library.get_interval_estimates(
            {"x": scores}, both, reps=reps, random_state=np.random.RandomState(0)
        )
    (mean, iqm), ((mean_lo, iqm_lo), (mean_hi, iqm_hi)) = point["x"], ci["x"]
    return dict(mean=float(mean), mean_lo=float(mean_lo), mean_hi=float(mean_hi),
                iqm=float(iqm), iqm_lo=float(iqm_lo), iqm_hi=float(iqm_hi))  # fmt: skip


def pairwise_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """rliable's ``metrics.probability_of_improvement``, counted pair by pair: per task the
    share of (run of X, run of Y) pairs where X scores higher, ties counting half (the
    Mann-Whitney U over n x m, which rliable gets from one scipy call per task), averaged
    over tasks. The same value in one array operation: the bootstrap calls it thousands of
    times per table, and scipy's per-call overhead made the report's P(improvement) table
    most of its time."""
    xs, ys = x[:, None, :], y[None, :, :]
    per_task = (xs > ys).mean(axis=(0, 1)) + 0.5 * (xs == ys).mean(axis=(0, 1))
    return float(per_task.mean())


def probability_of_improvement(
    x: np.ndarray, y: np.ndarray, reps: int = POI_REPS
) -> tuple[float, float, float]:
    """P(a run of X scores above a run of Y), with its stratified bootstrap 95% interval
    (rliable). ``x`` and ``y`` are (runs, tasks) matrices over the same tasks."""
    library, _ = _quiet_rliable()
    with _bootstrap_seed():
        point, ci = library.get_interval_estimates(
            {"xy": (x, y)}, pairwise_improvement, reps=reps,
            random_state=np.random.RandomState(0),
        )  # fmt: skip
    lo, hi = np.ravel(ci["xy"])[:2]
    return float(np.ravel(point["xy"])[0]), float(lo), float(hi)


def summarize(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (method, sim, size, act), in a stable order."""
    groups: dict[tuple[str, str, str, str, int], list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        key = (r["method"], r["sim"], r["size"], r.get("act", "greedy"), r.get("uavs", 1))
        groups[key].append(r)
    rows = []
    for key, group in sorted(groups.items(), key=lambda kv: _order(kv[0])):
        method, sim, size, act, uavs = key
        row: dict[str, Any] = {"method": method, "sim": sim, "size": size, "act": act}
        row["uavs"] = uavs
        row["n"] = len(group)
        for metric in HEADLINE:
            row[f"{metric}_mean"], row[f"{metric}_ci95"] = mean_ci95(g[metric] for g in group)
            scores = seed_scores(group, metric)
            row["seeds"] = scores.shape[0]
            est = interval_estimates(scores)
            for key in ("iqm", "iqm_lo", "iqm_hi", "mean_lo", "mean_hi"):
                row[f"{metric}_{key}"] = est[key]
        for metric in OTHER:
            row[f"{metric}_mean"] = float(np.mean([g.get(metric, 0.0) for g in group]))
        # Steps to 0.99 of coverable cells, over the episodes that got there (how many did:
        # reached_99; rows written before it was measured have none).
        near = [g["steps_to_99"] for g in group if g.get("steps_to_99") is not None]
        row["steps_to_99_mean"] = float(np.mean(near)) if near else math.nan
        row["reached_99"] = len(near)
        row["loop_episodes"] = loop_episodes(group)
        for metric in FLEET:
            reached = [g[metric] for g in group if g.get(metric) is not None]
            row[f"{metric}_mean"] = float(np.mean(reached)) if reached else math.nan
        ratios = speed_up_ratios(group, groups.get((method, sim, size, act, 1), []))
        row["speed_up_mean"], row["speed_up_ci95"] = (
            mean_ci95(ratios) if ratios else (math.nan, math.nan)
        )
        row["label"] = honest_label(group[0].get("label", method), _sources(group))
        rows.append(row)
    return rows


def speed_up_ratios(fleet: list[dict[str, Any]], single: list[dict[str, Any]]) -> list[float]:
    """makespan_99(K) / makespan_99(1) per scenario (same seed, same trained run), for the
    fleet rows of ``fleet`` whose K = 1 twin in ``single`` is a fleet row too; empty when any
    pair never reached 0.99 (a speed-up is then not defined) or when there is no twin."""
    ones = {
        (r.get("seed"), str(r.get("source"))): r["makespan_99"]
        for r in single
        if "makespan_99" in r
    }
    ratios = []
    for r in fleet:
        one = ones.get((r.get("seed"), str(r.get("source"))))
        if one is None or r.get("makespan_99") is None:
            return []
        ratios.append(r["makespan_99"] / one)
    return ratios


def loop_episodes(group: list[dict[str, Any]]) -> int:
    """Episodes of ``group`` that ended in a loop: their last 60 steps visited fewer than 10
    cells (``tail_cells``; rows written before it was measured do not count)."""
    return sum(1 for g in group if g.get("tail_cells", LOOP_CELLS) < LOOP_CELLS)


def _sources(group: list[dict[str, Any]]) -> list[str]:
    return sorted({str(r["source"]) for r in group if r.get("source")})


def _run_shaping(source: str) -> tuple[float, int, int] | None:
    """(pare.min_shaped, steps, unshaped steps) of a PIRL run folder, None for other runs."""
    from pirl.agents.run_folder import RunFolder

    folder = RunFolder(Path(source))
    try:
        record = folder.advisor_stats
        # A run without a config records no floor: the setting's default stands for it.
        pare = folder.config.pare if folder.has_config else PareSettings()
        min_shaped = pare.min_shaped
    except ConfigError:
        return None
    run = RunStats.of(record or {})
    if record is None or run.steps <= 0:
        return None
    return min_shaped, run.steps, run.unshaped


def unshaped_share(sources: Iterable[str]) -> float | None:
    """The unshaped share of a row's PIRL runs (all their steps pooled) when any of them was
    less than its ``pare.min_shaped`` shaped; None when every run was shaped enough (or the
    row has no PIRL run)."""
    found = [s for s in (_run_shaping(str(x)) for x in sources) if s is not None]
    if not any(1 - unshaped / steps < floor for floor, steps, unshaped in found):
        return None
    return sum(u for _, _, u in found) / sum(n for _, n, _ in found)


def honest_label(label: str, sources: Iterable[str]) -> str:
    """``label`` with ``unshaped N%`` when a run behind it was mostly unshaped: such a run
    trained as PPO-EWRI for most of its steps and must not pass as plain PIRL."""
    share = unshaped_share(sources)
    if share is None or "unshaped" in label:
        return label
    note = f"unshaped {share:.0%}"
    return f"{label[:-1]}; {note})" if label.endswith(")") else f"{label} ({note})"


def unshaped_warnings(rows: list[dict[str, Any]]) -> list[str]:
    """One warning line per row label that carries ``unshaped N%``."""
    labels = sorted({r["label"] for r in rows if "unshaped" in str(r["label"])})
    return [
        f"warning: {label}: most of its training steps were not shaped by advice, so it is "
        "mostly PPO-EWRI (advisor_stats.json of its runs; pare.min_shaped)"
        for label in labels
    ]


def _order(key: tuple) -> tuple:
    method, sim, size, act, uavs = key
    return (sim, act, method, size_key(size), uavs)


def size_key(size: str) -> tuple:
    """Sort key of a row's ``size``: generated sizes by their dimensions, then sites by name."""
    if size.startswith(SITE_PREFIX):
        return (1, size)
    return (0, tuple(int(v) for v in size.split("x")))


def write_summary(records: list[dict[str, Any]], path: Path) -> list[dict[str, Any]]:
    """Write ``summary.csv`` (atomically) and return its rows."""
    rows = summarize(records)
    for line in unshaped_warnings(rows):
        log.warning(line)
    with replacing(path) as tmp, open(tmp, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _fmt(v) for k, v in row.items()})
    return rows


def _fmt(value: Any) -> Any:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    return value


def read_summary(path: Path) -> list[dict[str, Any]]:
    """Rows of a summary.csv with numbers parsed."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    for row in rows:
        for key, value in row.items():
            if key not in TEXT_COLUMNS:
                row[key] = float(value)
    return rows
