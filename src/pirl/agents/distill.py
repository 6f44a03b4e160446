"""``pirl distill``: make a student of a teacher advisor offline, before any PPO run.

States come from rollouts of simple or trained policies on the training world (a planner,
random actions, a finished run); the teacher answers each sampled state; answers go into the
shared teacher dataset; the student is fitted on every answer that dataset holds for this
teacher and written to ``out/student.npz`` with ``out/student.json`` (its teacher, agreement,
the majority baseline and how it was made). ``pirl train --method pirl --student out`` starts
from it.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pirl.advice.student import STUDENT_FILE
from pirl.agents.loading import load_policy
from pirl.agents.methods import ADVISED, BUILTIN, PLAYED_ALONE
from pirl.agents.pirl_advice import build_pirl_advice, dataset_path
from pirl.agents.run_folder import RunFolder, folder_contents, lock_folder, release_folder
from pirl.config.choices import PareMode
from pirl.config.errors import ConfigError, UserError
from pirl.config.load import check_seed
from pirl.config.run import RunConfig

Progress = Callable[[int, int], None]


def collect_states(
    cfg: RunConfig,
    advisor: Any,
    policies: Sequence[str],
    states: int,
    seed: int = 0,
    keep: float = 0.25,
) -> tuple[list[str], list[Any] | None, np.ndarray]:
    """Prompts, views (when the advisor wants them) and student features of ``states`` states.

    Episodes alternate between ``policies``; each step is kept with probability ``keep`` so
    that the states spread over whole episodes. Scenario seeds start at ``2_000_000 + seed``
    (apart from training's and evaluation's).
    """
    from pirl.advice.state import advice_requests
    from pirl.advice.student import student_features
    from pirl.env.vcpp_env import VCPPEnv

    env = VCPPEnv(ADVISED.trains_on(cfg.env))
    rng = np.random.default_rng(seed)
    loaded = [load_policy(p, seed=seed) for p in policies]
    prompts: list[str] = []
    views: list[Any] = []
    feats: list[np.ndarray] = []
    episode = 0
    while len(prompts) < states:
        scenario = 2_000_000 + seed * 100_000 + episode
        policy = loaded[episode % len(loaded)]
        obs, info = env.reset(seed=scenario)
        policy.reset(env.world, 0, seed=scenario)
        done = False
        while not done and len(prompts) < states:
            if rng.random() < keep:
                p, v = advice_requests(env.world, [0], advisor, cfg.pare.prompt_variant)
                prompts += p
                if v is not None:
                    views += v
                feats.append(student_features(obs[None], env.world, [0])[0])
            obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
            done = terminated or truncated
        episode += 1
    return prompts, (views or None), np.stack(feats)


def distill(
    cfg: RunConfig,
    teacher: str,
    states: int,
    out: Path,
    policies: Sequence[str] = PLAYED_ALONE,
    seed: int = 0,
    fit_steps: int = 2000,
    batch_size: int = 32,
    progress: Progress | None = None,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Ask ``teacher`` about ``states`` states, fit a student, write it to ``out``.

    Returns the student's record (also written as ``out/student.json``).
    """
    from pirl.advice.student import encode

    out = Path(out)
    if out.exists():
        raise ConfigError(f"student folder {out} already exists; choose another --out")
    if states < 1:
        raise ConfigError(f"--states {states}: must be >= 1")
    if fit_steps < 1:
        raise ConfigError(f"--fit-steps {fit_steps}: must be >= 1 (an unfitted student is noise)")
    check_seed(seed)
    for source in policies:  # before the folder: a wrong --policy leaves nothing behind
        if source not in BUILTIN:
            if Path(source).exists():
                RunFolder(Path(source)).finished_meta()
            else:
                load_policy(source)
    cfg = cfg.with_overrides(pare={"advisor": teacher, "mode": PareMode.STUDENT})
    advice = build_pirl_advice(cfg, probe=True, seed=seed)
    advisor, student, dataset = advice.advisor, advice.student, advice.dataset
    assert student is not None and dataset is not None
    # One writer per student folder: the work happens in out.tmp, locked (a second distill
    # into the same --out is refused with the holder's PID), and is renamed into place.
    tmp = out.with_name(out.name + ".tmp")
    try:
        tmp.mkdir(parents=True, exist_ok=True)
        lock_folder(tmp, "student folder")
    except BaseException:
        advisor.close()
        raise
    for stale in folder_contents(tmp):  # a copy left by a killed earlier attempt
        if stale.is_dir():
            shutil.rmtree(stale)
        else:
            stale.unlink()
    started = time.perf_counter()
    ok_to_keep = False
    try:
        prompts, views, feats = collect_states(cfg, advisor, policies, states, seed)
        asked = ok = 0
        for lo in range(0, len(prompts), batch_size):
            hi = min(lo + batch_size, len(prompts))
            answers = advisor.advise(prompts[lo:hi], None if views is None else views[lo:hi])
            good = [i for i, a in enumerate(answers) if a.recommendation is not None]
            if good:
                labels = encode([answers[i].recommendation for i in good])
                dataset.add(student.teacher, feats[lo:hi][good], labels, f"distill:{out}")
            asked, ok = hi, ok + len(good)
            if progress is not None:
                progress(asked, len(prompts))
            if asked >= 50 and ok / asked < 0.5:
                raise UserError(
                    f"teacher {advisor.label}: only {ok} of {asked} answers parsed; "
                    "check the model and the prompt variant (pirl advise shows one answer)"
                )
        student.pull(dataset)
        score = student.fit(fit_steps)
        ok_to_keep = True
    finally:
        advisor.close()
        if not ok_to_keep:  # a failed distill leaves no half-made student folder
            release_folder(tmp)
            shutil.rmtree(tmp, ignore_errors=True)
    record = {
        "label": f"student of {advisor.label}",
        "teacher": student.teacher,
        "teacher_label": advisor.label,
        "states_asked": len(prompts),
        "answers_ok": ok,
        "policies": list(policies),
        "seed": seed,
        "dataset": str(dataset_path(cfg)),
        "dataset_size": student.dataset_size,
        "agreement": score.agreement,
        "majority": score.majority,
        "heldout": score.heldout,
        "per_field": score.per_field,
        "fit_steps": fit_steps,
        "prompt_variant": cfg.pare.prompt_variant,
        "seconds": round(time.perf_counter() - started, 1),
    }
    student.save(tmp / STUDENT_FILE)
    (tmp / "student.json").write_text(json.dumps(record, indent=2))
    os.replace(tmp, out)
    release_folder(tmp)
    return record


__all__ = ["collect_states", "distill"]
