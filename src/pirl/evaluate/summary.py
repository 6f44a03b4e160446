"""Per method x simulator x size summaries: means with 95% confidence intervals."""

from __future__ import annotations

import csv
import math
import os
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

HEADLINE = ("vcr", "be", "rvc")
OTHER = (
    "overlap", "views_per_cell", "steps", "collisions", "battery_left", "camera_share",
    "mean_footprint", "final_tilt", "final_zoom", "llm_calls",
)  # fmt: skip
COLUMNS = (
    ["method", "sim", "size", "n"]
    + [f"{m}_{s}" for m in HEADLINE for s in ("mean", "ci95")]
    + [f"{m}_mean" for m in OTHER]
    + ["label"]
)


def mean_ci95(values: Iterable[float]) -> tuple[float, float]:
    """Mean and half-width of the 95% Student-t confidence interval (nan for n < 2)."""
    x = np.asarray(list(values), dtype=np.float64)
    if x.size == 0:
        return math.nan, math.nan
    if x.size == 1:
        return float(x[0]), math.nan
    half = stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size)
    return float(x.mean()), float(half)


def summarize(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (method, sim, size), in a stable order."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        groups[(r["method"], r["sim"], r["size"])].append(r)
    rows = []
    for (method, sim, size), group in sorted(groups.items(), key=lambda kv: _order(kv[0])):
        row: dict[str, Any] = {"method": method, "sim": sim, "size": size, "n": len(group)}
        for metric in HEADLINE:
            row[f"{metric}_mean"], row[f"{metric}_ci95"] = mean_ci95(g[metric] for g in group)
        for metric in OTHER:
            row[f"{metric}_mean"] = float(np.mean([g.get(metric, 0.0) for g in group]))
        row["label"] = group[0].get("label", method)
        rows.append(row)
    return rows


def _order(key: tuple[str, str, str]) -> tuple:
    method, sim, size = key
    dims = tuple(int(v) for v in size.split("x"))
    return (sim, method, dims)


def write_summary(records: list[dict[str, Any]], path: Path) -> list[dict[str, Any]]:
    """Write ``summary.csv`` (atomically) and return its rows."""
    rows = summarize(records)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _fmt(v) for k, v in row.items()})
    os.replace(tmp, path)
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
            if key not in ("method", "sim", "size", "label"):
                row[key] = float(value)
    return rows
