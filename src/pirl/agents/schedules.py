"""The learning-rate schedules PPO trains with, as classes SB3 can store without code."""

from __future__ import annotations

from pirl.config.run import PPOSettings


class LinearDecay:
    """The learning rate decayed linearly to 0 over the run: ``lr`` times the progress left.

    A class, not a lambda: SB3 stores the schedule in model.zip, and a class is stored as its
    name and one number (which :func:`pirl.agents.loading.load_sb3` can check) where a lambda
    would be stored as code."""

    def __init__(self, lr: float) -> None:
        self.lr = float(lr)

    def __call__(self, progress_remaining: float) -> float:
        return progress_remaining * self.lr


def learning_rate_of(p: PPOSettings) -> float | LinearDecay:
    """What SB3 gets as ``learning_rate`` for these PPO settings."""
    return LinearDecay(p.learning_rate) if p.lr_schedule == "linear" else p.learning_rate


__all__ = ["LinearDecay", "learning_rate_of"]
