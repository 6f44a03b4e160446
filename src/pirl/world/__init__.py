"""The grid world: obstacles and scenarios, footprints, rules, metrics (its settings are
:class:`pirl.config.world.VCPPConfig`).

Pure numpy/numba: no reinforcement learning and no LLM here.
"""

from pirl.world.metrics import episode_metrics
from pirl.world.scenario import Scenario, draw_scenario
from pirl.world.state import WorldBatch

__all__ = [
    "Scenario",
    "WorldBatch",
    "draw_scenario",
    "episode_metrics",
]
