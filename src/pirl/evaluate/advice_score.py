"""How good is an advisor? ``pirl advise --score N``: its answers against the oracle's.

N states are drawn from seeded planner and random rollouts on validation scenarios (15x15x3
and 30x30x3: never training's, never evaluation's). The advisor under test and the oracle
(accuracy 1) answer each; the score says how often they agree on the move, on the cell the
UAV would reach and on the camera, with Cohen's kappa beside each (agreement beyond what
their answer frequencies give by chance), how much reward PARE would pay an agent that does
what the oracle advises (``alignment_mean``), how fast and how long the answers are, and what
one PIRL run of a profile would cost in calls, tokens and, given prices, money.

An unparseable answer counts as a disagreement everywhere (its own class in the kappas) and
earns no alignment.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pirl.advice.base import Advisor, Answer
from pirl.advice.oracle import MOVES, oracle_recommendation
from pirl.advice.recommendation import Recommendation
from pirl.advice.state import view_requests
from pirl.advice.student import cohen_kappa
from pirl.agents.methods import ADVISED, PLAYED_ALONE
from pirl.config import grid
from pirl.config.choices import PareMode
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig
from pirl.evaluate.scenarios import validation_seeds
from pirl.world.planning import WorldView

SCORE_SIZES: tuple[tuple[int, int, int], ...] = ((15, 15, 3), (30, 30, 3))
"""The validation worlds states are drawn from (half each)."""
KEEP = 0.2
"""Share of rollout steps kept as states, so they spread over whole episodes."""
CHARS_PER_TOKEN = 4.0
"""Tokens are estimated as characters / 4 where neither the server nor a tokenizer counts."""


@dataclass(frozen=True)
class AdviceScore:
    """What ``pirl advise --score`` prints (and ``--out`` writes, as these keys)."""

    advisor: str
    """The advisor's label (with its model)."""
    states: int
    """States asked about."""
    parse_rate: float
    """Share of answers that parse."""
    agreement_move: float
    """Share whose move (dx, dy, dz) is the oracle's."""
    kappa_move: float
    """Cohen's kappa of the moves against the oracle's."""
    agreement_position: float
    """Share that would take the UAV to the oracle's cell (a move into an obstacle or off
    the grid leaves it where it is)."""
    kappa_position: float
    """Cohen's kappa of the cells reached."""
    agreement_camera: float
    """Share whose pan, tilt and zoom (on the camera grid) are all the oracle's."""
    kappa_camera: float
    """Cohen's kappa of the camera poses."""
    alignment_mean: float
    """Mean PARE reward term (pare.lam_cam x cam + pare.lam_move x move) an agent doing what
    the oracle advises would earn from these answers; 0 for an unparseable one."""
    alignment_oracle: float
    """The same for the oracle's own answers: the most PARE pays."""
    latency_p50_s: float
    """Median answer latency, seconds (cached answers count as asked)."""
    latency_p95_s: float
    """95th percentile latency, seconds."""
    tokens_in: float
    """Mean prompt tokens per answer."""
    tokens_out: float
    """Mean completion tokens per answer."""
    tokens_counted_by: str
    """Who counted them: 'server' (its usage field), 'estimate' (characters / 4)."""

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class RunPrice:
    """What one PIRL run of a profile asks of its advisor."""

    profile: str
    calls: int
    """LLM calls: the teacher's (student mode: teacher_rate x steps, x student_closed_rate as
    if the gate never opened) plus the head start, or
    one per world every query_every steps (sync and async)."""
    tokens_in: int
    tokens_out: int
    cost: float | None
    """In the currency of the prices given, None without prices."""
    calls_gate_open: int = 0
    """The calls when the student's gate opens at once (the teacher at its own rate); the
    tokens and cost above are for :attr:`calls`, the most."""

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def line(self) -> str:
        money = "" if self.cost is None else f", cost {self.cost:,.2f}"
        calls = f"{self.calls:,} LLM calls"
        if self.calls_gate_open and self.calls_gate_open != self.calls:
            calls = (
                f"{self.calls_gate_open:,} to {self.calls:,} LLM calls (the most while the "
                "student's gate stays closed)"
            )
        return (
            f"price of one PIRL run of {self.profile}: {calls}, "
            f"{self.tokens_in:,} tokens in, {self.tokens_out:,} tokens out{money}"
        )


