"""The VCPP environments: single (Gymnasium), batched as a Gymnasium vector env and as a
Stable-Baselines3 VecEnv, and a fleet of UAVs as a PettingZoo ParallelEnv and an SB3 VecEnv of
(world, UAV) slots; all run the same :class:`~pirl.env.core.EnvCore`.

The names are imported on first use: the SB3 adapter brings Stable-Baselines3 and torch
(about 1.5 s), which a command that only checks its options or reads the core never needs.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "FleetParallelEnv",
    "FleetVecEnv",
    "VCPPEnv",
    "VCPPVecEnv",
    "VCPPVectorEnv",
    "make_fleet_vec_env",
    "make_vec_env",
]

_LAZY = {
    "VCPPEnv": "pirl.env.vcpp_env",
    "VCPPVecEnv": "pirl.env.sb3_vec",
    "make_vec_env": "pirl.env.sb3_vec",
    "VCPPVectorEnv": "pirl.env.gym_vector",
    "FleetParallelEnv": "pirl.env.fleet",
    "FleetVecEnv": "pirl.env.fleet",
    "make_fleet_vec_env": "pirl.env.fleet",
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'pirl.env' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


def __dir__() -> list[str]:
    return sorted(__all__)
