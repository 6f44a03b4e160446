"""PIRL's benefit as a curve of advice quality: the ``study-advice`` profile's figure and table.

Each point is one advisor's PIRL runs: x is the advisor's *measured* move agreement with the
oracle (``pirl advise --score``), not its nominal accuracy; y is VCR, the IQM over training
seeds with its stratified bootstrap 95% interval, one panel per evaluation size; PPO-EWRI is a
band. The table gives P(PIRL improves on PPO-EWRI) per point and how much of its runs the
advice shaped; the break-even is the smallest measured agreement whose P(improvement) has its
whole interval above 0.5. Points are measured runs; nothing is fitted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pirl.evaluate.summary import interval_estimates, probability_of_improvement, seed_scores
from pirl.report.tables import Table


@dataclass(frozen=True)
class CurveAdvisor:
    """One point's advisor: its label, its score and the run folders it taught."""

    label: str
    agreement: float
    """Measured move agreement with the oracle (``agreement_move``)."""
    kappa: float
    """Its kappa (``kappa_move``)."""
    sources: frozenset[str]
    """The PIRL run folders of this advisor (one per training seed)."""
    shaped: float | None
    """Mean share of those runs' steps that the advice shaped (None: not recorded)."""


@dataclass(frozen=True)
class CurvePoint:
    advisor: CurveAdvisor
    size: str
    iqm: float
    lo: float
    hi: float
    p: float
    """P(improvement over PPO-EWRI)."""
    p_lo: float
    p_hi: float
    seeds: int


def _scores(records: Sequence[dict[str, Any]], sources: frozenset[str], size: str, act: str):
    group = [
        r
        for r in records
        if r.get("source") in sources and r["size"] == size and r.get("act") == act
        and r.get("sim", "grid") == "grid"
    ]  # fmt: skip
    return seed_scores(group, "vcr") if group else None


def curve_points(
    records: Sequence[dict[str, Any]],
    advisors: Sequence[CurveAdvisor],
    baseline: frozenset[str],
    act: str,
) -> tuple[list[CurvePoint], dict[str, dict[str, float]]]:
    """Every (advisor, size) point, and PPO-EWRI's IQM and interval per size (``baseline``:
    its run folders)."""
    from pirl.evaluate.summary import size_key

    sizes = sorted({r["size"] for r in records if r.get("sim", "grid") == "grid"}, key=size_key)
    points, band = [], {}
    for size in sizes:
        base = _scores(records, baseline, size, act)
        if base is None:
            continue
        band[size] = interval_estimates(base)
        for adv in advisors:
            mine = _scores(records, adv.sources, size, act)
            if mine is None:
                continue
            est = interval_estimates(mine)
            n = min(len(mine), len(base))
            p, p_lo, p_hi = probability_of_improvement(mine[:n], base[:n])
            points.append(
                CurvePoint(
                    adv, size, est["iqm"], est["iqm_lo"], est["iqm_hi"], p, p_lo, p_hi, len(mine)
                )  # fmt: skip
            )
    return points, band


def break_even(points: Sequence[CurvePoint], size: str) -> CurvePoint | None:
    """The point of ``size`` with the smallest measured agreement whose P(improvement over
    PPO-EWRI) has its whole 95% interval above 0.5 (None: no such point)."""
    above = [p for p in points if p.size == size and p.p_lo > 0.5]
    return min(above, key=lambda p: p.advisor.agreement) if above else None


