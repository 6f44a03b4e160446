"""Policies: learned (PPO methods, imitation), LLM-driven, and classical planners."""

from pirl.agents.boustrophedon import BoustrophedonPolicy
from pirl.agents.policy import Policy, RandomPolicy

__all__ = ["BoustrophedonPolicy", "Policy", "RandomPolicy"]
