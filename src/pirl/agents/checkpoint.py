"""Resumable training state: everything needed to continue a PPO run exactly.

A checkpoint is a folder ``checkpoints/step_<N>/`` holding the SB3 model (weights and
optimizer, a copy for people; resuming does not read it) and ``state.npz`` (the policy and
optimizer tensors, worlds, their random streams, PARE's state, the monitor's counters, the
last observation and the global random states), written by :mod:`pirl.config.safe_state`:
arrays and JSON only, so a checkpoint from anyone can be resumed without running its code.
It is written into a temporary folder and renamed, and ``checkpoints/LATEST`` is replaced
atomically afterwards, so an interrupted write never damages the last good checkpoint.
"""

from __future__ import annotations

import copy
import random
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pirl._atomic import write_atomic
from pirl.agents.methods import PPO_ARTIFACT
from pirl.config import safe_state
from pirl.config.errors import ConfigError

if TYPE_CHECKING:  # SB3 brings torch: reading a run folder needs neither
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    from pirl.env.sb3_vec import VCPPVecEnv


def save_model(model: Any, path: Path) -> None:
    """``model.save(path)`` without the spaces' random generators: SB3 pickles each space
    whole, and a generator pickles as different numpy globals under numpy 1 and 2, which the
    safe loader (:data:`pirl.agents.loading.SB3_GLOBALS`) would have to trust. Nothing reads
    them back (the loader rebuilds the spaces from config.yaml); training keeps its own."""
    spaces = [getattr(model, k, None) for k in ("observation_space", "action_space")]
    spaces = [s for s in spaces if s is not None and hasattr(s, "_np_random")]
    kept = [s._np_random for s in spaces]
    try:
        for space in spaces:
            space._np_random = None
        model.save(path)
    finally:
        for space, rng in zip(spaces, kept, strict=True):
            space._np_random = rng


def capture(model: PPO, monitor: VecMonitor, venv: VCPPVecEnv, pare: Any | None) -> dict:
    """An in-memory copy of the whole training state (taken at a rollout boundary)."""
    state: dict[str, Any] = {
        "num_timesteps": int(model.num_timesteps),
        "n_updates": int(model._n_updates),  # SB3 logs train/n_updates from it
        "policy": {k: v.detach().clone() for k, v in model.policy.state_dict().items()},
        "optimizer": copy.deepcopy(model.policy.optimizer.state_dict()),
        # SB3 offers no public accessor for the rollout's next observation and episode starts.
        "last_obs": np.copy(model._last_obs),
        "last_episode_starts": np.copy(model._last_episode_starts),
        "ep_info_buffer": list(model.ep_info_buffer or []),
        "env": venv.state_dict(),
        "monitor": {
            "episode_returns": monitor.episode_returns.copy(),
            "episode_lengths": monitor.episode_lengths.copy(),
            "episode_count": monitor.episode_count,
        },
        "torch_rng": _torch().get_rng_state(),
        "numpy_rng": np.random.get_state(),
        "python_rng": random.getstate(),
    }
    if pare is not None:
        state["pare"] = pare.state_dict()
    return state


def restore(
    state: dict, model: PPO, monitor: VecMonitor, venv: VCPPVecEnv, pare: Any | None
) -> None:
    """Put a captured state back into a freshly built model and environment stack."""
    model.policy.load_state_dict(state["policy"])
    model.policy.optimizer.load_state_dict(state["optimizer"])
    model.num_timesteps = state["num_timesteps"]
    model._n_updates = int(state.get("n_updates", 0))  # older checkpoints lack it
    model._last_obs = state["last_obs"]
    model._last_episode_starts = state["last_episode_starts"]
    model.ep_info_buffer = None  # rebuilt by learn(); refilled below
    venv.load_state_dict(state["env"])
    monitor.episode_returns = state["monitor"]["episode_returns"].copy()
    monitor.episode_lengths = state["monitor"]["episode_lengths"].copy()
    monitor.episode_count = state["monitor"]["episode_count"]
    if pare is not None and "pare" in state:
        pare.load_state_dict(state["pare"])
    _torch().set_rng_state(state["torch_rng"])
    np.random.set_state(state["numpy_rng"])
    random.setstate(state["python_rng"])