def score_states(cfg: RunConfig, n: int, seed: int = 0) -> list[WorldView]:
    """``n`` frozen world states from planner and random rollouts (episodes alternate) on the
    validation scenarios of :data:`SCORE_SIZES`, the same for every advisor."""
    from pirl.agents.loading import load_policy
    from pirl.env.vcpp_env import VCPPEnv

    if n < 1:
        raise ConfigError(f"--score {n}: ask about at least 1 state")
    views: list[WorldView] = []
    rng = np.random.default_rng([seed, 0xAD1CE])
    for k, size in enumerate(SCORE_SIZES):
        want = n // len(SCORE_SIZES) + (1 if k < n % len(SCORE_SIZES) else 0)
        env = VCPPEnv(ADVISED.trains_on(cfg.env.replace(size=size)))
        policies = [load_policy(name, seed=seed) for name in PLAYED_ALONE]
        got = 0
        for episode, scenario in enumerate(validation_seeds(size, 10_000)):
            if got >= want:
                break
            policy = policies[episode % 2]
            obs, info = env.reset(seed=scenario)
            policy.reset(env.world, 0, seed=scenario)
            done = False
            while not done and got < want:
                if rng.random() < KEEP:
                    views.append(WorldView.of(env.world, 0, copy=True))
                    got += 1
                obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
                done = terminated or truncated
    return views


def _move_class(rec: Recommendation | None) -> int:
    if rec is None:
        return len(MOVES) + 1
    move = (int(rec.dx), int(rec.dy), int(rec.dz))
    return MOVES.index(move) if move in MOVES else len(MOVES)


def _reached(view: WorldView, rec: Recommendation | None) -> int:
    """Class of the cell the UAV reaches: the move's, or hold when the move is not free."""
    if rec is None:
        return len(MOVES) + 1
    move = (int(rec.dx), int(rec.dy), int(rec.dz))
    if move not in MOVES:
        return len(MOVES)
    x, y, z = view.position
    target = (x + move[0], y + move[1], z + move[2])
    return MOVES.index(move) if view.free(target) else 0


_PANS, _TILTS, _ZOOMS = grid.pan_steps(), grid.tilt_steps(), grid.zoom_steps()


def _nearest(values: Sequence[float], value: float) -> int:
    return int(np.argmin([abs(v - value) for v in values]))


def _camera_class(rec: Recommendation | None) -> int:
    if rec is None:
        return len(_PANS) * len(_TILTS) * len(_ZOOMS)
    p, t, z = _nearest(_PANS, rec.pan), _nearest(_TILTS, rec.tilt), _nearest(_ZOOMS, rec.zoom)
    return (p * len(_TILTS) + t) * len(_ZOOMS) + z


def _alignment(views: Sequence[WorldView], recs: Sequence[Recommendation | None],
               oracle: Sequence[Recommendation], cfg: RunConfig) -> float:  # fmt: skip
    """Mean f_llm an agent following ``oracle`` would earn under advice ``recs``."""
    from pirl.pare.alignment import alignment_arrays

    rows = [k for k, r in enumerate(recs) if r is not None]
    if not rows:
        return 0.0
    total = 0.0
    for size in {views[k].cfg.size for k in rows}:
        idx = [k for k in rows if views[k].cfg.size == size]
        p_t = np.array([views[k].position for k in idx], dtype=np.float64)
        p_next = p_t.copy()
        for row, k in enumerate(idx):
            o = oracle[k]
            target = tuple(int(v) for v in p_t[row] + (o.dx, o.dy, o.dz))
            if views[k].free(target):
                p_next[row] = target
        cam = np.array([(o.tilt, o.pan, o.zoom) for o in (oracle[k] for k in idx)])
        rec = np.array([[r.pan, r.tilt, r.zoom, r.dx, r.dy, r.dz] for r in (recs[k] for k in idx)])
        _, _, move, cam_term = alignment_arrays(
            p_t, p_next, cam, rec, np.asarray(size), cfg.pare.alpha
        )
        total += float((cfg.pare.lam_cam * cam_term + cfg.pare.lam_move * move).sum())
    return total / len(recs)


def _tokens(answers: Sequence[Answer], prompts: Sequence[str]) -> tuple[float, float, str]:
    counted = [a for a in answers if a.prompt_tokens > 0 and not a.from_cache]
    if counted and len(counted) == len([a for a in answers if not a.from_cache]):
        return (
            float(np.mean([a.prompt_tokens for a in counted])),
            float(np.mean([a.completion_tokens for a in counted])),
            "server",
        )
    tin = float(np.mean([len(p) for p in prompts])) / CHARS_PER_TOKEN
    tout = float(np.mean([len(a.text) for a in answers])) / CHARS_PER_TOKEN
    return tin, tout, "estimate"


