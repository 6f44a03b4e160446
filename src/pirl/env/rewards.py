"""Reward weights (static for PPO-SR, EWRI re-drawn at every reset) and the weighted sum.

The raw terms come from the world's rules (:mod:`pirl.world.dynamics`); this module only
decides how much each one counts (docs/design.md).
"""

from __future__ import annotations

import numpy as np

from pirl.config.world import REWARD_TERMS, VCPPConfig

LLM_INDEX = REWARD_TERMS.index("llm")


def draw_weights(cfg: VCPPConfig, rng: np.random.Generator) -> np.ndarray:
    """One episode's weights, in the order of REWARD_TERMS.

    EWRI draws every weight (the LLM one too, so the random stream does not depend on whether
    PARE is on); the LLM weight stays 0 unless ``cfg.llm_weight`` (set by PARE).
    """
    if cfg.reward == "ewri":
        ranges = np.asarray(cfg.ewri_ranges, dtype=np.float64)
        weights = rng.uniform(ranges[:, 0], ranges[:, 1])
    else:
        weights = np.asarray(cfg.static_weights, dtype=np.float64).copy()
    if not cfg.llm_weight:
        weights[LLM_INDEX] = 0.0
    return weights
