"""Evaluation scenario sets: per world size, a fixed list of seeds every method shares.

A seed fixes an episode's obstacles, start cell and wind. The seeds of a size are derived
from the size alone, far from the seeds training uses (those start at 1000 * training seed),
so no method is ever evaluated on a world it trained on. Validation seeds (for choosing
settings such as PARE's weights) sit in the same block of the size, 50,000 above its
evaluation seeds, so a choice made on them never sees an evaluation scenario.
"""

from __future__ import annotations

import re

from pirl.config.errors import ConfigError

EVAL_SEED_BASE = 1_000_000_000
VALIDATION_OFFSET = 50_000  # evaluation uses at most this many scenarios per size


def parse_size(text: str | int) -> tuple[int, int, int]:
    """'30' -> (30, 30, 3); '40x25x4' -> (40, 25, 4); '40x25' -> (40, 25, 3)."""
    raw = str(text).strip().lower()
    if re.fullmatch(r"\d+", raw):
        n = int(raw)
        size = (n, n, 3)
    elif m := re.fullmatch(r"(\d+)x(\d+)(?:x(\d+))?", raw):
        size = (int(m.group(1)), int(m.group(2)), int(m.group(3) or 3))
    else:
        raise ConfigError(f"size {text!r}: write N (NxNx3), XxY (height 3) or XxYxZ, e.g. 40x25x4")
    if min(size) < 3:
        raise ConfigError(f"size {text!r} is impossible: every side must be >= 3 cells")
    return size


def size_name(size: tuple[int, int, int]) -> str:
    return "x".join(str(s) for s in size)


def scenario_seeds(size: tuple[int, int, int], episodes: int) -> list[int]:
    """The evaluation seeds of ``size``: the same for every method and every run."""
    if episodes > VALIDATION_OFFSET:
        raise ConfigError(f"{episodes} scenarios per size: at most {VALIDATION_OFFSET}")
    return [_base(size) + k for k in range(episodes)]


def validation_seeds(size: tuple[int, int, int], episodes: int) -> list[int]:
    """Scenario seeds for choosing settings: never among :func:`scenario_seeds` of any size."""
    if episodes > 100_000 - VALIDATION_OFFSET:
        raise ConfigError(f"{episodes} validation scenarios: at most 50000")
    return [_base(size) + VALIDATION_OFFSET + k for k in range(episodes)]


def _base(size: tuple[int, int, int]) -> int:
    x, y, z = size
    return EVAL_SEED_BASE + ((x * 2048 + y) * 64 + z) * 100_000
