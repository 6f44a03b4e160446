"""Per-step info: its keys, and LazyInfo (the batched env's lazily filled dict)."""

from __future__ import annotations

import copy
import json
import pickle

import gymnasium as gym
import numpy as np
import pytest

from pirl.config.world import REWARD_TERMS
from pirl.env import make_vec_env
from pirl.env.info import INFO_KEYS, LazyInfo

SETTINGS = {"size": (10, 10, 3), "wind_prob": 0.0}


@pytest.fixture
def pair():
    """A one-world vec env and a single env, same seed; ``step(a)`` returns both infos."""
    venv = make_vec_env(1, seed=0, **SETTINGS)
    env = gym.make("pirl/VCPP-v0", **SETTINGS)
    venv.reset()
    env.reset(seed=0)

    def step(action: int):
        _, _, _, vinfos = venv.step(np.array([action]))
        _, _, _, _, info = env.step(action)
        return vinfos[0], info

    return step


def unfilled(info: LazyInfo) -> bool:
    """No VCPP key has been materialised in the dict's own storage yet."""
    return not any(dict.__contains__(info, key) for key in INFO_KEYS)


def test_single_env_info_keys_and_types():
    env = gym.make("pirl/VCPP-v0", **SETTINGS)
    _, info = env.reset(seed=0)
    assert set(info) == INFO_KEYS - {"episode_metrics"}
    _, _, _, _, info = env.step(0)
    assert type(info) is dict
    assert list(info["reward_terms"]) == list(REWARD_TERMS)
    assert list(info["reward_weights"]) == list(REWARD_TERMS)
    assert isinstance(info["position"], tuple) and len(info["position"]) == 3
    assert isinstance(info["camera"], tuple) and info["camera"] == (90, 0, 1.0)
    for key in ("collision", "redundant", "idle", "wind"):
        assert isinstance(info[key], bool)
    for key in ("new_cells", "covered", "coverable", "steps"):
        assert type(info[key]) is int
    assert type(info["battery"]) is float
    json.dumps(info)  # plain Python values only


def test_vec_infos_are_lazy(pair):
    vinfo, _ = pair(0)
    assert isinstance(vinfo, LazyInfo) and isinstance(vinfo, dict)
    assert unfilled(vinfo)


def test_lazy_info_dict_equals_the_single_env_info(pair):
    vinfo, info = pair(0)
    plain = dict(vinfo)
    assert type(plain) is dict
    assert plain == info
    assert vinfo == info and info == vinfo
    vinfo, info = pair(2)
    assert vinfo == info  # __eq__ fills by itself
    vinfo, info = pair(2)
    assert info == vinfo  # reflected: LazyInfo is the subclass, so its __eq__ runs


def test_lazy_info_not_equal_is_consistent_with_equal(pair):
    vinfo, info = pair(0)
    assert (vinfo != info) is False
    vinfo, info = pair(1)
    assert (info != vinfo) is False


def test_lazy_info_json(pair):
    vinfo, info = pair(0)
    assert json.loads(json.dumps(vinfo)) == json.loads(json.dumps(info))


def test_lazy_info_pickle_and_copies(pair):
    vinfo, info = pair(0)
    restored = pickle.loads(pickle.dumps(vinfo))
    assert type(restored) is dict and restored == info
    vinfo, info = pair(1)
    deep = copy.deepcopy(vinfo)
    assert deep == info
    vinfo, info = pair(2)
    assert copy.copy(vinfo) == info
    vinfo, info = pair(3)
    assert vinfo.copy() == info and type(vinfo.copy()) is dict
    vinfo, info = pair(0)
    assert {**vinfo} == info


def test_lazy_info_merge_operator(pair):
    vinfo, info = pair(0)
    assert vinfo | {"extra": 1} == {**info, "extra": 1}


def test_lazy_info_membership_and_lookups(pair):
    vinfo, info = pair(0)
    assert "covered" in vinfo
    assert not unfilled(vinfo)
    vinfo, info = pair(1)
    assert vinfo["reward_terms"] == info["reward_terms"]
    assert vinfo.get("position") == info["position"]
    assert len(vinfo) == len(info)
    assert sorted(vinfo) == sorted(info)
    assert dict(vinfo.items()) == info
    assert list(vinfo.keys()) == list(vinfo)
    assert vinfo.pop("steps") == info["steps"] and "steps" not in vinfo
    assert repr(vinfo).startswith("{")


def test_lazy_info_foreign_keys_do_not_fill(pair):
    vinfo, _ = pair(0)
    assert vinfo.get("episode") is None
    assert vinfo.get("episode", 5) == 5
    assert "terminal_observation" not in vinfo
    assert "TimeLimit.truncated" not in vinfo
    with pytest.raises(KeyError):
        vinfo["episode"]
    assert vinfo.pop("episode", None) is None
    assert unfilled(vinfo)
    # Keys set by others (VecMonitor, the auto-reset) live beside the VCPP keys.
    vinfo["episode"] = {"r": 1.0, "l": 3}
    assert unfilled(vinfo)
    assert vinfo["episode"] == {"r": 1.0, "l": 3}
    assert set(dict(vinfo)) == INFO_KEYS - {"episode_metrics"} | {"episode"}


def test_lazy_info_keeps_values_set_before_filling(pair):
    vinfo, info = pair(0)
    vinfo["covered"] = -1
    assert vinfo["covered"] == -1
    assert vinfo["coverable"] == info["coverable"]


def test_lazy_info_is_a_snapshot(pair):
    vinfo, info = pair(0)
    for action in (0, 2, 8):
        pair(action)
    assert vinfo == info  # later steps do not change an earlier info
    assert vinfo["steps"] == 1


def test_lazy_info_not_hashable(pair):
    vinfo, _ = pair(0)
    with pytest.raises(TypeError):
        hash(vinfo)