def write(state: dict, model: PPO, folder: Path, keep: int = 3) -> Path:
    """Write ``state`` as ``folder/step_<N>`` atomically and point LATEST at it."""
    folder.mkdir(parents=True, exist_ok=True)
    name = f"step_{state['num_timesteps']}"
    final = folder / name
    tmp = folder / f".{name}.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    # The model file must hold the captured weights, not the live ones.
    live = {k: v.detach().clone() for k, v in model.policy.state_dict().items()}
    live_opt = copy.deepcopy(model.policy.optimizer.state_dict())
    live_steps = model.num_timesteps
    try:
        model.policy.load_state_dict(state["policy"])
        model.policy.optimizer.load_state_dict(state["optimizer"])
        model.num_timesteps = state["num_timesteps"]
        save_model(model, tmp / PPO_ARTIFACT)
    finally:
        model.policy.load_state_dict(live)
        model.policy.optimizer.load_state_dict(live_opt)
        model.num_timesteps = live_steps
    safe_state.save(state, tmp / STATE_FILE)
    shutil.rmtree(final, ignore_errors=True)
    tmp.rename(final)
    write_atomic(folder / "LATEST", name)
    for old in sorted(folder.glob("step_*"), key=lambda p: int(p.name.split("_")[1]))[:-keep]:
        if old.name != name:
            shutil.rmtree(old, ignore_errors=True)
    return final


STATE_FILE = "state.npz"
"""The resumable state in a checkpoint folder."""
OLD_STATE_FILE = "state.pkl"
"""What checkpoints held before they became safe to share: a pickle, never loaded."""


def latest(folder: Path) -> Path | None:
    """The checkpoint LATEST points at, or None."""
    pointer = folder / "LATEST"
    if not pointer.is_file():
        return None
    path = folder / pointer.read_text().strip()
    return path if (path / STATE_FILE).is_file() and (path / PPO_ARTIFACT).is_file() else None


def load_state(path: Path) -> dict:
    """The state of checkpoint folder ``path`` (arrays and JSON; nothing is unpickled)."""
    return safe_state.load(path / STATE_FILE)


def load_latest(folder: Path, log: Any = None) -> tuple[Path, dict] | None:
    """The newest checkpoint that loads, and its state: LATEST first, then older ones.

    A damaged checkpoint (a truncated ``state.pkl`` after a full disk, a copy cut short) is
    skipped with a note through ``log``; None when no checkpoint loads.
    """
    first = latest(folder)
    steps = sorted(folder.glob("step_*"), key=_step_of, reverse=True) if folder.is_dir() else []
    candidates = ([first] if first is not None else []) + [p for p in steps if p != first]
    for path in candidates:
        if (path / OLD_STATE_FILE).is_file() and not (path / STATE_FILE).is_file():
            raise safe_state.refuse_pickle(path / OLD_STATE_FILE, "a checkpoint")
        if not ((path / STATE_FILE).is_file() and (path / PPO_ARTIFACT).is_file()):
            continue
        try:
            state = load_state(path)
        except safe_state.UnsafeFile:
            raise
        except Exception as exc:  # noqa: BLE001 - any unreadable state means "damaged"
            if log is not None:
                log(f"resume: checkpoint {path} is damaged ({type(exc).__name__}); skipping it")
            continue
        if isinstance(state, dict) and "num_timesteps" in state:
            if "env" not in state:
                raise ConfigError(
                    f"resume: checkpoint {path} was written by an older pirl (world arrays "
                    "before the named world state); resume it with that version or start anew"
                )
            return path, state
    return None


def _step_of(path: Path) -> int:
    try:
        return int(path.name.split("_")[1])
    except (IndexError, ValueError):
        return -1


def _torch():
    # Imported when a checkpoint is taken or restored: a command that only reads a run
    # folder (and every refused one) starts without torch's 1.4 s import.
    import torch

    return torch
