"""PARE's engine: one advice source, the advice board and the pure core, driven by an
environment adapter (:mod:`pirl.pare.sb3_vec` for Stable-Baselines3, :mod:`pirl.pare.gym_vector`
for Gymnasium) through the environment's public shaping hooks.

The advice about state ``s_t`` shapes the reward ``r_{t+1}``: after the action, the move
``p_t -> p_{t+1}`` and the new camera are compared with the advice (:mod:`pirl.pare.alignment`) and
``w_llm * f_llm`` is added to the reward, ``w_llm`` being the episode's weight of the LLM term.
None of the sources ever passes one state's advice off as another's. When more than
``max_failure_rate`` of the last ``failure_window`` teacher answers failed,
:class:`~pirl.pare.stats.AdvisorFailing` stops training.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from pirl.config.errors import ConfigError
from pirl.config.run import PareSettings
from pirl.env.shaping import ShapingHooks
from pirl.pare.board import AdviceBoard
from pirl.pare.bundle import AdviceBundle
from pirl.pare.core import Shaped, Weights, add_llm_term, shape
from pirl.pare.sources import SOURCES, AdviceSource, SourceSetup
from pirl.pare.stats import Health, PareStats

_NONE = np.zeros(0, dtype=np.int64)


class PARE:
    """Shapes the rewards of a batched VCPP environment with the advice of ``source``.

    Arguments:
        env: the batched environment (its shaping hooks), made with ``llm_weight=True`` so
            that each episode draws (EWRI) or sets (static) the weight of the LLM term.
        source: where the advice comes from.
        board: the advice each world holds (written by ``source``).
        health: the teacher's answers and failures (shared with ``source``).
        weights: the weights of the LLM term.
    """

    def __init__(
        self,
        env: ShapingHooks,
        source: AdviceSource,
        board: AdviceBoard,
        health: Health,
        weights: Weights,
    ) -> None:
        self.env, self.source, self.board, self.health = env, source, board, health
        self.weights = weights
        self._consts = weights.constants(env.cfg.size)
        self._p_t = np.zeros((board.n, 3), dtype=np.float64)
        # A fleet's slots whose UAV had left before the step (parked: no transition to shape).
        self._parked = np.zeros(board.n, dtype=np.bool_)
        # Cumulative steps per status, then the staleness sum.
        self._counts = np.zeros(6, dtype=np.int64)

    @classmethod
    def from_settings(
        cls,
        env: ShapingHooks,
        settings: PareSettings,
        advice: AdviceBundle,
        refit_every: int = 256,
        seed: int = 0,
        source: str = "",
    ) -> PARE:
        """PARE as the ``pare`` settings section says.

        ``advice`` is the run's advice side (:class:`~pirl.pare.bundle.AdviceBundle`:
        the teacher, in student mode the student and its dataset, the teacher's rate and
        batch size, the label); ``refit_every`` is PPO's ``n_steps``; ``seed`` the teacher's
        sampling stream; ``source`` the run's name in the teacher dataset (a resumed run
        deletes what it stored there after its checkpoint, then stores it again).
        """
        if not isinstance(env, ShapingHooks):
            raise ConfigError(
                "PARE wraps the batched VCPP environment itself (put VecMonitor outside it)"
            )
        if not env.cfg.llm_weight:
            raise ConfigError("PARE needs an environment made with llm_weight=True")
        # The section checked its mode and query_every when it was built (pirl.config.run).
        kind = SOURCES[settings.mode]
        board = AdviceBoard(env.num_envs)
        stats = PareStats(label=advice.label, mode=settings.mode)
        health = Health(advice.advisor, stats, settings.max_failure_rate, settings.failure_window)
        setup = SourceSetup(
            board, health, advice.advisor, settings, advice, int(refit_every), seed, source
        )
        weights = Weights(settings.lam_cam, settings.lam_move, settings.alpha)
        return cls(env, kind.build(setup), board, health, weights)

    @property
    def mode(self) -> str:
        """The source's mode: student, sync or async."""
        return self.source.mode

    @property
    def stats(self) -> PareStats:
        return self.health.stats

    # -- the steps ------------------------------------------------------------------------
    def start(self, obs: np.ndarray) -> None:
        """After every world was reset (``obs``: their first observations)."""
        self.source.reset()
        self.board.start_all()
        self.source.request(self.env, obs, None)

    def before_step(self) -> None:
        """Before the worlds step: where they are, and which of a fleet's UAVs are parked."""
        self._p_t[:] = self.env.poses()[:, :3]
        self._parked[:] = self.env.parked()

    def after_step(
        self,
        obs: np.ndarray,
        rewards: np.ndarray,
        dones: np.ndarray,
        live: np.ndarray | None = None,
        restarted: np.ndarray | None = None,
    ) -> Shaped:
        """Shape the step just taken: adds ``w_llm * f_llm`` to ``rewards`` in place and
        reports the LLM term through the env; then asks about the new states.

        ``dones``: the worlds whose episode ended on this step. With an environment that
        resets a world on the step after its end (Gymnasium's next-step autoreset), ``live``
        marks the worlds whose state is a real one now (not an ended episode's last) and
        ``restarted`` the worlds this step reset: their step is no transition, so it is
        neither shaped nor counted. Both None: every world is live (auto-reset at once).

        A fleet's UAV that had left before the step (parked, :meth:`ShapingHooks.parked`) took
        no step: its slot is neither shaped nor counted, and it is not asked about until its
        world starts again, so the counts, the teacher's samples and its price are UAV steps.
        """
        env, board, st = self.env, self.board, self.stats
        self.source.collect()
        shaped = shape(self._p_t, env.step_poses(), board.rec, board.meta, board.t, self._consts)
        skip = self._parked if restarted is None else self._parked | restarted
        if self._parked.any():
            shaped.table[self._parked] = 0.0
        f_llm = shaped.table[:, 0]
        env.set_step_term("llm", f_llm)
        add_llm_term(rewards, f_llm, env.step_weights("llm"))
        status, staleness = shaped.status, shaped.staleness
        if skip.any():
            status, staleness = status[~skip], staleness[~skip]
        self._counts[:5] += np.bincount(status, minlength=5)
        self._counts[5] += int(staleness.sum())
        st.steps += len(status)
        st.count_steps(self._counts)
        ended = np.flatnonzero(dones) if dones.any() else _NONE
        board.tick(ended)
        if restarted is not None:
            board.episode_step[restarted] = 0  # the reset was no step of the new episode
        if ended.size:
            self.source.end(ended)
        self.source.tick()
        parked = env.parked()
        if parked.any():
            live = ~parked if live is None else live & ~parked
        self.source.request(env, obs, live)
        return shaped

    # -- state ----------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume (at a rollout boundary); see each source for what it
        keeps of the advice in flight."""
        return {
            "board": self.board.state_dict(),
            "counts": self._counts.copy(),
            "stats": copy.deepcopy(self.stats.__dict__),
            "source": self.source.state_dict(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`state_dict` into a freshly built PARE."""
        self.board.load_state_dict(state["board"])
        self._counts[...] = state["counts"]
        st = self.stats
        label = st.label
        st.__dict__.update(copy.deepcopy(state["stats"]))
        st.label = label or st.label
        self.health.restart()
        self.source.load_state_dict(state["source"])

    def settle(self) -> PareStats:
        """At the end of a run, without waiting: count a teacher batch that has finished, and
        the prompts still in flight or waiting to be sent (``answers_in_flight``,
        ``teacher_waiting``), so that no prompt sent goes uncounted."""
        self.source.settle()
        return self.stats

    def close(self) -> None:
        """Stop the source and close the advisor."""
        self.source.close()
        self.health.advisor.close()


__all__ = ["PARE"]
