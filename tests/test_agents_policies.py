"""Policies behind one interface: IL (TabNet), LLM-only, loading by name or run folder."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pirl.advice.base import Advisor, Answer
from pirl.advice.oracle import OracleAdvisor
from pirl.advice.recommendation import Recommendation
from pirl.agents.imitation import train_il
from pirl.agents.llm_only import LLMOnlyPolicy, action_queue
from pirl.agents.loading import PPOPolicy, TabNetPolicy, load_policy
from pirl.agents.policy import hold_action
from pirl.agents.train import train
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig
from pirl.env import VCPPEnv
from pirl.evaluate import run_episode

ROOT = Path(__file__).resolve().parents[1]


class Mute(Advisor):
    """An advisor whose answers never parse."""

    name, model, label = "mute", "none", "mute"

    def settings_key(self) -> str:
        return "-"

    def advise(self, prompts, views=None):
        return [Answer("no idea", None) for _ in prompts]


def test_action_queue_camera_first_then_move():
    rec = Recommendation(pan=30, tilt=70, zoom=1.2, dx=1, dy=-1, dz=0)
    # From tilt 90, pan 0, zoom 1.0: 4 x tilt-5, 2 x pan+15, 2 x zoom+0.1, then x+, y-.
    assert action_queue((90, 0, 10), rec) == [7, 7, 7, 7, 8, 8, 10, 10, 0, 3]
    # Values between grid steps snap to the nearest step.
    assert action_queue((90, 0, 10), Recommendation(0, 86.0, 1.04, 0, 0, 1)) == [7, 4]
    assert action_queue((90, 0, 10), Recommendation(0, 90, 1.0, 0, 0, 0)) == []


def test_hold_action_changes_nothing_when_it_can():
    env = VCPPEnv(size=(10, 10, 3), wind_prob=0.0)
    env.reset(seed=0)
    _, _, _, _, info = env.step(hold_action((90, 0, 10)))
    assert info["idle"] and info["camera"] == (90, 0, 1.0)


def test_llm_only_with_oracle_covers_and_respects_its_call_limit():
    env = VCPPEnv(size=(20, 20, 3))
    policy = LLMOnlyPolicy(OracleAdvisor())
    assert "oracle" in policy.label
    full = run_episode(env, policy, seed=3).metrics
    assert full["vcr"] > 0.8
    limited = LLMOnlyPolicy(OracleAdvisor(), max_calls=5)
    short = run_episode(env, limited, seed=3).metrics
    assert limited.stats()["calls"] == 5
    assert short["vcr"] < full["vcr"]


def test_llm_only_holds_when_answers_do_not_parse():
    env = VCPPEnv(size=(10, 10, 3), wind_prob=0.0, max_steps=20, scale_by_alpha=False)
    policy = LLMOnlyPolicy(Mute())
    metrics = run_episode(env, policy, seed=1).metrics
    assert policy.stats()["failed"] == 20
    assert metrics["collisions"] == 0 and metrics["camera_share"] == 1.0


def test_ppo_and_il_runs_load_as_policies(tmp_path):
    cfg = RunConfig.from_yaml(ROOT / "configs" / "test.yaml")
    expert = tmp_path / "ewri"
    train("ppo-ewri", cfg, expert, seed=0, show_progress=False)
    il_model = train_il(cfg, expert, tmp_path / "il", seed=0)
    stats = json.loads((tmp_path / "il" / "il_stats.json").read_text())
    assert 0.0 <= stats["valid_accuracy"] <= 1.0
    assert stats["train_rows"] + stats["valid_rows"] <= cfg.il.expert_steps
    assert il_model.is_file()
    env = VCPPEnv(cfg.env)  # the observation layout the runs trained with
    ppo, il = load_policy(expert), load_policy(tmp_path / "il")
    assert isinstance(ppo, PPOPolicy) and ppo.label == "PPO-EWRI"
    assert isinstance(il, TabNetPolicy)
    # Its probabilities are TabNet's own predict_proba, exactly, over several batches.
    obs = np.random.default_rng(0).random((7, il.obs_size), dtype=np.float32)
    il.model.batch_size = 3
    own = il.model.predict_proba(obs)
    assert np.array_equal(il.probabilities(obs)[:, own_columns(il)], own)
    # PPO's are sb3-contrib's distribution's, exactly, taken without building it.
    import torch

    assert ppo.masked
    obs = np.random.default_rng(1).random((5, ppo.obs_size), dtype=np.float32)
    with torch.no_grad():
        dist = ppo.model.policy.get_distribution(torch.as_tensor(obs)).distribution
    assert np.array_equal(ppo.probabilities(obs), dist.probs.numpy())
    for policy in (ppo, il, load_policy("boustrophedon"), load_policy("random", seed=1)):
        metrics = run_episode(env, policy, seed=11).metrics
        assert 0.0 <= metrics["vcr"] <= 1.0
    other = VCPPEnv(cfg.env.replace(obs_visits=False, obs_target=False))
    with pytest.raises(ConfigError, match="observations of 441 values; this environment gives 317"):
        run_episode(other, ppo, seed=11)
    with pytest.raises(ConfigError, match="not a finished PPO run|not a run folder"):
        train_il(cfg, tmp_path / "il", tmp_path / "il2")
    with pytest.raises(ConfigError, match="neither a run folder nor a method"):
        load_policy("ppo-magic")
    with pytest.raises(ConfigError, match="needs an advisor"):
        load_policy("llm-only")


def own_columns(policy: TabNetPolicy) -> list[int]:
    """The actions behind the columns of TabNet's own predict_proba."""
    n = len(policy.model.preds_mapper)
    return [int(policy.model.preds_mapper[str(k)]) for k in range(n)]


