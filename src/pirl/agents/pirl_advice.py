"""What PIRL's reward shaping needs before a run starts: the teacher advisor (probed), the
student and its dataset in student mode, and the label that says what ran.

Everything here happens before a run folder exists, so a wrong key, a dead server or a
student of another teacher stops with one line and leaves nothing behind.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pirl.advice.registry import find_advisor_kind
from pirl.agents.methods import ADVISED
from pirl.config.choices import DatasetScope, PareMode
from pirl.config.errors import UserError
from pirl.config.run import PareSettings, RunConfig
from pirl.pare.bundle import AdviceBundle

RUN_KEY = ":run:"
"""Joins a teacher's dataset key and a run's own suffix (``pare.student_dataset_scope: run``)."""


def _num(value: float) -> str:
    return f"{value:g}"


def pirl_label(cfg: RunConfig, advisor_label: str) -> str:
    """The label of a PIRL configuration: advisor and model, mode, K, lam_cam and lam_move."""
    p = cfg.pare
    weights = f"lam_cam {_num(p.lam_cam)}, lam_move {_num(p.lam_move)}"
    if p.mode == PareMode.STUDENT:
        return f"PIRL (student of {advisor_label}; {weights})"
    return f"PIRL ({p.mode} {advisor_label}, K {p.query_every}; {weights})"


def dataset_path(cfg: RunConfig) -> Path:
    """Where the teacher answers live (``pare.student_dataset`` or beside the answer cache)."""
    from pirl.advice.teacher_dataset import default_dataset_path

    return (
        Path(cfg.pare.student_dataset).expanduser()
        if cfg.pare.student_dataset
        else (default_dataset_path())
    )


def build_pirl_advice(
    cfg: RunConfig,
    advisor: Any | None = None,
    student_path: Path | None = None,
    probe: bool = True,
    seed: int = 0,
    log: Callable[[str], Any] = print,
    run: str = "",
) -> AdviceBundle:
    """Build (and probe) the teacher, and in student mode the student and its dataset.

    ``run``: the run folder, which keys the run's own answers under
    ``pare.student_dataset_scope: run`` (a run started from ``student_path`` learns under the
    teacher's key its student was distilled under).

    ``student_path``: a student written by ``pirl distill`` to start from; its teacher must be
    the configured one. A probe answer that does not parse is a warning (``log``), not an
    error: training counts such answers, and a server may answer better later.
    """
    from pirl.advice.factory import make_advisor
    from pirl.advice.health import probe as probe_call

    env_cfg = ADVISED.trains_on(cfg.env)
    if advisor is None:
        advisor = make_advisor(cfg.pare.advisor, cfg, process=cfg.advisor.local_process)
    if probe:
        try:
            answer = probe_call(
                advisor, env_cfg, cfg.pare.prompt_variant, cfg.advisor.probe_timeout_s, print
            )  # "probing ..." goes to stdout: stderr is kept for warnings and the error line
        except UserError:
            advisor.close()
            raise
        if answer.recommendation is None:
            log(probe_warning(advisor.label, answer.text, cfg.pare.prompt_variant))
    label = pirl_label(cfg, advisor.label)
    kind = find_advisor_kind(advisor.name)  # an advisor handed in may be of no kind
    rate = kind.teacher_rate(cfg) if kind else cfg.pare.teacher_rate
    batch = kind.batch_size(cfg) if kind else 4 * cfg.advisor.openai_concurrency
    if cfg.pare.mode != PareMode.STUDENT:
        return AdviceBundle(advisor, None, None, rate, batch, label)
    student, dataset = make_student(cfg, advisor, env_cfg, student_path, seed, run)
    return AdviceBundle(advisor, student, dataset, rate, batch, label)


def probe_warning(label: str, text: str, prompt_variant: str) -> str:
    """One line for a probe answer that does not parse, naming the next step."""
    shown = " ".join(text.split())[:60] or "(empty)"
    return (
        f"warning: advisor {label}'s probe answer does not parse ({shown!r}); its answers "
        f"will not shape PIRL until they do: check it with pirl advise --advisor ... "
        f"(prompt variant {prompt_variant})"
    )


def shaped_share(stats: dict[str, Any]) -> float:
    """Share of a PIRL run's steps shaped by advice (student or teacher), from its
    ``advisor_stats.json``."""
    from pirl.pare.stats import RunStats

    return RunStats.of(stats).shaped_share


def unshaped_warning(
    stats: dict[str, Any],
    min_shaped: float,
    gate: float,
    min_heldout: int = PareSettings.student_min_heldout,
) -> str | None:
    """One line when a PIRL run was less than ``min_shaped`` shaped, saying why; else None.

    The reasons come from the run's counters: teacher answers received, unparseable, failed,
    still in flight at the end, and whether (and when) the student passed its gate.
    """
    shaped = shaped_share(stats)
    if shaped >= min_shaped:
        return None
    ok, bad = int(stats.get("answers_ok", 0)), int(stats.get("answers_unparseable", 0))
    failed, flight = int(stats.get("answers_failed", 0)), int(stats.get("answers_in_flight", 0))
    sent = int(stats.get("prompts_sent", stats.get("teacher_calls", 0)))
    why = [
        f"teacher sent {sent:,} prompts, answered {ok:,}, unparseable {bad:,}, failed "
        f"{failed:,}, in flight at the end {flight:,}"
    ]
    if stats.get("mode") == PareMode.STUDENT:
        passed = int(stats.get("gate_passed_at_step", -1))
        if passed < 0:
            kappa = float(stats.get("student_kappa", 0.0))
            informative = stats.get("student_informative") or []
            signal = (
                f"kappa {kappa:.2f} over {', '.join(informative)}"
                if informative
                else "the teacher's answers carry no state information (no field varies)"
            )
            why.append(
                f"student gate never passed (agreement {stats.get('student_agreement', 0):.2f}, "
                f"{signal}; gate {gate:g} on {int(stats.get('student_heldout', 0))} held-out "
                f"answers; it needs {min_heldout})"
            )
        else:
            why.append(f"student gate passed at step {passed:,} of {int(stats['steps']):,}")
    if bad and not ok:
        why.append("no answer parsed: check the advisor with pirl advise")
    if stats.get("budget_exhausted"):
        why.append(f"budget spent at step {int(stats.get('budget_exhausted_at_step', -1)):,}")
    return (
        f"warning: {stats.get('label', 'PIRL')} was {1 - shaped:.0%} unshaped (less than "
        f"pare.min_shaped {min_shaped:g} shaped), so it trained mostly as PPO-EWRI: "
        + "; ".join(why)
    )


def make_student(
    cfg: RunConfig,
    advisor: Any,
    env_cfg: Any,
    student_path: Path | None,
    seed: int = 0,
    run: str = "",
) -> tuple[Any, Any]:
    """A new student of ``advisor`` (or the one saved at ``student_path``) and its dataset."""
    from pirl.advice.student import (
        N_EXTRA,
        STUDENT_FILE,
        Student,
        TeacherDataset,
        teacher_key,
    )
    from pirl.env.observation import obs_size_for

    dataset = TeacherDataset(dataset_path(cfg))
    key = teacher_key(advisor, cfg.pare.prompt_variant, env_cfg)
    # A run's own key (scope run); outside a run (distill, a teacher phase) and for a run that
    # starts from a distilled student, the teacher's key, which that student was made under.
    if cfg.pare.student_dataset_scope == DatasetScope.RUN and run and student_path is None:
        key += RUN_KEY + hashlib.sha256(run.encode()).hexdigest()[:12]
    if student_path is not None:
        path = Path(student_path)
        file = path / STUDENT_FILE if path.is_dir() else path
        if not file.is_file():
            raise UserError(f"--student {path}: no {STUDENT_FILE} (make one with pirl distill)")
        try:
            student = Student.load(file, dataset)
        except UserError:
            raise
        except (ValueError, OSError, RuntimeError, KeyError) as exc:
            raise UserError(f"--student {file} cannot be loaded: {exc}") from None
        student.min_heldout = cfg.pare.student_min_heldout  # a setting of this run, not the file's
        if student.teacher != key:
            raise UserError(
                f"--student {path} imitates {student.teacher}, but this run's teacher is {key} "
                "(advisor, model, prompt variant and world settings must match)"
            )
        return student, dataset
    n_features = obs_size_for(env_cfg) + N_EXTRA
    student = Student(
        key,
        n_features,
        label=advisor.label,
        hidden=cfg.pare.student_hidden,
        seed=seed,
        min_heldout=cfg.pare.student_min_heldout,
    )
    return student, dataset


__all__ = [
    "build_pirl_advice",
    "dataset_path",
    "make_student",
    "pirl_label",
    "probe_warning",
    "shaped_share",
    "unshaped_warning",
]
