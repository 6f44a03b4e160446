"""The compiled rules take a handful of named arguments, and a world batch saves and loads its
state through ``state_dict``."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import numpy as np
from numba.core.dispatcher import Dispatcher

import pirl.env
import pirl.pare
import pirl.physics
import pirl.world
from pirl.env import VCPPEnv, VCPPVectorEnv, make_vec_env
from pirl.world.footprint import Lens
from pirl.world.state import STATE_ARRAYS, Params, WorldArrays, WorldBatch

MAX_PARAMETERS = 8
SMALL = {"size": (8, 8, 3), "max_steps": 40, "scale_by_alpha": False, "battery_capacity": 30.0}


def _kernels() -> dict[str, Dispatcher]:
    found = {}
    for package in (pirl.world, pirl.env, pirl.pare, pirl.physics):
        names = [package.__name__] + [
            m.name for m in pkgutil.walk_packages(package.__path__, package.__name__ + ".")
        ]
        for name in names:
            module = importlib.import_module(name)
            for attr, value in vars(module).items():
                if isinstance(value, Dispatcher) and value.py_func.__module__ == name:
                    found[f"{name}.{attr}"] = value
    return found


def test_no_kernel_takes_more_than_eight_parameters():
    kernels = _kernels()
    assert "pirl.env.core._step_serial" in kernels and "pirl.world.dynamics.step_one" in kernels
    wide = {
        name: len(inspect.signature(k.py_func).parameters)
        for name, k in kernels.items()
        if len(inspect.signature(k.py_func).parameters) > MAX_PARAMETERS
    }
    assert not wide, f"kernels over {MAX_PARAMETERS} parameters: {wide}"


def test_world_arrays_are_named_and_the_state_is_a_subset():
    world = WorldBatch(make_vec_env(1).cfg, 2)
    assert set(STATE_ARRAYS) <= set(WorldArrays._fields)
    assert world.status.dtype.names[:6] == ("x", "y", "z", "tilt", "pan", "zoom10")
    assert world.status is world.arrays.status  # one set of arrays, reached by name
    # The kernels pass Params where a footprint function wants a Lens.
    assert Params._fields[: len(Lens._fields)] == Lens._fields
    assert tuple(world.params[: len(Lens._fields)]) == tuple(world.lens)


def _play(env, steps: int, seed: int) -> list:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps):
        obs, rewards, dones, _ = env.step(rng.integers(0, 12, env.num_envs))
        out.append((obs.copy(), rewards.copy(), dones.copy()))
    return out


def test_vec_env_state_dict_continues_exactly_in_a_fresh_env():
    env = make_vec_env(3, 7, **SMALL)
    env.reset()
    _play(env, 25, 0)
    state = env.state_dict()
    expected = _play(env, 60, 1)  # crosses episode ends: the random generators matter
    fresh = make_vec_env(3, 99, **SMALL)
    fresh.reset()
    fresh.load_state_dict(state)
    for (o1, r1, d1), (o2, r2, d2) in zip(expected, _play(fresh, 60, 1), strict=True):
        assert np.array_equal(o1, o2) and np.array_equal(r1, r2) and np.array_equal(d1, d2)


def test_state_dict_is_a_copy_and_load_keeps_the_arrays_in_place():
    env = make_vec_env(2, 0, **SMALL)
    env.reset()
    state = env.state_dict()
    status = env.world.status
    _play(env, 5, 0)
    assert not np.array_equal(state["core"]["world"]["status"], env.world.status)
    env.load_state_dict(state)
    assert env.world.status is status
    assert np.array_equal(env.world.status, state["core"]["world"]["status"])


def test_gymnasium_envs_state_dict_continue_exactly():
    single = VCPPEnv(**SMALL)
    single.reset(seed=4)
    for a in (0, 2, 6, 10):
        single.step(a)
    state = single.state_dict()
    then = [single.step(a)[:4] for a in (1, 3, 5, 7, 9, 11) * 8]
    other = VCPPEnv(**SMALL)
    other.reset(seed=5)
    other.load_state_dict(state)
    again = [other.step(a)[:4] for a in (1, 3, 5, 7, 9, 11) * 8]
    for x, y in zip(then, again, strict=True):
        assert np.array_equal(x[0], y[0]) and x[1:] == y[1:]

    vector = VCPPVectorEnv(2, **SMALL)
    vector.reset(seed=1)
    state = vector.state_dict()
    actions = np.random.default_rng(2).integers(0, 12, (50, 2))
    then = [vector.step(a)[:4] for a in actions]
    other = VCPPVectorEnv(2, **SMALL)
    other.reset(seed=8)
    other.load_state_dict(state)
    for x, y in zip(then, [other.step(a)[:4] for a in actions], strict=True):
        assert all(np.array_equal(p, q) for p, q in zip(x, y, strict=True))