def score_advisor(
    advisor: Advisor,
    cfg: RunConfig,
    n: int,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    batch: int = 16,
) -> AdviceScore:
    """Ask ``advisor`` about :func:`score_states` and score its answers against the oracle's."""
    views = score_states(cfg, n, seed)
    prompts, shown = view_requests(views, advisor, cfg.pare.prompt_variant)
    answers: list[Answer] = []
    for lo in range(0, len(prompts), batch):
        part = None if shown is None else shown[lo : lo + batch]
        answers += advisor.advise(prompts[lo : lo + batch], part)
        if progress is not None:
            progress(len(answers), len(prompts))
    oracle = [oracle_recommendation(v) for v in views]
    recs = [a.recommendation for a in answers]

    def pair(classes: Callable[..., int], *, with_view: bool = False, k: int) -> tuple:
        if with_view:
            got = np.array([classes(v, r) for v, r in zip(views, recs, strict=True)])
            want = np.array([classes(v, o) for v, o in zip(views, oracle, strict=True)])
        else:
            got = np.array([classes(r) for r in recs])
            want = np.array([classes(o) for o in oracle])
        return float((got == want).mean()), cohen_kappa(got, want, k)

    n_moves = len(MOVES) + 2
    move = pair(_move_class, k=n_moves)
    position = pair(_reached, with_view=True, k=n_moves)
    camera = pair(_camera_class, k=len(_PANS) * len(_TILTS) * len(_ZOOMS) + 1)
    latency = np.array([a.latency_s for a in answers], dtype=np.float64)
    tin, tout, counted_by = _tokens(answers, prompts)
    return AdviceScore(
        advisor=str(getattr(advisor, "label", advisor)),
        states=len(answers),
        parse_rate=float(np.mean([r is not None for r in recs])),
        agreement_move=move[0], kappa_move=move[1],
        agreement_position=position[0], kappa_position=position[1],
        agreement_camera=camera[0], kappa_camera=camera[1],
        alignment_mean=_alignment(views, recs, oracle, cfg),
        alignment_oracle=_alignment(views, oracle, oracle, cfg),
        latency_p50_s=float(np.percentile(latency, 50)),
        latency_p95_s=float(np.percentile(latency, 95)),
        tokens_in=tin, tokens_out=tout, tokens_counted_by=counted_by,
    )  # fmt: skip


def run_calls(cfg: RunConfig, advisor: str, gate_open: bool = False) -> int:
    """LLM calls one PIRL run of ``cfg`` makes with ``advisor``: in student mode its teacher
    rate times the run's steps (times ``pare.student_closed_rate``, as if the student's gate
    never opened: the most it can ask; ``gate_open``: the rate alone, the least) plus the
    profile's head start (LLM teachers only); otherwise one answer per world every
    ``pare.query_every`` steps."""
    from pirl.advice.registry import advisor_kind
    from pirl.agents.settings import method_steps

    steps = method_steps(cfg, ADVISED.name)
    kind = advisor_kind(advisor)
    p = cfg.pare
    if p.mode == PareMode.STUDENT:
        head_start = int(cfg.reproduce.teacher_phase_answers) if kind.llm else 0
        rate = kind.teacher_rate(cfg) * (1.0 if gate_open else p.student_closed_rate)
        return int(math.ceil(rate * steps)) + head_start
    return int(math.ceil(steps / p.query_every))


def price_run(
    cfg: RunConfig,
    advisor: str,
    profile: str,
    tokens_in: float,
    tokens_out: float,
    price_in: float | None = None,
    price_out: float | None = None,
) -> RunPrice:
    """The calls, tokens and (with prices per million tokens) cost of one PIRL run."""
    calls = run_calls(cfg, advisor)
    t_in, t_out = int(round(calls * tokens_in)), int(round(calls * tokens_out))
    cost = None
    if price_in is not None or price_out is not None:
        cost = (t_in * (price_in or 0.0) + t_out * (price_out or 0.0)) / 1e6
    return RunPrice(profile, calls, t_in, t_out, cost, run_calls(cfg, advisor, gate_open=True))


def prompt_tokens_estimate(cfg: RunConfig) -> float:
    """Tokens of one prompt of ``cfg``'s training world (characters / 4): for plans printed
    before any advisor is asked."""
    from pirl.advice.state import advice_requests
    from pirl.env.vcpp_env import VCPPEnv

    env = VCPPEnv(cfg.env.replace(llm_weight=False))
    env.reset(seed=validation_seeds(cfg.env.size, 1)[0])
    prompts, _ = advice_requests(env.world, [0], None, cfg.pare.prompt_variant)
    return len(prompts[0]) / CHARS_PER_TOKEN


__all__ = [
    "AdviceScore",
    "RunPrice",
    "price_run",
    "prompt_tokens_estimate",
    "run_calls",
    "score_advisor",
    "score_states",
]
