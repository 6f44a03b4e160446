"""The state hash of many seeded sphere-world episodes (a test helper).

It walks each seed's episode with seeded random actions and hashes, after the reset and after
every step, the observation, the reward and the world's pose, camera, counters, battery,
blocked and coverable grids, views and visits. Sphere worlds are the paper's: this hash, taken
on the code before the voxel world, must not change.
"""

from __future__ import annotations

import hashlib

import numpy as np

from pirl.env.vcpp_env import VCPPEnv

CONFIGS = {
    "paper": {"size": (15, 15, 3)},
    "frustum-occlusion": {
        "size": (20, 16, 4), "footprint": "frustum", "occlusion": True, "obstacles_max": 8,
        "obs_target": True, "obs_target_path": True, "obs_visits": True,
    },
    "target-line": {"size": (24, 18, 3), "obs_target": True, "obstacles_max": 6},
}  # fmt: skip
"""The configurations hashed: the paper's default, and the frustum camera with occlusion."""

FIELDS = ("status", "energy", "blocked", "coverable", "views", "visits", "redmask")


def state_hash(config: dict, seeds: range, steps: int = 40) -> str:
    """The sha256 of ``steps`` seeded random steps from each seed's reset."""
    digest = hashlib.sha256()
    env = VCPPEnv(**config)
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        for _ in range(steps + 1):
            digest.update(np.ascontiguousarray(obs).tobytes())
            for name in FIELDS:
                digest.update(np.ascontiguousarray(getattr(env.world, name)).tobytes())
            obs, reward, terminated, truncated, _ = env.step(int(rng.integers(env.action_space.n)))
            digest.update(np.float64(reward).tobytes())
            if terminated or truncated:
                break
    return digest.hexdigest()


if __name__ == "__main__":
    for name, config in CONFIGS.items():
        print(name, state_hash(config, range(200)))
