"""The single VCPP environment (Gymnasium API)."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig
from pirl.env.core import EnvCore, require_one_uav
from pirl.env.observation import obs_size_for
from pirl.env.render import render_world
from pirl.world import dynamics as D
from pirl.world.scenario import Scenario
from pirl.world.state import WorldBatch


class VCPPEnv(gym.Env):
    """Visual coverage path planning with a pan-tilt-zoom camera on a 3D grid.

    ## Description
    A UAV flies in an ``X x Y x Z`` grid with 2-5 spherical obstacles. Its camera sees a
    footprint of ground cells (``footprint="paper"``: a square whose size depends on zoom and
    tilt; ``"frustum"``: a pinhole camera, optionally occluded by obstacles). The task is to see
    every coverable ground cell while saving battery, avoiding collisions and redundant views.
    Random gusts (``wind_prob``) push the UAV one cell.

    ## Action Space
    ``Discrete(12)``: 0 x+, 1 x-, 2 y+, 3 y-, 4 z+, 5 z-, 6 tilt+5, 7 tilt-5, 8 pan+15,
    9 pan-15, 10 zoom+0.1, 11 zoom-0.1. A move into an obstacle or out of the grid leaves the UAV
    in place and is a collision; a camera action at its limit changes nothing. Tilt is in
    [0, 90] degrees (90 looks straight down), pan in [-90, 90] (0 = +x), zoom in [0.5, 2.0].
    ``action_masks()`` and ``info["action_mask"]`` give the actions that can change something
    (12 booleans; never all False), for masked policies such as sb3-contrib's ``MaskablePPO``.
    With ``stall_guard=N`` (0, off, is the paper's) the env takes over after N steps without
    new coverage: it carries out one action, whatever the policy chose, leading the UAV to the
    nearest ground not yet covered, until coverage grows (the mask shows only that action;
    ``episode_metrics["guarded_steps"]`` counts them).

    ## Observation Space
    ``Box(0, 1, (2*W*W + G*G + 11,), float32)`` with ``W = obs_window`` (11) and
    ``G = obs_global`` (8): 317 values by default, the same for every world size.

    ====================  ===========  ======================================================
    slice                 shape        meaning
    ====================  ===========  ======================================================
    ``[0, W*W)``          (W, W)       local window centred on the UAV (x rows, y columns):
                                       1 = coverable ground not yet covered
    ``[W*W, 2*W*W)``      (W, W)       local window: 1 = blocked at the UAV's altitude or
                                       outside the grid
    ``[2*W*W, +G*G)``     (G, G)       coarse global map: share of each block's coverable
                                       cells still uncovered
    last 11               scalars      x/(X-1), y/(Y-1), z/(Z-1), tilt/90, (pan+90)/180,
                                       (zoom-0.5)/1.5, battery, coverage so far,
                                       steps left / limit, blocked above, blocked below
    ====================  ===========  ======================================================

    ``obs_visits`` adds W*W visit counts and ``obs_target`` 3 values towards the nearest work
    left (by the way round obstacles with ``obs_target_path``): :mod:`pirl.env.observation`.

    ## Rewards
    ``r = sum_k w_k * term_k`` over ``coverage`` (new cells / largest footprint), ``redundant``
    (view added nothing), ``battery`` (energy used / energy of one x/y move), ``cam_usage``
    (a camera action added cells), ``curiosity`` (1/sqrt(visits) of the cell moved into),
    ``collision``, ``idle`` (nothing changed, no collision) and ``llm`` (PARE; 0 here).
    Weights are static (``reward="static"``, PPO-SR) or drawn at every reset from the EWRI
    ranges (``reward="ewri"``). ``info["reward_terms"]`` and ``info["reward_weights"]`` give
    both, so every reward can be recomputed.

    ## Starting State
    A seeded scenario: obstacles, a uniformly random free cell, camera tilt 90, pan 0, zoom 1.0,
    full battery. The first view is covered at reset without reward.

    ## Episode End
    Terminated when the battery is empty or every coverable cell is covered; truncated after
    ``max_steps`` steps. Battery capacity and ``max_steps`` scale with
    ``alpha = X*Y*Z / (15*15*3)`` unless ``scale_by_alpha=False``. At the end, ``info`` holds
    ``episode_metrics`` (VCR, BE, RVC, overlap, ...).

    ## Arguments
    ``gymnasium.make("pirl/VCPP-v0", size=(X, Y, Z), footprint="paper"|"frustum",
    reward="static"|"ewri", wind_prob=0.1, ...)``: any field of
    :class:`pirl.config.world.VCPPConfig` as a keyword, or ``config=`` a VCPPConfig or a
    mapping; ``render_mode="rgb_array"`` for top-down pictures. ``reset(options={"scenario":
    s})`` replays a given :class:`~pirl.world.scenario.Scenario`.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 8}

    def __init__(
        self,
        config: VCPPConfig | Mapping[str, Any] | None = None,
        render_mode: str | None = None,
        **settings: Any,
    ) -> None:
        self.cfg = VCPPConfig.resolve(config, settings)
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode={render_mode!r}: allowed values are None, 'rgb_array'")
        self.render_mode = render_mode
        require_one_uav(self.cfg, "pirl/VCPP-v0 (VCPPEnv)")
        self.core = EnvCore(self.cfg, 1)
        self.action_space = spaces.Discrete(D.N_ACTIONS)
        n = obs_size_for(self.cfg)
        self.observation_space = spaces.Box(0.0, 1.0, (n,), dtype=np.float32)
        self.path: list[tuple[int, int, int]] = []

    @property
    def world(self) -> WorldBatch:
        """The underlying one-world :class:`~pirl.world.state.WorldBatch`."""
        return self.core.world

    def state_dict(self) -> dict[str, Any]:
        """Copies of what this env owns (the core and its random generator), enough to continue
        exactly after :meth:`load_state_dict`."""
        return {"core": self.core.state_dict(), "np_random": copy.deepcopy(self.np_random)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Put a :meth:`state_dict` back (the render path starts afresh)."""
        self.core.load_state_dict(state["core"])
        self.np_random = copy.deepcopy(state["np_random"])
        self.path = [self.world.position(0)]

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        scenario: Scenario | None = (options or {}).get("scenario")
        self.core.reset_world(0, self.np_random, scenario)
        self.path = [self.world.position(0)]
        return self.core.obs[0].copy(), self.core.infos()[0]

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action) and not (
            isinstance(action, np.ndarray) and action.size == 1
        ):
            raise ValueError(f"action must be an integer in [0, 12); got {action!r}")
        self.core.step(np.asarray(action, dtype=np.int64).reshape(1))
        self.path.append(self.world.position(0))
        return (
            self.core.obs[0].copy(),
            float(self.core.rewards[0]),
            bool(self.core.terminated[0]),
            bool(self.core.truncated[0]),
            self.core.infos()[0],
        )

    def action_masks(self) -> np.ndarray:
        """The 12 actions that can change something now (``info["action_mask"]`` too): moves
        that stay inside the grid and out of obstacles, camera actions not at their limit.
        The method sb3-contrib's ``MaskablePPO`` looks for."""
        return self.core.masks[0].copy()

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return render_world(self.world, 0, self.path, self.cfg.render_cell_px)
