"""How much memory worlds need, estimated from their size before anything is allocated.

Every command that builds worlds asks :func:`check_memory` first (and :class:`WorldBatch`
asks again when it allocates), so an impossible size is one line, not minutes of swapping.
"""

from __future__ import annotations

import os

from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig

GB = 1024**3
# What an episode appends per step to the env's path list (a tuple of three small ints).
PATH_BYTES_PER_STEP = 88


def machine_memory() -> int:
    """This machine's physical memory, bytes."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not Linux
        return 8 * GB


def memory_limit(cfg: VCPPConfig) -> int:
    """``env.max_memory_gb`` in bytes, or half of the machine's memory when it is 0."""
    if cfg.max_memory_gb > 0:
        return int(cfg.max_memory_gb * GB)
    return machine_memory() // 2


def world_bytes(cfg: VCPPConfig) -> int:
    """The arrays of one world (what :class:`~pirl.world.state.WorldBatch` allocates per world):
    per voxel ``blocked`` and ``occluding`` (1 byte each) and each UAV's ``visits`` (4); per
    ground cell ``coverable``, ``redmask`` (1 each), ``views`` (4) and each UAV's path-search
    scratch (8); the rest is small."""
    sx, sy, sz = cfg.size
    k = cfg.uavs
    return sx * sy * sz * (2 + 4 * k) + sx * sy * (6 + 8 * k) + 64 * 1024 * k


def longest_episode(cfg: VCPPConfig) -> int:
    """Most steps one episode can take: the step limit, or fewer when the battery runs out
    first (every step costs at least ``energy_hover`` plus the cheapest action)."""
    cheapest = cfg.energy_hover + min(
        cfg.energy_move, cfg.energy_climb, cfg.energy_descend, cfg.energy_camera
    )
    limit = int(cfg.step_limit)
    if cheapest > 0:
        limit = min(limit, int(cfg.capacity / cheapest) + 1)
    return limit


def check_memory(cfg: VCPPConfig, worlds: int = 1, per_step_bytes: int = 0) -> int:
    """The bytes ``worlds`` worlds of ``cfg`` need, each recording ``per_step_bytes`` per step
    (for example a rendered frame) besides its path; raise one ConfigError line when that is
    over :func:`memory_limit`."""
    grids = world_bytes(cfg) * worlds
    recording = longest_episode(cfg) * (PATH_BYTES_PER_STEP * cfg.uavs + per_step_bytes) * worlds
    need, limit = grids + recording, memory_limit(cfg)
    if need > limit:
        size = "x".join(str(s) for s in cfg.size)
        fleet = f" of {cfg.uavs} UAVs" if cfg.uavs > 1 else ""
        raise ConfigError(
            f"world {size}: {worlds} world(s){fleet} need about {need / GB:.1f} GB (grids "
            f"{grids / GB:.2f} GB, episode recording {recording / GB:.2f} GB), over the limit "
            f"of {limit / GB:.1f} GB (env.max_memory_gb; 0 = half of this machine's "
            f"{machine_memory() / GB:.0f} GB); choose a smaller size"
        )
    return need


__all__ = ["check_memory", "longest_episode", "machine_memory", "memory_limit", "world_bytes"]