def test_distribution_checks_off_change_no_number():
    """pirl._torch.configure() turns off torch.distributions' argument checks for speed: a
    masked action distribution gives the same probabilities, log-probabilities, entropy and
    samples with the checks on and off, and NaN logits still stop sampling."""
    import torch
    from sb3_contrib.common.maskable.distributions import MaskableCategorical
    from torch.distributions import Distribution

    from pirl._torch import configure

    logits = torch.randn(16, 30, generator=torch.Generator().manual_seed(0))
    masks = torch.rand(16, 30, generator=torch.Generator().manual_seed(1)) > 0.3
    masks[:, 0] = True

    def figures():
        dist = MaskableCategorical(logits=logits)
        dist.apply_masking(masks)
        torch.manual_seed(2)
        sample = dist.sample()
        return dist.probs, dist.log_prob(sample), dist.entropy(), sample

    default = Distribution._validate_args
    try:
        Distribution.set_default_validate_args(True)
        checked = figures()
        configure.cache_clear()
        configure()
        assert not Distribution._validate_args
        for a, b in zip(checked, figures(), strict=True):
            assert torch.equal(a, b)
        with pytest.raises(RuntimeError, match="nan"):
            MaskableCategorical(logits=torch.full((1, 3), float("nan"))).sample()
    finally:
        Distribution.set_default_validate_args(default)


_ADAM_RUN = """
import hashlib, sys, torch
if sys.argv[1] == "configured":
    from pirl._torch import configure
    configure()
torch.manual_seed(0)
net = torch.nn.Sequential(torch.nn.Linear(10, 64), torch.nn.Tanh(), torch.nn.Linear(64, 3))
opt = torch.optim.Adam(net.parameters(), lr=3e-4, eps=1e-5)
for _ in range(40):
    loss = net(torch.randn(32, 10)).pow(2).mean()
    opt.zero_grad()
    loss.backward()
    torch.nn.utils.clip_grad_norm_(net.parameters(), 0.5)
    opt.step()
opt.load_state_dict(opt.state_dict())
opt.step()  # the restored moments are used
digest = hashlib.sha256(b"".join(p.detach().numpy().tobytes() for p in net.parameters()))
print(digest.hexdigest(), "torch._dynamo" in sys.modules, torch.is_grad_enabled())
"""


def test_optimizer_without_compile_hooks_gives_the_same_weights():
    """pirl._torch.configure() rebinds Adam's and Optimizer's torch.compile wrappers to the
    functions they wrap: the same weights to the bit, and torch._dynamo is never imported
    (each process starts fresh, since which modules a process imported is what is tested)."""
    runs = {}
    for how in ("stock", "configured"):
        out = subprocess.run(
            [sys.executable, "-c", _ADAM_RUN, how], capture_output=True, text=True, check=True
        )
        runs[how] = out.stdout.split()
    assert runs["configured"][0] == runs["stock"][0]
    assert runs["stock"][1:] == ["True", "True"]  # stock Adam imports torch._dynamo
    assert runs["configured"][1:] == ["False", "True"]
