"""Run a policy: one episode on a single environment (optionally recording frames), or many
scenarios at once on the batched core with one policy forward per step."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import imageio.v2 as imageio
import numpy as np

from pirl._atomic import write_atomic
from pirl.agents.loading import LearnedPolicy, act_rng
from pirl.agents.policy import Policy
from pirl.config.errors import ConfigError
from pirl.config.world import VCPPConfig
from pirl.env.core import EnvCore
from pirl.env.vcpp_env import VCPPEnv
from pirl.world.metrics import Milestone, PathTail, episode_metrics


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
    tail, near = PathTail(1), Milestone(1)
    done = False
    step = 0
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        tail.record(env.world)
        near.record(env.world)
        done = terminated or truncated
        step += 1
        if record and (done or step % frame_every == 0):
            frames.append(env.render())
    metrics = {
        **info["episode_metrics"],
        "tail_cells": tail.distinct(0),
        "steps_to_99": near.steps(0),
    }
    return EpisodeResult(seed, metrics, frames)


def run_batch(cfg: VCPPConfig, policy: LearnedPolicy, seeds: list[int]) -> list[dict[str, float]]:
    """Play every scenario of ``seeds`` at once: one batched world, one ``act_batch`` per step.

    World ``i`` is reset exactly as ``VCPPEnv.reset(seed=seeds[i])`` resets (the same
    generator), and its actions are drawn from :func:`~pirl.agents.loading.act_rng` of its
    scenario, as :func:`run_episode` draws them, so the episode metrics equal the per-episode
    runner's. A world whose episode has ended holds still (its metrics are already taken)
    until the last one ends.
    """
    from gymnasium.utils import seeding

    n = len(seeds)
    core = EnvCore(cfg, n)
    rngs = []
    for e, seed in enumerate(seeds):
        core.reset_world(e, seeding.np_random(int(seed))[0])
        rngs.append(act_rng(int(seed)))
    metrics: list[dict[str, float] | None] = [None] * n
    active = np.ones(n, dtype=bool)
    actions = np.zeros(n, dtype=np.int64)
    tail, near = PathTail(n), Milestone(n)
    while active.any():
        live = np.flatnonzero(active)
        actions[live] = policy.act_batch(core.obs[live], [rngs[e] for e in live], core.masks[live])
        ended_any = core.step(actions)
        tail.record(core.world, live)
        near.record(core.world, live)
        if ended_any:
            flags = core.world.flags
            ended = live[(flags["terminated"][live] | flags["truncated"][live]) != 0]
            for e in ended:
                metrics[e] = {
                    **episode_metrics(core.world, int(e)),
                    "tail_cells": tail.distinct(e),
                    "steps_to_99": near.steps(int(e)),
                }
            active[ended] = False
    return [m for m in metrics if m is not None]


def record_gif(
    cfg: VCPPConfig, policy: Policy, seed: int, out: str | Path, fps: int = 12
) -> tuple[EpisodeResult, Path]:
    """``pirl render``: one episode of ``policy`` on scenario ``seed`` as an animated GIF at
    ``out``; refused before it flies when the GIF cannot be written or its frames would not
    fit in memory. Returns the episode and the GIF's path."""
    from pirl.env.render import cell_pixels
    from pirl.world.memory import check_memory

    check_gif_target(Path(out), fps)
    px = cell_pixels(cfg.size, cfg.render_cell_px)
    check_memory(cfg, 1, per_step_bytes=cfg.size[0] * cfg.size[1] * px * px * 3)
    if cfg.uavs > 1:  # a fleet: each UAV in its colour (docs/fleets.md)
        from pirl.evaluate.fleet import run_fleet_episode, team_for

        fleet = run_fleet_episode(cfg, seed, team_for(policy), record=True)
        result = EpisodeResult(seed, fleet.row, fleet.frames)
    else:
        result = run_episode(VCPPEnv(cfg, render_mode="rgb_array"), policy, seed, record=True)
    return result, save_gif(result.frames, out, fps=fps)


def save_gif(frames: list[np.ndarray], path: str | Path, fps: int = 12) -> Path:
    """Write frames as an animated GIF (parent folders created); returns the path.

    Written to a temporary name beside ``path`` and renamed, so a failed write (a full or
    read-only disk) leaves neither a partial GIF nor a stray temporary file."""
    path = Path(path)
    check_gif_target(path, fps)
    # Encoded in memory, then written by plain file IO: a failed write raises once, here,
    # instead of again from the GIF writer's finaliser.
    data = imageio.mimwrite("<bytes>", frames, format="GIF", duration=1000 / fps, loop=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_atomic(path, data, path.with_name(path.name + ".tmp.gif"))


def check_gif_target(path: Path, fps: int) -> None:
    """Refuse, before an episode is flown, a GIF that could not be written: ``fps`` < 1 or a
    ``path`` that is a folder."""
    if fps < 1:
        raise ConfigError(f"--fps {fps}: must be >= 1 frame per second")
    if Path(path).is_dir():
        raise ConfigError(
            f"--out {path} is a folder; give the GIF file to write, e.g. {path}/episode.gif"
        )
