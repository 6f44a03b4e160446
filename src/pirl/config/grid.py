"""The action grid, defined once: the camera's pose steps and limits and the one-cell moves.

The dynamics step on it, the valid-action mask stops at its limits, and the advice side derives
from it the prompt's ranges, the parser's clamps, the embedded LLM's grammar values and the
student's output classes.
"""

from __future__ import annotations

TILT_MIN, TILT_MAX, TILT_STEP = 0, 90, 5
"""Tilt in degrees (0 = forward, 90 = straight down) and one tilt action's step."""
PAN_MIN, PAN_MAX, PAN_STEP = -90, 90, 15
"""Pan in degrees (0 = +x, world frame) and one pan action's step."""
ZOOM_MIN10, ZOOM_MAX10, ZOOM_STEP10 = 5, 20, 1
"""Zoom in tenths (0.5x to 2.0x) and one zoom action's step."""
MOVE_VALUES: tuple[int, int, int] = (-1, 0, 1)
"""Allowed values of each move component dx, dy, dz."""

TILT_RANGE: tuple[float, float] = (float(TILT_MIN), float(TILT_MAX))
PAN_RANGE: tuple[float, float] = (float(PAN_MIN), float(PAN_MAX))
ZOOM_RANGE: tuple[float, float] = (ZOOM_MIN10 / 10.0, ZOOM_MAX10 / 10.0)


def tilt_steps() -> tuple[int, ...]:
    """Every tilt the camera can hold, degrees."""
    return tuple(range(TILT_MIN, TILT_MAX + 1, TILT_STEP))


def pan_steps() -> tuple[int, ...]:
    """Every pan the camera can hold, degrees."""
    return tuple(range(PAN_MIN, PAN_MAX + 1, PAN_STEP))


def zoom_steps() -> tuple[float, ...]:
    """Every zoom factor the camera can hold."""
    return tuple(round(k / 10.0, 1) for k in range(ZOOM_MIN10, ZOOM_MAX10 + 1, ZOOM_STEP10))


PAPER_NADIR_TILT = 80
"""Tilt, degrees, from which the paper footprint's square halves (a camera looking down)."""


def paper_half_width(tilt: int, zoom10: int) -> int:
    """Half-width of the paper footprint's square, ``floor(m * zoom + 0.5)`` with m = 2 below
    80 degrees of tilt, else 1, in integer arithmetic on the camera's steps (zoom in tenths).
    The footprint kernel compiles this very function; the prompt states it."""
    m = 2 if tilt < PAPER_NADIR_TILT else 1
    return (m * zoom10 + 5) // 10
