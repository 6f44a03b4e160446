"""Physics-based evaluation: the grid policy flown by a simulated quadrotor (docs/physics.md).

- :mod:`.mission`: the logic every backend shares (waypoints from actions, coverage from the
  pose, battery, metrics), built on the grid's own world, observation and metrics code.
- :mod:`.pyflyt_backend`: PyFlyt (PyBullet) QuadX; :func:`run_physics_episode` is
  ``pirl evaluate --sim physics``.
- :mod:`.webots`: a Webots world generator and a Mavic 2 Pro controller, for users who have
  Webots (not exercised in CI).

PyFlyt is imported only when a flight starts, so the world generator and the mission logic
load without it.
"""

from __future__ import annotations

from typing import Any

from pirl.physics.flight import Mission, Pose, StepPlan

__all__ = ["Mission", "Pose", "StepPlan", "run_physics_episode"]


def __getattr__(name: str) -> Any:
    if name == "run_physics_episode":
        from pirl.physics.pyflyt_backend import run_physics_episode

        return run_physics_episode
    raise AttributeError(f"module 'pirl.physics' has no attribute {name!r}")
