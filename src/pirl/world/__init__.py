"""The grid world: configuration, obstacles and scenarios, footprints, rules, metrics.

Pure numpy/numba: no reinforcement learning and no LLM here.
"""

from pirl.world.config import REWARD_TERMS, ConfigError, VCPPConfig
from pirl.world.metrics import episode_metrics
from pirl.world.state import Scenario, WorldBatch, draw_scenario

__all__ = [
    "REWARD_TERMS",
    "ConfigError",
    "Scenario",
    "VCPPConfig",
    "WorldBatch",
    "draw_scenario",
    "episode_metrics",
]
