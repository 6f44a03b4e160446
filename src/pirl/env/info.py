"""Per-step ``info`` dicts, built lazily for the batched environment.

Building 64 nested dicts per step would cost more than stepping the worlds, and most steps
nobody reads them (Stable-Baselines3 only looks up ``episode`` and ``terminal_observation``).
So each step takes a cheap snapshot of the state arrays, and each world's info is a
:class:`LazyInfo`: a real ``dict`` whose VCPP keys are filled from the snapshot the first time
any of them is read. Keys set by others (``terminal_observation``, ``episode``) work as usual.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pirl.config.world import REWARD_TERMS
from pirl.world.state import WorldBatch, copy_records

INFO_KEYS = frozenset(
    {
        "reward_terms",
        "reward_weights",
        "new_cells",
        "covered",
        "coverable",
        "battery",
        "collision",
        "redundant",
        "idle",
        "wind",
        "position",
        "camera",
        "steps",
        "episode_metrics",
        "action_mask",
    }
)


class InfoSnapshot:
    """Copies of the arrays an info is made of, at one step: the worlds' ``status`` and
    ``flags`` records, ``terms``, ``energy``, and the env's ``weights`` and ``masks``."""

    __slots__ = (
        "status", "terms", "weights", "flags", "energy", "capacity", "metrics", "masks", "extras",
    )  # fmt: skip

    def __init__(
        self,
        world: WorldBatch,
        weights: np.ndarray,
        metrics: dict[int, dict[str, float]],
        masks: np.ndarray | None = None,
    ) -> None:
        w = world.arrays
        self.status, self.flags = copy_records(w.status), copy_records(w.flags)
        self.terms, self.weights, self.energy = w.terms.copy(), weights.copy(), w.energy.copy()
        self.capacity = world.capacity
        self.metrics = metrics
        # None where the caller has no valid-action rule (then info has no "action_mask").
        self.masks = None if masks is None else masks.copy()
        # Wrappers add their own lazily built keys here: key -> function of the world index.
        self.extras: dict[str, Callable[[int], Any]] = {}

    def info(self, e: int) -> dict[str, Any]:
        """The full info dict of world ``e``."""
        r = dict(zip(self.status.dtype.names, self.status[e].tolist(), strict=True))
        f = dict(zip(self.flags.dtype.names, self.flags[e].tolist(), strict=True))
        info = {
            "reward_terms": dict(zip(REWARD_TERMS, self.terms[e].tolist(), strict=True)),
            "reward_weights": dict(zip(REWARD_TERMS, self.weights[e].tolist(), strict=True)),
            "new_cells": f["new_cells"],
            "covered": r["covered"],
            "coverable": r["coverable"],
            "battery": max(0.0, float(self.energy[e]) / self.capacity),
            "collision": bool(f["collision"]),
            "redundant": bool(f["redundant"]),
            "idle": bool(f["idle"]),
            "wind": bool(f["wind"]),
            "position": (r["x"], r["y"], r["z"]),
            "camera": (r["tilt"], r["pan"], r["zoom10"] / 10.0),
            "steps": r["steps"],
        }
        if self.masks is not None:
            # A tuple: info dicts are compared and written as JSON (action_masks() gives arrays).
            info["action_mask"] = tuple(self.masks[e].tolist())
        if e in self.metrics:
            info["episode_metrics"] = self.metrics[e]
        for key, build in self.extras.items():
            info[key] = build(e)
        return info

    def vector_info(self, worlds: np.ndarray | None = None) -> dict[str, Any]:
        """Every world's info as Gymnasium's vector envs give it: a dict of arrays (first axis
        = world), each key ``k`` with a boolean mask ``_k`` of the worlds that have it (those
        in the boolean mask ``worlds``, default all)."""
        n = self.status.shape[0]
        r, f = self.status, self.flags
        out: dict[str, Any] = {}
        every = np.ones(n, dtype=np.bool_) if worlds is None else np.asarray(worlds, np.bool_)

        def put(into: dict[str, Any], key: str, value: Any, mask: np.ndarray | None = None) -> None:
            into[key] = value
            into["_" + key] = every.copy() if mask is None else mask

        for key, table in (("reward_terms", self.terms), ("reward_weights", self.weights)):
            inner: dict[str, Any] = {}
            for k, name in enumerate(REWARD_TERMS):
                put(inner, name, table[:, k].copy())
            put(out, key, inner)
        put(out, "new_cells", f["new_cells"].copy())
        put(out, "covered", r["covered"].copy())
        put(out, "coverable", r["coverable"].copy())
        put(out, "battery", np.maximum(0.0, self.energy / self.capacity))
        for key in ("collision", "redundant", "idle", "wind"):
            put(out, key, f[key].astype(np.bool_))
        put(out, "position", np.stack([r["x"], r["y"], r["z"]], axis=1))
        camera = np.stack([r["tilt"], r["pan"], r["zoom10"]], axis=1).astype(np.float64)
        camera[:, 2] /= 10.0
        put(out, "camera", camera)
        put(out, "steps", r["steps"].copy())
        if self.masks is not None:
            put(out, "action_mask", self.masks.copy())
        ended = {e: m for e, m in self.metrics.items() if every[e]}
        if ended:
            mask = np.zeros(n, dtype=np.bool_)
            mask[list(ended)] = True
            names = next(iter(ended.values())).keys()
            metrics: dict[str, Any] = {}
            for name in names:
                column = np.zeros(n, dtype=np.float64)
                for e, values in ended.items():
                    column[e] = values[name]
                put(metrics, name, column, mask.copy())
            put(out, "episode_metrics", metrics, mask)
        for key, build in self.extras.items():
            put(out, key, np.array([build(e) for e in range(n)]))
        return out


