"""The value sets of settings and options, each named once.

Members are ``str`` (:class:`enum.StrEnum`), so a config read from YAML compares equal to them
(``cfg.pare.mode == PareMode.STUDENT``) and messages print their plain values.
"""

from __future__ import annotations

from enum import StrEnum


class Sim(StrEnum):
    """Where an episode is flown: the grid simulator, or a simulated quadrotor (PyFlyt)."""

    GRID = "grid"
    PHYSICS = "physics"


class PareMode(StrEnum):
    """How PARE gets advice (``pare.mode``): a distilled student answers every step and the
    advisor teaches it, or the advisor is asked every K steps, waited for or not."""

    STUDENT = "student"
    SYNC = "sync"
    ASYNC = "async"


class DatasetScope(StrEnum):
    """Whose teacher answers a student learns from (``pare.student_dataset_scope``)."""

    RUN = "run"
    SHARED = "shared"


class Footprint(StrEnum):
    """The camera's ground footprint model (``env.footprint``)."""

    PAPER = "paper"
    FRUSTUM = "frustum"


class Act(StrEnum):
    """How a trained policy acts in evaluation: sampled (seeded per scenario) or its mode."""

    STOCHASTIC = "stochastic"
    GREEDY = "greedy"


__all__ = ["Act", "DatasetScope", "Footprint", "PareMode", "Sim"]
