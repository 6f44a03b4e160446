"""PIRL: prompt-informed reinforcement learning for UAV visual coverage path planning.

``import pirl`` registers the Gymnasium environment ``pirl/VCPP-v0``, with its batched
version as the vector entry point (``gymnasium.make_vec("pirl/VCPP-v0", num_envs=N)``).
"""

from pirl import _numba_cache

# Before any kernel module is imported: numba fixes its cache location at decoration time.
_numba_cache.configure()

import gymnasium as _gym  # noqa: E402

import pirl_gym  # noqa: E402

__version__ = "0.1.0"

pirl_gym.register(_gym)
