"""Shared fixtures for the world and environment tests.

Most tests build small hand-made worlds: ``open_env(start, ...)`` gives a single environment
(through ``gymnasium.make``) reset on a scenario with the given obstacles (none by default),
start cell and wind seed, with wind off unless asked.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

import pirl  # noqa: F401  (registers pirl/VCPP-v0)
from pirl._paths import cache_root
from pirl.world.scenario import Scenario

# Compiled kernels are shared by every test process and the `pirl` subprocesses tests start.
# Those subprocesses get a cache folder of their own (PIRL_CACHE_DIR, to test the advice
# cache and datasets), which would put numba's cache there too: each compiled the world's
# kernels again, ~22 of the 29 s of a `pirl train --config test`.
os.environ.setdefault("PIRL_NUMBA_CACHE", str(cache_root() / "numba"))

EMPTY = np.zeros((0, 4))


@pytest.fixture(scope="session", autouse=True)
def _compiled_kernels() -> None:
    """The step kernels compiled once for every test process (the first compiles under the
    cache's lock, the others load what it wrote), not once per process on a fresh cache."""
    from pirl.env.core import compile_kernels

    compile_kernels()


# One torch thread per test process, as the product's own training and evaluation set it
# (ppo.torch_threads, evaluation workers). `make test` runs one test worker per core; torch's
# default of one thread per core in each worker makes them spin against each other: fitting
# a small student (test_advice_quality's kappa gate) took 2 s with one thread and 10 s with
# two on a loaded 2-core machine (82 s inside the full suite). A test that wants more threads
# sets them itself; subprocesses are unaffected.
torch.set_num_threads(1)


def scenario(
    start: tuple[int, int, int],
    obstacles: list[list[float]] | np.ndarray | None = None,
    wind_seed: int = 0,
) -> Scenario:
    """A hand-made scenario; no obstacles unless given as rows (cx, cy, cz, r)."""
    obs = EMPTY if obstacles is None else np.asarray(obstacles, dtype=np.float64).reshape(-1, 4)
    return Scenario(obstacles=obs, start=start, wind_seed=wind_seed)


@pytest.fixture
def make_env() -> Callable[..., gym.Env]:
    """Factory: ``make_env(size=..., **settings)`` -> gymnasium.make env (wind off by default)."""
    envs: list[gym.Env] = []

    def _make(size: tuple[int, int, int] = (5, 5, 3), **settings: Any) -> gym.Env:
        settings.setdefault("wind_prob", 0.0)
        env = gym.make("pirl/VCPP-v0", size=size, **settings)
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()


@pytest.fixture
def open_env(make_env) -> Callable[..., tuple[gym.Env, np.ndarray, dict]]:
    """Factory: ``open_env(start, size=..., obstacles=None, wind_seed=0, seed=0, **settings)``.

    Returns (env, first observation, first info) of an env reset on a hand-made scenario.
    """

    def _open(
        start: tuple[int, int, int],
        size: tuple[int, int, int] = (5, 5, 3),
        obstacles: list[list[float]] | None = None,
        wind_seed: int = 0,
        seed: int = 0,
        **settings: Any,
    ):
        env = make_env(size=size, **settings)
        obs, info = env.reset(
            seed=seed, options={"scenario": scenario(start, obstacles, wind_seed)}
        )
        return env, obs, info

    return _open


def rel_cells(cells: np.ndarray, origin: tuple[int, int]) -> set[tuple[int, int]]:
    """Footprint rows (i, j) as a set of offsets from ``origin``."""
    return {(int(i) - origin[0], int(j) - origin[1]) for i, j in cells}
