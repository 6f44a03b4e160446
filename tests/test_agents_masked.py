"""Training and acting with valid-action masks (ppo.action_masking): MaskablePPO through PARE,
exact resume, evaluation that gives each policy the masks its run trained with, IL's expert."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from sb3_contrib import MaskablePPO

from pirl.agents.imitation import collect_expert, load_expert
from pirl.agents.loading import load_policy, mask_probabilities
from pirl.agents.run_folder import RunFolder
from pirl.agents.train import train
from pirl.config.run import RunConfig
from pirl.env.vcpp_env import VCPPEnv
from pirl.evaluate.rollout import run_batch, run_episode

ROOT = Path(__file__).resolve().parents[1]
TEST_CFG = ROOT / "configs" / "test.yaml"


def masked_cfg(tmp_path: Path, name: str, steps: int) -> RunConfig:
    return RunConfig.from_yaml(TEST_CFG).with_overrides(
        ppo={"action_masking": True},
        pare={
            "advisor": "oracle", "mode": "student", "oracle_teacher_rate": 0.25,
            "student_gate": 0.0, "student_wait_teacher": True, "student_fit_steps": 20,
            "student_dataset": str(tmp_path / f"{name}.sqlite"),
        },
        train={"total_steps": steps, "checkpoint_every": 128},
    )  # fmt: skip


def _weights(path: Path) -> dict:
    return MaskablePPO.load(path, device="cpu").policy.state_dict()


def test_masked_pirl_trains_resumes_exactly_and_records_masking(tmp_path):
    straight = train(
        "pirl", masked_cfg(tmp_path, "a", 1024), tmp_path / "a", seed=2, show_progress=False
    )
    first = tmp_path / "b"
    train("pirl", masked_cfg(tmp_path, "b", 512), first, seed=2, show_progress=False)
    resumed = train(
        "pirl", masked_cfg(tmp_path, "b", 1024), first, seed=2, resume=True, show_progress=False
    )
    a, b = _weights(straight), _weights(resumed)
    assert all(torch.equal(a[k], b[k]) for k in a)
    sa = json.loads((tmp_path / "a" / "advisor_stats.json").read_text())
    sb = json.loads((first / "advisor_stats.json").read_text())
    for key in ("steps", "steps_student", "teacher_calls"):
        assert sa[key] == sb[key], key
    assert RunFolder(first).masked and (first / "tb").is_dir()
    assert (tmp_path / "a" / "episodes.csv").read_text() == (first / "episodes.csv").read_text()


@pytest.fixture(scope="module")
def masked_ewri(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("masked") / "ppo-ewri"
    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(ppo={"action_masking": True})
    train("ppo-ewri", cfg, out, seed=0, show_progress=False)
    return out


@pytest.mark.parametrize("act", ["greedy", "stochastic"])
def test_masked_policy_never_chooses_an_invalid_action(masked_ewri, act):
    policy = load_policy(masked_ewri, act=act)
    assert policy.masked and isinstance(policy.model, MaskablePPO)
    cfg = RunConfig.from_yaml(TEST_CFG).env.replace(size=(12, 12, 3), max_steps=60)
    env = VCPPEnv(cfg)
    for seed in (1, 2):
        obs, info = env.reset(seed=seed)
        policy.reset(env.world, 0, seed=seed)
        done = False
        while not done:
            a = policy.act(obs, info)
            assert info["action_mask"][a], (seed, a)
            obs, _, terminated, truncated, info = env.step(a)
            done = terminated or truncated
    # the batched runner gives the same masks, so the same episodes
    batched = run_batch(cfg, load_policy(masked_ewri, act=act), [1, 2])
    single = [run_episode(env, load_policy(masked_ewri, act=act), s).metrics for s in (1, 2)]
    assert batched == single


def test_il_expert_data_respects_the_mask(masked_ewri):
    from pirl.agents.run_folder import train_seed_base
    from pirl.env.sb3_vec import make_vec_env

    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(ppo={"action_masking": True})
    model = load_expert(masked_ewri)
    assert isinstance(model, MaskablePPO)
    n = cfg.ppo.n_envs
    x, y = collect_expert(model, cfg, 50 * n, seed=0)
    # replay the same worlds with the expert's actions: each was valid where it was taken
    venv = make_vec_env(n, seed=train_seed_base(0) + 500, config=cfg.env.replace(reward="ewri"))
    obs = venv.reset()
    for t in range(50):
        rows = slice(t * n, (t + 1) * n)
        assert np.array_equal(obs, x[rows])
        assert venv.action_masks()[np.arange(n), y[rows]].all(), t
        obs, _, _, _ = venv.step(y[rows])


def test_mask_probabilities_renormalises_and_never_picks_a_masked_action():
    probs = np.array([[0.5, 0.5, 0.0], [0.9, 0.1, 0.0], [1.0, 0.0, 0.0]])
    masks = np.array([[True, False, True], [False, True, True], [False, False, True]])
    out = mask_probabilities(probs, masks)
    assert np.allclose(out.sum(axis=1), 1.0)
    assert np.allclose(out[0], [1.0, 0.0, 0.0])
    assert np.allclose(out[1], [0.0, 1.0, 0.0])
    assert np.allclose(out[2], [0.0, 0.0, 1.0])  # valid actions all at 0: uniform over them
    assert not (out[~masks] > 0).any()
