"""Evaluation: episodes, metrics, scenario sets, reports."""

from pirl.evaluate.rollout import EpisodeResult, run_episode, save_gif

__all__ = ["EpisodeResult", "run_episode", "save_gif"]
