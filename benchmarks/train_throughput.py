"""PPO training throughput and where the time goes.

Prints, in one run on the same machine:

1. PPO training steps/s on 15x15x3 with ``make_vec_env`` (batched numpy worlds) against SB3's
   ``DummyVecEnv`` and ``SubprocVecEnv`` over single ``VCPPEnv``s (same PPO settings);
2. PIRL (PARE with an advisor, student mode by default: a distilled advisor answers every
   step, the teacher is asked in the background; its dataset starts empty here) against
   PPO-EWRI, with the teacher calls per env-step, the staleness of shaped steps and the
   student's agreement;
3. where the time goes, per phase, as PufferLib's trainer prints it: env step (inside the
   VecEnv, advice excluded), policy forward (the rollout's ``policy(obs)`` calls), PPO update
   (``train()``), advisor (PARE waiting for answers) and the rest (rollout buffer, tensor
   copies, callbacks), in seconds and as a share of wall time;
4. PPO with valid-action masks (sb3-contrib's ``MaskablePPO``) against plain PPO on the same
   batched env: the line ``masked / unmasked training throughput``.

Usage: ``python benchmarks/train_throughput.py [--steps 16384] [--envs 16]
[--advisor local|oracle] [--mode student|async|sync]``.
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnvWrapper, VecMonitor

from pirl.advice.factory import make_advisor
from pirl.agents.methods import ADVISED
from pirl.agents.pirl_advice import build_pirl_advice
from pirl.agents.train import build_env_stack, build_ppo, resolved_config
from pirl.config.run import RunConfig
from pirl.env import VCPPEnv, make_vec_env


class StepTimer(VecEnvWrapper):
    """Measures time spent inside the wrapped env's step."""

    def __init__(self, venv):
        super().__init__(venv)
        self.seconds = 0.0

    def reset(self):
        return self.venv.reset()

    def step_async(self, actions):
        self._t = time.perf_counter()
        self.venv.step_async(actions)

    def step_wait(self):
        out = self.venv.step_wait()
        self.seconds += time.perf_counter() - self._t
        return out


def timed_learn(model: PPO, steps: int) -> dict[str, float]:
    """Train for ``steps``; returns wall time, the time inside PPO updates and the time in
    the policy's forward pass during rollouts (the update calls ``evaluate_actions``)."""
    spent = {"update": 0.0, "forward": 0.0}
    original_train, original_forward = model.train, model.policy.forward

    def train_timed() -> None:
        start = time.perf_counter()
        original_train()
        spent["update"] += time.perf_counter() - start

    def forward_timed(*args, **kwargs):
        start = time.perf_counter()
        out = original_forward(*args, **kwargs)
        spent["forward"] += time.perf_counter() - start
        return out

    model.train = train_timed
    model.policy.forward = forward_timed
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    return {"wall": time.perf_counter() - start, **spent}


def _ppo(env, cfg: RunConfig) -> PPO:
    model = build_ppo(env, cfg, seed=0, tb_dir=None)
    model.set_logger(Logger(None, []))  # SB3's default would make a folder in the temp dir
    return model


def run_case(name: str, env, cfg: RunConfig, steps: int, pare=None) -> dict[str, float]:
    # One reset and step outside the clock: worker processes start, kernels load from cache.
    env.reset()
    env.step(np.zeros(env.num_envs, dtype=np.int64))
    timer = StepTimer(env)
    model = _ppo(VecMonitor(timer), cfg)
    model.tensorboard_log = None
    t = timed_learn(model, steps)
    env_s = timer.seconds
    advice_s = pare.stats.wait_s if pare is not None else 0.0
    rollout_s = t["wall"] - t["update"]
    return {
        "name": name,
        "sps": steps / t["wall"],
        "env": env_s - advice_s,
        "forward": t["forward"],
        "update": t["update"],
        "advice": advice_s,
        "other": rollout_s - env_s - t["forward"],
        "wall": t["wall"],
    }