class _Pending:
    """Marker kept in a LazyInfo's storage until it is filled (see LazyInfo)."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "<pending>"


_PENDING = _Pending()


class LazyInfo(dict):
    """A dict whose VCPP keys appear on first read. ``dict(info)`` gives a plain dict.

    Until filled, the underlying storage holds one private marker, so code that looks at the
    raw dict size (the C JSON encoder) goes through ``items()``, which fills it first.
    """

    __slots__ = ("_snap", "_e")

    def __init__(self, snap: InfoSnapshot, e: int) -> None:
        # dict.__new__ already made an empty dict; skipping dict.__init__ halves the cost.
        dict.__setitem__(self, _PENDING, None)
        self._snap: InfoSnapshot | None = snap
        self._e = e

    def _lazy(self, key: Any) -> bool:
        snap = self._snap
        return snap is not None and (key in INFO_KEYS or key in snap.extras)

    def _build(self, snap: InfoSnapshot) -> dict[str, Any]:
        return snap.info(self._e)

    def _fill(self) -> None:
        snap = self._snap
        if snap is not None:
            self._snap = None
            dict.pop(self, _PENDING, None)
            for key, value in self._build(snap).items():
                dict.setdefault(self, key, value)

    def __getitem__(self, key: Any) -> Any:
        if self._lazy(key):
            self._fill()
        return dict.__getitem__(self, key)

    def get(self, key: Any, default: Any = None) -> Any:
        if self._lazy(key):
            self._fill()
        return dict.get(self, key, default)

    def __contains__(self, key: object) -> bool:
        if self._lazy(key):
            self._fill()
        return dict.__contains__(self, key)

    def __delitem__(self, key: Any) -> None:
        if self._lazy(key):
            self._fill()
        dict.__delitem__(self, key)

    def setdefault(self, key: Any, default: Any = None) -> Any:
        if self._lazy(key):
            self._fill()
        return dict.setdefault(self, key, default)

    def pop(self, key: Any, *default: Any) -> Any:
        if self._lazy(key):
            self._fill()
        return dict.pop(self, key, *default)

    def popitem(self) -> tuple[Any, Any]:
        self._fill()
        return dict.popitem(self)

    def clear(self) -> None:
        self._snap = None
        dict.clear(self)

    def __iter__(self):
        self._fill()
        return dict.__iter__(self)

    def __reversed__(self):
        self._fill()
        return dict.__reversed__(self)

    def __len__(self) -> int:
        self._fill()
        return dict.__len__(self)

    def keys(self):
        self._fill()
        return dict.keys(self)

    def values(self):
        self._fill()
        return dict.values(self)

    def items(self):
        self._fill()
        return dict.items(self)

    def copy(self) -> dict[str, Any]:
        self._fill()
        return dict(dict.items(self))

    def __or__(self, other: Any) -> dict[str, Any]:
        return self.copy() | other

    def __ror__(self, other: Any) -> dict[str, Any]:
        return dict(other) | self.copy()

    def __ior__(self, other: Any) -> LazyInfo:
        self._fill()
        dict.update(self, other)
        return self

    def __eq__(self, other: object) -> bool:
        self._fill()
        if isinstance(other, LazyInfo):
            other._fill()
        return dict.__eq__(self, other)

    def __ne__(self, other: object) -> bool:
        return not self.__eq__(other)

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        self._fill()
        return dict.__repr__(self)

    def __reduce__(self):
        return (dict, (self.copy(),))


class LazyVectorInfo(LazyInfo):
    """The info of a Gymnasium vector env step (:meth:`InfoSnapshot.vector_info`), built on
    first read: one object per step, so a training loop that never reads it pays nothing."""

    __slots__ = ("_worlds",)

    def __init__(self, snap: InfoSnapshot, worlds: np.ndarray | None = None) -> None:
        super().__init__(snap, -1)
        self._worlds = worlds

    def _lazy(self, key: Any) -> bool:
        snap = self._snap
        if snap is None or not isinstance(key, str):
            return False
        name = key[1:] if key.startswith("_") else key
        return name in INFO_KEYS or name in snap.extras

    def _build(self, snap: InfoSnapshot) -> dict[str, Any]:
        return snap.vector_info(self._worlds)
