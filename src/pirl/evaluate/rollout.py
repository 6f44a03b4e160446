"""Run one policy for one episode on a single environment, optionally recording frames."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import imageio.v2 as imageio
import numpy as np

from pirl.agents.policy import Policy
from pirl.env.vcpp_env import VCPPEnv


@dataclass
class EpisodeResult:
    """Metrics of one episode and, when recorded, its frames."""

    seed: int
    metrics: dict[str, float]
    frames: list[np.ndarray] = field(default_factory=list)


def run_episode(
    env: VCPPEnv, policy: Policy, seed: int, record: bool = False, frame_every: int = 1
) -> EpisodeResult:
    """Reset ``env`` with ``seed``, let ``policy`` act until the episode ends."""
    obs, info = env.reset(seed=seed)
    policy.reset(env.world, 0, seed=seed)
    frames = [env.render()] if record else []
    done = False
    step = 0
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        done = terminated or truncated
        step += 1
        if record and (done or step % frame_every == 0):
            frames.append(env.render())
    return EpisodeResult(seed, info["episode_metrics"], frames)


def save_gif(frames: list[np.ndarray], path: str | Path, fps: int = 12) -> Path:
    """Write frames as an animated GIF (parent folders created); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.gif")
    imageio.mimsave(tmp, frames, duration=1000 / fps, loop=0)
    tmp.replace(path)
    return path
