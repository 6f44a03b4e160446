"""PARE during training: a VecEnv wrapper that adds ``w_llm * f_llm`` to every world's reward.

Flow of one step (``mode="sync"``, the paper's timing):

1. After step t-1 the prompt for ``s_t`` of every world due a query is sent to the advisor in
   a background thread, so the LLM's latency overlaps the policy's forward pass.
2. ``step_async(a_t)`` remembers ``p_t``; ``step_wait`` steps the worlds, then waits (up to
   ``timeout_s``) for the answers about ``s_t``, computes the alignment of the move
   ``p_t -> p_{t+1}`` and of the new camera with the advice, and adds the LLM term to the
   reward ``r_{t+1}``.
3. The prompts for ``s_{t+1}`` go out at once.

``mode="async"`` never waits: each world uses the freshest answer that has arrived (reporting
how many steps stale it is), and a new batch is sent whenever none is in flight. When the LLM
is slower than an episode, that answer may come from an earlier episode of the same world;
it is still used (its move as a direction, its camera as a target) and counted in
``answers_cross_episode``. Sync mode only uses advice about the current episode.

Between queries (``query_every`` K > 1) the last advice is reused: its move is read as a
direction from the current position, its camera as a target. A failed, late or unparseable
answer gives ``f_llm = 0`` for that step and is counted; it never stops training.

Per step, ``info["pare"]`` holds ``f_llm``, ``dir_align``, ``pos_align``, ``move``, ``cam``,
``status`` (fresh, cached, stale or missing) and ``staleness`` (steps); the LLM term also
appears in ``info["reward_terms"]["llm"]``.
"""

from __future__ import annotations

import contextlib
import time
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnvWrapper

from pirl.advice.base import Advisor, Answer
from pirl.advice.factory import exhausted
from pirl.advice.state import advice_requests
from pirl.env.vec_env import VCPPVecEnv
from pirl.pare.alignment import _align_one
from pirl.world import dynamics as D
from pirl.world.config import ConfigError

STATUSES = ("missing", "fresh", "cached", "stale")
_MISSING, _FRESH, _CACHED, _STALE = range(4)


@numba.njit(cache=True)
def _shape(
    p_t, ints, rec, has, rec_step, rec_cached, t, d_max, alpha, lam_cam, lam_move, weights,
    llm_col, rewards, terms, p_next, cam_next, table, status, staleness, counts,
):  # fmt: skip
    """One step of PARE for every world: alignment, f_llm, status, the shaped reward.

    ``table`` rows get (f_llm, dir_align, pos_align, move, cam), all 0 without advice; the LLM
    term is written into the step's reward terms and ``w_llm * f_llm`` added to ``rewards``.
    ``counts`` accumulates (missing, fresh, cached, stale, staleness sum).
    """
    for e in range(p_t.shape[0]):
        p_next[e, 0], p_next[e, 1], p_next[e, 2] = ints[e, D.PX], ints[e, D.PY], ints[e, D.PZ]
        cam_next[e, 0], cam_next[e, 1] = ints[e, D.TILT], ints[e, D.PAN]
        cam_next[e, 2] = ints[e, D.ZOOM] / 10.0
        if not has[e]:
            for k in range(5):
                table[e, k] = 0.0
            status[e], staleness[e] = _MISSING, 0
            terms[e, llm_col] = 0.0
            counts[_MISSING] += 1
            continue
        _align_one(e, p_t, p_next, cam_next, rec, d_max, alpha, table[:, 1:])
        f = lam_cam * table[e, 4] + lam_move * table[e, 3]
        table[e, 0] = f
        terms[e, llm_col] = f
        rewards[e] += np.float32(weights[e, llm_col] * f)
        staleness[e] = t - rec_step[e]
        if staleness[e] > 0:
            status[e] = _STALE
        elif rec_cached[e]:
            status[e] = _CACHED
        else:
            status[e] = _FRESH
        counts[status[e]] += 1
        counts[4] += staleness[e]


@dataclass
class _Job:
    """One batch of prompts in flight."""

    worlds: np.ndarray
    episodes: np.ndarray
    step: int
    future: Future
    sent: float = field(default_factory=time.perf_counter)


