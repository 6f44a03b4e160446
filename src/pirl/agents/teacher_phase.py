"""A head start for slow teachers: before a PIRL run, its teacher answers states of a reference
policy into the shared teacher dataset, so the run's student passes its gate at its first
rollouts instead of never.

``pirl reproduce`` runs one phase per distinct slow teacher (an LLM: the oracle answers fast
enough during the run) in a worker of its own while PPO-SR and PPO-EWRI train; the PIRL runs of
that teacher start when it is done. The answers are the teacher's own, asked now (nothing
precomputed is shipped), and they are stored under the same dataset key the run will use
(teacher, generation settings, prompt variant and text version, world settings), so answers of
another model or prompt never mix in.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pirl.advice.registry import advisor_kind
from pirl.agents.methods import PLANNER
from pirl.agents.pirl_advice import RUN_KEY, build_pirl_advice, dataset_path
from pirl.config.choices import DatasetScope, PareMode
from pirl.config.run import RunConfig
from pirl.pare.bundle import AdviceBundle

POLICY = PLANNER.name
"""The reference policy whose states the teacher answers: the planner covers the world
systematically, so its states span positions, coverage and battery levels."""
SEED = 7
"""Scenario stream of the phase (2,000,000 + 700,000 onwards: apart from training,
evaluation and ``pirl distill``'s default)."""
SOURCE = "teacher-phase:"
"""The dataset source of every answer a phase stores (followed by the phase's name)."""


@dataclass(frozen=True)
class TeacherPhase:
    """One teacher's head start: the PARE overrides of the PIRL variant it serves."""

    advisor: str
    pare: tuple[tuple[str, Any], ...]
    answers: int

    @property
    def name(self) -> str:
        """``teacher-<advisor>-<prompt variant>``, for logs and plans."""
        variant = dict(self.pare).get("prompt_variant", "")
        return f"teacher-{self.advisor}" + (f"-{variant}" if variant else "")


def needs_head_start(cfg: RunConfig, pare: dict[str, Any]) -> bool:
    """Whether a PIRL variant's teacher is an LLM (slower than the oracle) and the run learns
    from a student (the only mode whose shaping waits for teacher answers to pile up)."""
    merged = cfg.with_variant(pare).pare
    return merged.mode == PareMode.STUDENT and advisor_kind(merged.advisor).llm


def phase_of(cfg: RunConfig, pare: dict[str, Any]) -> TeacherPhase | None:
    """The head start a PIRL variant needs (``reproduce.teacher_phase_answers`` answers), or
    None. Variants that differ only in PARE's weights share one teacher, so one phase."""
    answers = cfg.reproduce.teacher_phase_answers
    if answers <= 0 or not needs_head_start(cfg, pare):
        return None
    merged = cfg.with_variant(pare).pare
    keep = {"advisor": merged.advisor, "prompt_variant": merged.prompt_variant}
    return TeacherPhase(merged.advisor, tuple(sorted(keep.items())), answers)


def run_teacher_phase(
    cfg: RunConfig,
    phase: TeacherPhase,
    log: Callable[[str], Any] = print,
    batch_size: int = 16,
) -> dict[str, Any]:
    """Ask the phase's teacher about planner states until the shared dataset holds
    ``phase.answers`` phase answers under the key the PIRL runs will use (a phase's answers
    already there, from an earlier reproduction, count; a run's own answers do not). Returns
    what it did.

    One phase at a time per dataset (a file lock beside it): two processes that both need
    the head start store one phase's answers, in one order, so the first ``phase.answers``
    rows every run copies are the same whoever asked first."""
    from filelock import FileLock

    lock = dataset_path(cfg).with_suffix(".phase.lock")
    lock.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(str(lock)):
        return _run_phase(cfg, phase, log, batch_size)


def _run_phase(
    cfg: RunConfig, phase: TeacherPhase, log: Callable[[str], Any], batch_size: int
) -> dict[str, Any]:
    from pirl.advice.student import encode
    from pirl.agents.distill import collect_states

    # The phase runs in a worker process of its own: no child process for the model.
    run_cfg = cfg.with_overrides(
        pare={
            **dict(phase.pare),
            "mode": PareMode.STUDENT,
            "student_dataset_scope": DatasetScope.SHARED,
        },
        advisor={"local_process": False},
    )
    started = time.perf_counter()
    advice = build_pirl_advice(run_cfg, probe=True, seed=SEED, log=log)
    advisor, student, dataset = advice.advisor, advice.student, advice.dataset
    assert student is not None and dataset is not None
    key = student.teacher
    have = dataset.count(key, SOURCE)
    asked = ok = 0
    try:
        if have < phase.answers:
            # A few more states than answers missing: an unparseable answer stores nothing.
            want = int((phase.answers - have) * 1.1) + 1
            prompts, views, feats = collect_states(run_cfg, advisor, [POLICY], want, SEED)
            for lo in range(0, len(prompts), batch_size):
                if have + ok >= phase.answers:
                    break
                hi = min(lo + batch_size, len(prompts))
                answers = advisor.advise(prompts[lo:hi], None if views is None else views[lo:hi])
                good = [i for i, a in enumerate(answers) if a.recommendation is not None]
                if good:
                    labels = encode([answers[i].recommendation for i in good])
                    dataset.add(key, feats[lo:hi][good], labels, SOURCE + phase.name)
                asked, ok = hi, ok + len(good)
    finally:
        advisor.close()
    seconds = time.perf_counter() - started
    return {
        "teacher": advisor.label,
        "key": key,
        "had": have,
        "asked": asked,
        "stored": ok,
        "seconds": round(seconds, 1),
    }


def take_head_start(
    cfg: RunConfig, advice: AdviceBundle, source: str, log: Callable[[str], Any] = print
) -> int:
    """Give a new run of ``pare.student_dataset_scope: run`` its head start: the first
    ``reproduce.teacher_phase_answers`` answers of its teacher's phase, copied under the run's
    own key before it trains (the phase is run here first when its answers are missing, as
    under ``pirl train`` alone). Returns the rows copied; 0 when the run needs no phase."""
    phase = phase_of(cfg, {})
    if phase is None or advice.student is None or advice.dataset is None:
        return 0
    dataset, base = advice.dataset, advice.student.teacher.split(RUN_KEY)[0]
    if dataset.count(base, SOURCE) < phase.answers:
        log(f"{phase.name}: the teacher answers planner states first (head start)")
        run_teacher_phase(cfg, phase, log)
    return dataset.copy_first(base, SOURCE, phase.answers, advice.student.teacher, source)


__all__ = [
    "POLICY",
    "SOURCE",
    "TeacherPhase",
    "needs_head_start",
    "phase_of",
    "run_teacher_phase",
    "take_head_start",
]
