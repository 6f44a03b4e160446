"""Short display names for the HTML report, each method's full label once in a legend.

A row's label is its provenance (``PIRL (student of local:SmolLM2-135M-Instruct.Q4_1;
lam_cam 1, lam_move 2)``): right in ``episodes.jsonl``, ``summary.csv`` and ``table.md``, too
long to repeat in every cell, finding and figure of a page read at 1280 px. The page calls each
method by a short name (``PIRL-LLM``, ``PIRL-oracle``, ``PPO-EWRI``, ``Planner``) and shows
the full label once, in :func:`legend_table`; a cell keeps the full label as its hover title.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from typing import Any

from pirl.advice.registry import BUILTIN as BUILTIN_ADVISORS
from pirl.agents.methods import METHODS, is_advised_key, report_order
from pirl.report.tables import Named, Span, Table

_UNSHAPED = re.compile(r"unshaped \d+%")
# Advisors that are not an LLM: a method played by asking one must not pass as an LLM's.
_NOT_LLM = tuple(k.name for k in BUILTIN_ADVISORS.values() if not k.llm)


def _base_name(key: str, label: str) -> str:
    """The short name of an evaluation key (``<method>``, ``<method>-<advisor>``), variant
    suffix (``:<slug>``) aside."""
    base = key.split(":", 1)[0]
    entry = METHODS.get(base)
    if entry is None and is_advised_key(base):
        # ``<method>-<advisor>``: an advisor that is not an LLM (the oracle), named as such.
        advised = next((m for m in METHODS.values() if base.startswith(f"{m.name}-")), None)
        if advised is not None:
            return f"{advised.label}-{base[len(advised.name) + 1 :]}"
    if entry is None:
        return base
    if entry.advised:  # its own key: an LLM advises it (pirl.agents.methods.advised_key)
        return f"{entry.label}-LLM"
    short = entry.short or entry.label
    if entry.asks:
        advisor = next((a for a in _NOT_LLM if f"({a}" in label), None)
        return f"{short} ({advisor})" if advisor else short
    return short


def display_names(rows: Iterable[Mapping[str, Any]]) -> dict[str, str]:
    """Each evaluation key of ``rows`` (``method``, ``label``) to its short display name.

    Variants of one method (keys ``<method>:<slug>``) are numbered in key order; a row whose
    label says ``unshaped N%`` keeps it in its short name, so a mostly unshaped PIRL never
    passes as plain PIRL anywhere on the page."""
    labels: dict[str, str] = {}
    for r in rows:
        labels.setdefault(str(r["method"]), str(r.get("label", r["method"])))
    names: dict[str, str] = {}
    taken: dict[str, list[str]] = {}
    for key in sorted(labels, key=report_order):
        taken.setdefault(_base_name(key, labels[key]), []).append(key)
    for base, keys in taken.items():
        # Two keys with one base name are variants: told apart by number, in key order.
        numbered = len(keys) > 1
        for k, key in enumerate(sorted(keys), start=1):
            name = f"{base} {k}" if numbered else base
            unshaped = _UNSHAPED.search(labels[key])
            names[key] = f"{name} ({unshaped.group(0)})" if unshaped else name
    return names


def name_cell(label: str, short: str | None) -> str:
    """A method's cell: its full label, shown as ``short`` on the page (None: the label)."""
    return Named(label, short) if short and short != label else label


def legend_table(rows: Iterable[Mapping[str, Any]], names: Mapping[str, str]) -> Table:
    """The legend: each short name beside its method's full provenance label and seeds, in
    the reports' order."""
    labels: dict[str, list[str]] = {}
    seeds: dict[str, int] = {}
    for r in rows:
        key = str(r["method"])
        found = labels.setdefault(key, [])
        if str(r["label"]) not in found:
            found.append(str(r["label"]))
        seeds[key] = max(seeds.get(key, 0), int(r.get("seeds", 1)))
    body = [
        [Span(names.get(key, key), bold=True), " / ".join(labels[key]), str(seeds[key])]
        for key in sorted(labels, key=report_order)
    ]
    return Table(
        "Methods",
        ["name", "full label (provenance, as in summary.csv and table.md)", "training seeds"],
        body,
        anchor="methods",
    )


__all__ = ["display_names", "legend_table", "name_cell"]