@dataclass
class PareStats:
    """Counters of one PARE run (all cumulative)."""

    steps: int = 0
    prompts_sent: int = 0
    batches_sent: int = 0
    answers_ok: int = 0
    answers_failed: int = 0
    answers_unparseable: int = 0
    answers_late: int = 0
    answers_cached: int = 0
    answers_cross_episode: int = 0
    steps_fresh: int = 0
    steps_cached: int = 0
    steps_stale: int = 0
    steps_missing: int = 0
    staleness_sum: int = 0
    wait_s: float = 0.0
    budget_exhausted: bool = False

    def as_dict(self) -> dict[str, Any]:
        out = dict(self.__dict__)
        shaped = self.steps_fresh + self.steps_cached + self.steps_stale
        out["mean_staleness"] = self.staleness_sum / shaped if shaped else 0.0
        answered = self.answers_ok + self.answers_unparseable
        out["parse_rate"] = self.answers_ok / answered if answered else 0.0
        return out


class PAREVecEnv(VecEnvWrapper):
    """Adds the PARE reward term to a :class:`~pirl.env.vec_env.VCPPVecEnv`.

    Arguments:
        venv: the batched environment, made with ``llm_weight=True`` so that each episode
            draws (EWRI) or sets (static) the weight of the LLM term.
        advisor: any :class:`~pirl.advice.base.Advisor` (wrap it in a cache or budget first).
        query_every: K, ask every K steps of each world (paper: 1).
        mode: ``"sync"`` (the paper's timing) or ``"async"`` (never blocks).
        lam_cam, lam_move, alpha: the weights of DESIGN.md section 5.
        timeout_s: sync mode: longest wait for a batch; later answers count as late.
        prompt_variant, decimals: passed to :func:`pirl.advice.prompt.build_prompt`.
    """

    def __init__(
        self,
        venv: VCPPVecEnv,
        advisor: Advisor,
        query_every: int = 1,
        mode: str = "sync",
        lam_cam: float = 1.0,
        lam_move: float = 1.0,
        alpha: float = 0.5,
        timeout_s: float = 120.0,
        prompt_variant: str = "paper",
        decimals: int = 2,
    ) -> None:
        if not isinstance(venv, VCPPVecEnv):
            raise ConfigError("PARE wraps the VCPPVecEnv itself (put VecMonitor outside it)")
        if not venv.cfg.llm_weight:
            raise ConfigError("PARE needs an environment made with llm_weight=True")
        if mode not in ("sync", "async"):
            raise ConfigError(f"mode={mode!r}: allowed values are sync, async")
        if query_every < 1:
            raise ConfigError(f"query_every={query_every!r}: must be >= 1")
        super().__init__(venv)
        self.advisor = advisor
        self.query_every = int(query_every)
        self.mode = mode
        self.lam_cam, self.lam_move, self.alpha = float(lam_cam), float(lam_move), float(alpha)
        self.timeout_s = float(timeout_s)
        self.prompt_variant, self.decimals = prompt_variant, int(decimals)
        self.stats = PareStats()

        n = venv.num_envs
        self._world = venv.world
        self._rec = np.zeros((n, 6), dtype=np.float64)  # pan, tilt, zoom, dx, dy, dz
        self._has_rec = np.zeros(n, dtype=bool)
        self._rec_step = np.zeros(n, dtype=np.int64)
        self._rec_cached = np.zeros(n, dtype=bool)
        self._episode = np.zeros(n, dtype=np.int64)
        self._episode_step = np.zeros(n, dtype=np.int64)
        self._want = np.zeros(n, dtype=bool)  # due a query, not yet sent
        self._p_t = np.zeros((n, 3), dtype=np.float64)
        self._p_next = np.zeros((n, 3), dtype=np.float64)
        self._cam_next = np.zeros((n, 3), dtype=np.float64)
        self._table = np.zeros((n, 5), dtype=np.float64)
        self._status = np.zeros(n, dtype=np.int64)
        self._staleness = np.zeros(n, dtype=np.int64)
        self._counts = np.zeros(5, dtype=np.int64)  # missing, fresh, cached, stale, stale sum
        self._d_max = float(np.linalg.norm(np.asarray(venv.cfg.size, dtype=np.float64) - 1.0))
        self._t = 0
        self._job: _Job | None = None
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="pare-advisor")

    # -- requests -------------------------------------------------------------------------
    def _submit(self, worlds: np.ndarray) -> None:
        """Send the prompts of ``worlds`` (their current state) as one batch."""
        if not worlds.size or exhausted(self.advisor):
            self.stats.budget_exhausted = exhausted(self.advisor)
            return
        prompts, views = advice_requests(
            self._world, worlds, self.advisor, self.prompt_variant, self.decimals
        )
        future = self._pool.submit(self.advisor.advise, prompts, views)
        self._job = _Job(worlds, self._episode[worlds].copy(), self._t, future)
        self.stats.prompts_sent += len(prompts)
        self.stats.batches_sent += 1

    def _send_due(self) -> None:
        """Mark the worlds due a query this step; send all waiting ones if nothing is in flight."""
        self._want |= self._episode_step % self.query_every == 0
        if self._job is None:
            worlds = np.flatnonzero(self._want)
            self._want[:] = False
            self._submit(worlds)

    def _collect(self, wait: bool) -> None:
        """Take the in-flight batch's answers if they are there (sync: wait for them)."""
        job = self._job
        if job is None:
            return
        if not wait and not job.future.done():
            return
        start = time.perf_counter()
        try:
            answers: list[Answer] = job.future.result(timeout=self.timeout_s if wait else 0)
        except FutureTimeout:
            # Late: the step goes on without advice; the batch is dropped.
            self.stats.answers_late += len(job.worlds)
            self.stats.wait_s += time.perf_counter() - start
            self._job = None
            self._has_rec[job.worlds] = False
            return
        except Exception as exc:  # an advisor must not raise; if one does, training goes on
            answers = [Answer("", None, error=f"{type(exc).__name__}: {exc}")] * len(job.worlds)
        self.stats.wait_s += time.perf_counter() - start
        self._job = None
        for e, episode, answer in zip(job.worlds, job.episodes, answers, strict=True):
            if answer.error is not None:
                self.stats.answers_failed += 1
            elif answer.recommendation is None:
                self.stats.answers_unparseable += 1
            else:
                self.stats.answers_ok += 1
                self.stats.answers_cached += int(answer.from_cache)
            if episode != self._episode[e]:
                if self.mode == "sync":
                    continue  # that episode is over
                # Async uses the freshest answer that has arrived, even one asked in an
                # earlier episode of this world: a slow LLM's answers may never arrive within
                # one episode. Its staleness says so.
                self.stats.answers_cross_episode += 1
            rec = answer.recommendation
            if rec is None:
                self._has_rec[e] = False
                continue
            self._rec[e] = (rec.pan, rec.tilt, rec.zoom, rec.dx, rec.dy, rec.dz)
            self._has_rec[e] = True
            self._rec_step[e] = job.step
            self._rec_cached[e] = answer.from_cache

    # -- VecEnv ---------------------------------------------------------------------------
    def reset(self) -> np.ndarray:
        obs = self.venv.reset()
        self._drain()
        self._has_rec[:] = False
        self._episode += 1
        self._episode_step[:] = 0
        self._want[:] = False
        self._send_due()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        ints = self._world.ints
        self._p_t[:] = ints[:, D.PX : D.PZ + 1]
        self.venv.step_async(actions)

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        self._collect(wait=self.mode == "sync")
        # The snapshot was taken before auto-reset: it holds p_{t+1}, the camera after the
        # action and the ended episodes' weights.
        snap = self.venv.step_snapshot
        table, status, staleness = self._table, self._status, self._staleness
        _shape(
            self._p_t, snap.ints, self._rec, self._has_rec, self._rec_step, self._rec_cached,
            self._t, self._d_max, self.alpha, self.lam_cam, self.lam_move, snap.weights,
            D.T_LLM, rewards, snap.terms, self._p_next, self._cam_next, table, status,
            staleness, self._counts,
        )  # fmt: skip
        # Copies: the lazy infos read them later, after these buffers moved on.
        table, status, staleness = table.copy(), status.copy(), staleness.copy()
        snap.extras["pare"] = lambda e: {
            "f_llm": float(table[e, 0]),
            "dir_align": float(table[e, 1]),
            "pos_align": float(table[e, 2]),
            "move": float(table[e, 3]),
            "cam": float(table[e, 4]),
            "status": STATUSES[status[e]],
            "staleness": int(staleness[e]),
        }
        st, counts = self.stats, self._counts
        st.steps += self.num_envs
        st.steps_missing, st.steps_fresh, st.steps_cached, st.steps_stale = (
            int(counts[_MISSING]),
            int(counts[_FRESH]),
            int(counts[_CACHED]),
            int(counts[_STALE]),
        )
        st.staleness_sum = int(counts[4])
        self._t += 1
        self._episode_step += 1
        if dones.any():
            ended = np.flatnonzero(dones)
            self._episode[ended] += 1
            self._episode_step[ended] = 0
            if self.mode == "sync":
                self._has_rec[ended] = False
            self._want[ended] = False
        self._send_due()
        return obs, rewards, dones, infos

    def _drain(self) -> None:
        if self._job is not None:
            # An unfinished batch is dropped at reset; its outcome no longer matters.
            with contextlib.suppress(Exception):
                self._job.future.result(timeout=self.timeout_s)
            self._job = None

    def close(self) -> None:
        self._drain()
        self._pool.shutdown(wait=True)
        self.advisor.close()
        self.venv.close()