def plot(points: Sequence[CurvePoint], band: dict[str, dict[str, float]], path: Path,
         act: str, title: str = "") -> Path:  # fmt: skip
    """``advice_quality.png``: one panel per size, points with their intervals, PPO-EWRI as a
    band; each point is labelled with its advisor."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pirl.report.figures import style, width

    sizes = list(band)
    with style():
        fig, axes = plt.subplots(
            1, len(sizes), figsize=(width(len(sizes), 3.8), 3.9), squeeze=False
        )
        _panels(axes[0], sizes, points, band, act)
        axes[0][0].legend(loc="lower right")
        if title:
            fig.suptitle(title)
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)
    return path


def _panels(axes: Any, sizes: list[str], points: Sequence[CurvePoint],
            band: dict[str, dict[str, float]], act: str) -> None:  # fmt: skip
    """One panel per size: PPO-EWRI's band, each advisor's point and interval."""
    for ax, size in zip(axes, sizes, strict=True):
        b = band[size]
        ax.axhspan(b["iqm_lo"], b["iqm_hi"], color="0.85", label="PPO-EWRI (95% interval)")
        ax.axhline(b["iqm"], color="0.5", lw=1)
        mine = sorted((p for p in points if p.size == size), key=lambda p: p.advisor.agreement)
        for p in mine:
            llm = "oracle" not in p.advisor.label
            ax.errorbar(
                p.advisor.agreement, p.iqm, yerr=[[p.iqm - p.lo], [p.hi - p.iqm]],
                fmt="s" if llm else "o", color="tab:red" if llm else "tab:blue", capsize=3,
            )  # fmt: skip
            short = p.advisor.label.replace(" (not an LLM)", "").replace("oracle, accuracy", "p =")
            # Short enough to stay beside its point in a panel a third of the page wide.
            ax.annotate(short[:20], (p.advisor.agreement, p.iqm),
                        xytext=(3, 3), textcoords="offset points")  # fmt: skip
        ax.set_title(f"{size} (act {act})")
        ax.set_xlabel("measured move agreement with the oracle")
        ax.set_xlim(-0.02, 1.05)
        ax.set_ylabel("VCR, IQM over seeds")


def section(points: Sequence[CurvePoint], band: dict[str, dict[str, float]], act: str) -> Table:
    """The report's table of points, PPO-EWRI's band per size and the break-even per size."""
    rows = []
    for p in sorted(points, key=lambda p: (p.size, -p.advisor.agreement)):
        a = p.advisor
        rows.append([
            a.label, f"{a.agreement:.2f} ({a.kappa:.2f})",
            "-" if a.shaped is None else f"{a.shaped:.0%}", p.size,
            f"{p.iqm:.3f} [{p.lo:.3f}, {p.hi:.3f}]", f"{p.p:.2f} [{p.p_lo:.2f}, {p.p_hi:.2f}]",
            str(p.seeds),
        ])  # fmt: skip
    for size, b in band.items():
        iqm = f"{b['iqm']:.3f} [{b['iqm_lo']:.3f}, {b['iqm_hi']:.3f}]"
        rows.append(["PPO-EWRI", "-", "-", size, iqm, "-", "-"])
    verdicts = []
    for size in band:
        found = break_even(points, size)
        if found is None:
            verdicts.append(f"{size}: no advisor beats PPO-EWRI with its interval above 0.5.")
        else:
            verdicts.append(
                f"{size}: break-even at agreement {found.advisor.agreement:.2f} "
                f"({found.advisor.label}: P = {found.p:.2f} [{found.p_lo:.2f}, {found.p_hi:.2f}])."
            )
    return Table(
        f"Advice quality: PIRL's VCR by its advisor's measured agreement (act {act})",
        ["advisor", "agreement (kappa)", "shaped", "size", "VCR IQM", "P(improvement)", "seeds"],
        rows,
        intro=[
            "x: the advisor's move agreement with the oracle measured by `pirl advise --score` "
            "(kappa beside it); VCR: IQM over training seeds [95% interval]; P: P(PIRL improves "
            "on PPO-EWRI) [95% interval]; shaped: the share of the runs' steps the advice shaped "
            "(a point below 80% is mostly PPO-EWRI)."
        ],
        bullets=verdicts,
    )


__all__ = [
    "CurveAdvisor",
    "CurvePoint",
    "break_even",
    "curve_points",
    "plot",
    "section",
]
