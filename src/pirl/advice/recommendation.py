"""The advisor's answer, as numbers: a camera target and a one-cell move."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from pirl.config.grid import MOVE_VALUES, PAN_RANGE, TILT_RANGE, ZOOM_RANGE

FORMAT_EXAMPLE = "pan: 75, tilt: 45, zoom: 1.0, X: -1, Y: 0, Z: 0"
"""An answer in the exact output format (the paper's sample values)."""


def clamp(value: float, low: float, high: float) -> float:
    """``value`` limited to ``[low, high]``."""
    return min(max(value, low), high)


def round_move(value: float) -> int:
    """A move component clamped to [-1, 1] and rounded half away from zero (0.5 -> 1)."""
    v = clamp(float(value), -1.0, 1.0)
    return int(math.copysign(math.floor(abs(v) + 0.5), v)) + 0


def _fmt(value: float, min_decimals: int = 0) -> str:
    """Shortest decimal text of ``value`` (at most 3 decimals), never ``-0``."""
    v = round(float(value), 3) + 0.0
    text = f"{v:.3f}".rstrip("0").rstrip(".")
    if text == "-0":
        text = "0"
    if min_decimals and "." not in text:
        text += "." + "0" * min_decimals
    return text


@dataclass(frozen=True)
class Recommendation:
    """What the advisor suggests for the next step.

    Attributes:
        pan: target pan in degrees, in [-90, 90].
        tilt: target tilt in degrees, in [0, 90].
        zoom: target zoom factor, in [0.5, 2.0].
        dx: move along x, one of -1, 0, 1.
        dy: move along y, one of -1, 0, 1.
        dz: move along z, one of -1, 0, 1.

    Values outside the ranges raise ``ValueError``; use :meth:`clamped` to build one from raw
    numbers.
    """

    pan: float
    tilt: float
    zoom: float
    dx: int
    dy: int
    dz: int

    def __post_init__(self) -> None:
        for name, (low, high) in (("pan", PAN_RANGE), ("tilt", TILT_RANGE), ("zoom", ZOOM_RANGE)):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, numbers.Real)
                or not math.isfinite(value)
            ):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
            if not low <= value <= high:
                raise ValueError(f"{name} must be in [{low:g}, {high:g}], got {value!r}")
            object.__setattr__(self, name, float(value) + 0.0)
        for name in ("dx", "dy", "dz"):
            value = getattr(self, name)
            if isinstance(value, bool) or value not in MOVE_VALUES:
                raise ValueError(f"{name} must be -1, 0 or 1, got {value!r}")
            object.__setattr__(self, name, int(value))

    @classmethod
    def clamped(
        cls, pan: float, tilt: float, zoom: float, dx: float, dy: float, dz: float
    ) -> Recommendation:
        """Build from raw finite numbers: camera values clamped, moves rounded and clamped."""
        values = (pan, tilt, zoom, dx, dy, dz)
        if not all(math.isfinite(float(v)) for v in values):
            raise ValueError(f"all values must be finite, got {values!r}")
        return cls(
            pan=clamp(float(pan), *PAN_RANGE) + 0.0,
            tilt=clamp(float(tilt), *TILT_RANGE) + 0.0,
            zoom=clamp(float(zoom), *ZOOM_RANGE),
            dx=round_move(dx),
            dy=round_move(dy),
            dz=round_move(dz),
        )

    @property
    def move(self) -> tuple[int, int, int]:
        """The move as ``(dx, dy, dz)``."""
        return (self.dx, self.dy, self.dz)

    def to_text(self) -> str:
        """The answer in the exact output format, ``pan: 75, tilt: 45, zoom: 1.0, X: -1, ...``."""
        return (
            f"pan: {_fmt(self.pan)}, tilt: {_fmt(self.tilt)}, zoom: {_fmt(self.zoom, 1)}, "
            f"X: {self.dx}, Y: {self.dy}, Z: {self.dz}"
        )
