"""The report's physics section: each policy's physics VCR beside its grid VCR, gaps explained.

For every run (method and training seed) flown in the physics simulator, the grid episodes of
the same scenarios (same method, run, size, act mode and scenario seeds) give the grid VCR;
the physics episodes give the physics VCR and what happened in flight, counted: why the
episodes ended (``end``), steps, timeouts, contacts, recoveries, and the battery by cause
(the ``energy_<cause>`` fields of :mod:`pirl.physics.flight`). A gap above
:data:`GAP_EXPLAINED` gets a sentence built from those counts.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from typing import Any

import numpy as np

from pirl.config.choices import Sim
from pirl.physics.flight import ENERGY_CAUSES
from pirl.report.tables import Table

GAP_EXPLAINED = 0.1
"""|grid VCR - physics VCR| above which the table says why, from counted events."""
# Causes that are not ordinary flight: what a gap is usually made of.
_LOSSES = ("timeout", "contact", "geofence")


def _key(r: dict[str, Any]) -> tuple:
    return (r["method"], r.get("train_seed"), r["size"], r.get("act", "fixed"))


def _size_order(size: str) -> tuple:
    from pirl.evaluate.summary import size_key

    return size_key(size)


_HEADER = (
    "method", "run", "size", "act", "n", "grid VCR", "physics VCR", "gap", "end (physics)",
    "steps grid / physics", "timeouts", "contacts", "recoveries", "battery by cause", "why",
)  # fmt: skip


def physics_gap_table(records: list[dict[str, Any]]) -> Table | None:
    """Per run and size, grid VCR and physics VCR on the same scenarios, the gap, why the
    physics episodes ended, counted events and the battery by cause; None without physics
    episodes."""
    physics: dict[tuple, list[dict[str, Any]]] = defaultdict(list)
    grid: dict[tuple, dict[int, dict[str, Any]]] = defaultdict(dict)
    for r in records:
        if r.get("sim") == Sim.PHYSICS:
            physics[_key(r)].append(r)
        elif r.get("sim") == "grid":
            grid[_key(r)][int(r["seed"])] = r
    if not physics:
        return None
    rows = []
    keys = sorted(physics, key=lambda k: (k[0], str(k[1]), _size_order(k[2]), k[3]))
    for key in keys:
        flights = sorted(physics[key], key=lambda r: int(r["seed"]))
        twins = [grid[key].get(int(r["seed"])) for r in flights]
        paired = [(f, g) for f, g in zip(flights, twins, strict=True) if g is not None]
        rows.append(_row(key, flights, paired))
    return Table(
        "Physics beside grid (same scenarios; means over them)",
        _HEADER,
        rows,
        intro=[
            "Battery by cause: share of the battery used (docs/physics.md). A gap above "
            f"{GAP_EXPLAINED} VCR is explained from the counted events."
        ],
    )


def _row(key: tuple, flights: list[dict[str, Any]], paired: list[tuple[dict, dict]]) -> list[str]:
    method, train_seed, size, act = key
    label = flights[0].get("label", method)
    vcr_p = float(np.mean([f["vcr"] for f in flights]))
    steps_p = float(np.mean([f["steps"] for f in flights]))
    ends = Counter(str(f.get("end", "?")) for f in flights)
    counts = {c: int(sum(f.get(c, 0) for f in flights)) for c in ("timeouts", "contacts")}
    counts["recoveries"] = int(sum(f.get("recoveries", 0) for f in flights))
    energy = {c: sum(float(f.get(f"energy_{c}", 0.0)) for f in flights) for c in ENERGY_CAUSES}
    total = sum(energy.values())
    shares = {c: e / total for c, e in energy.items() if total > 0 and e > 0}
    by_cause = ", ".join(  # causes under half a percent would only print as 0%
        f"{c} {100 * s:.0f}%"
        for c, s in sorted(shares.items(), key=lambda kv: -kv[1])
        if s >= 0.005
    )
    end_text = ", ".join(f"{k} {v}" for k, v in sorted(ends.items()))
    if paired:
        vcr_g = float(np.mean([g["vcr"] for _, g in paired]))
        gap = float(np.mean([g["vcr"] - f["vcr"] for f, g in paired]))
        steps_g = float(np.mean([g["steps"] for _, g in paired]))
        grid_ends = Counter(_grid_end(g) for _, g in paired)
        cells = [f"{vcr_g:.2f}", f"{vcr_p:.2f}", f"{gap:+.2f}"]
        steps = f"{steps_g:.0f} / {steps_p:.0f}"
        why = _why(gap, ends, grid_ends, steps_g, steps_p, counts, shares, len(flights))
    else:  # no grid episode of these scenarios in this evaluation
        cells, steps, why = ["-", f"{vcr_p:.2f}", "-"], f"- / {steps_p:.0f}", ""
    run = "-" if train_seed is None else str(train_seed)
    return [
        str(label), run, str(size), str(act), str(len(flights)), *cells, end_text, steps,
        str(counts["timeouts"]), str(counts["contacts"]), str(counts["recoveries"]), by_cause, why,
    ]  # fmt: skip


def _grid_end(r: dict[str, Any]) -> str:
    """Why a grid episode ended, from its metrics (grid records carry no ``end``)."""
    if float(r["vcr"]) >= 1.0:
        return "coverage"
    return "battery" if float(r.get("battery_left", 1.0)) <= 0.0 else "step_limit"


def _why(
    gap: float,
    ends: Counter,
    grid_ends: Counter,
    steps_g: float,
    steps_p: float,
    counts: dict[str, int],
    shares: dict[str, float],
    n: int,
) -> str:
    """One sentence from counted events for a gap above :data:`GAP_EXPLAINED`, else ''."""
    if abs(gap) <= GAP_EXPLAINED:
        return ""
    parts = []
    if ends != grid_ends:
        fmt = ", ".join
        parts.append(
            f"ended by {fmt(f'{k} {v}' for k, v in sorted(ends.items()))} in physics against "
            f"{fmt(f'{k} {v}' for k, v in sorted(grid_ends.items()))} on the grid"
        )
    parts.append(f"{steps_p:.0f} steps per episode against {steps_g:.0f}")
    lost = sum(shares.get(c, 0.0) for c in _LOSSES)
    if counts["timeouts"] or counts["contacts"]:
        parts.append(
            f"{counts['timeouts'] / n:.1f} timeouts and {counts['contacts'] / n:.1f} contacts "
            f"per episode took {100 * lost:.0f}% of the battery"
        )
    elif lost < 0.05:
        parts.append("no timeout or contact: the flight itself cost about what the grid charges")
    return "; ".join(parts)


__all__ = ["GAP_EXPLAINED", "physics_gap_table"]