PHASES = ("env", "forward", "update", "advice", "other")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=16_384)
    parser.add_argument("--envs", type=int, default=16)
    parser.add_argument("--advisor", default="local", choices=("local", "oracle"))
    parser.add_argument("--mode", default="student", choices=("student", "async", "sync"))
    parser.add_argument("--config", default="configs/quick.yaml")
    parser.add_argument("--no-pirl", action="store_true", help="skip the PIRL case")
    args = parser.parse_args()
    torch.set_num_threads(1)
    dataset = tempfile.mkdtemp(prefix="pirl-bench-") + "/student.sqlite"
    cfg = RunConfig.from_yaml(args.config).with_overrides(
        ppo={"n_envs": args.envs},
        pare={"advisor": args.advisor, "mode": args.mode, "student_dataset": dataset},
    )
    env_cfg = cfg.env.replace(reward="ewri")
    # Warm-up (torch and SB3 first-call costs), not reported.
    run_case("warm-up", make_vec_env(args.envs, 0, env_cfg), cfg, cfg.ppo.n_steps * args.envs)
    rows = []
    rows.append(run_case("make_vec_env", make_vec_env(args.envs, 0, env_cfg), cfg, args.steps))
    rows.append(
        run_case(
            "DummyVecEnv",
            DummyVecEnv([lambda: VCPPEnv(env_cfg) for _ in range(args.envs)]),
            cfg,
            args.steps,
        )
    )
    rows.append(
        run_case(
            "SubprocVecEnv",
            SubprocVecEnv([lambda: VCPPEnv(env_cfg) for _ in range(args.envs)]),
            cfg,
            args.steps,
        )
    )
    masking = {}
    for masked in (False, True):
        case = cfg.with_overrides(ppo={"action_masking": masked})
        name = "MaskablePPO" if masked else "PPO, no masks"
        row = run_case(name, make_vec_env(args.envs, 0, env_cfg), case, args.steps)
        rows.append(row)
        masking[masked] = row["sps"]
    stats = None
    pirl_row = None
    if not args.no_pirl:
        # Cold cache: every prompt reaches the LLM, which runs in its own process as in training.
        advisor = make_advisor(args.advisor, cfg, cache=False, process=True)
        advice = build_pirl_advice(cfg, advisor, probe=False)
        stack = build_env_stack(resolved_config(ADVISED.name, cfg), seed=0, advice=advice)
        pirl_row = run_case(
            f"PIRL ({args.advisor}, {args.mode})", stack.pare, cfg, args.steps, stack.pare
        )
        rows.append(pirl_row)
        stats = stack.pare.stats.as_dict()
        stack.pare.close()

    base = rows[0]["sps"]
    print(f"PPO training on 15x15x3, {args.envs} envs, {args.steps:,} steps per case")
    print(f"{'case':<24} {'steps/s':>9} {'x vec':>7} " + " ".join(f"{p:>14}" for p in PHASES))
    for r in rows:
        cells = [f"{r[p]:6.1f}s {r[p] / r['wall']:>5.0%}" for p in PHASES]
        print(f"{r['name']:<24} {r['sps']:>9,.0f} {r['sps'] / base:>7.2f} " + " ".join(cells))
    print(f"make_vec_env / DummyVecEnv: {base / rows[1]['sps']:.1f}x")
    print(f"masked / unmasked training throughput: {masking[True] / masking[False]:.2f}x")
    if stats is None or pirl_row is None:
        return
    print(f"PIRL / PPO-EWRI (make_vec_env): {pirl_row['sps'] / base:.0%}")
    print(f"PIRL label: {stats['label']}")
    print(
        "PIRL advice: "
        f"teacher calls {stats['teacher_calls']} ({stats['teacher_calls_per_step']:.4f} per "
        f"env-step), steps shaped by the student {stats['steps_student']}, by the teacher "
        f"{stats['steps_teacher']} (fresh {stats['steps_fresh']}, stale {stats['steps_stale']}),"
        f" unshaped {stats['steps_unshaped']}, mean staleness {stats['mean_staleness']:.1f}"
    )
    if args.mode == "student":
        print(
            f"student: agreement {stats['student_agreement']:.3f} (majority "
            f"{stats['student_majority']:.3f}) on {stats['student_heldout']} held-out answers, "
            f"dataset {stats['student_dataset_size']}, gate passed at step "
            f"{stats['gate_passed_at_step']}"
        )


if __name__ == "__main__":
    main()
