"""Training runs: run folders, checkpoints, Ctrl-C and exact resume, config errors."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from pirl.agents.loading import load_model
from pirl.agents.train import train
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig

ROOT = Path(__file__).resolve().parents[1]
TEST_CFG = ROOT / "configs" / "test.yaml"


def _same_weights(a: Path, b: Path) -> bool:
    sa = load_model(a, device="cpu").policy.state_dict()
    sb = load_model(b, device="cpu").policy.state_dict()
    return all(torch.equal(sa[k], sb[k]) for k in sa)


def test_run_folder_contents_and_no_overwrite(tmp_path):
    cfg = RunConfig.from_yaml(TEST_CFG)
    out = tmp_path / "run"
    train("ppo-sr", cfg, out, seed=1, show_progress=False)
    for name in ("model.zip", "config.yaml", "meta.json", "episodes.csv", "tb", "checkpoints"):
        assert (out / name).exists(), name
    meta = json.loads((out / "meta.json").read_text())
    assert meta["complete"] and meta["method"] == "ppo-sr" and meta["timesteps"] == 512
    assert meta["git_commit"] != ""
    assert RunConfig.from_yaml(out / "config.yaml") == cfg
    with pytest.raises(ConfigError, match="already exists"):
        train("ppo-sr", cfg, out, seed=1, show_progress=False)


def test_same_seed_same_model(tmp_path):
    cfg = RunConfig.from_yaml(TEST_CFG)
    a = train("ppo-ewri", cfg, tmp_path / "a", seed=3, show_progress=False)
    b = train("ppo-ewri", cfg, tmp_path / "b", seed=3, show_progress=False)
    c = train("ppo-ewri", cfg, tmp_path / "c", seed=4, show_progress=False)
    assert _same_weights(a, b)
    assert not _same_weights(a, c)


def _stopped(pid: int) -> bool:
    # /proc/PID/stat: "pid (comm) state ..."; T = stopped by a signal.
    stat = Path(f"/proc/{pid}/stat").read_text()
    return stat[stat.rindex(")") + 2] in "TtZ"


def _interrupt_at(proc: subprocess.Popen, latest: Path, step: int, limit: float = 240) -> None:
    """Let ``proc`` run in 20 ms slices and look at its checkpoint only while it is stopped
    (SIGSTOP), then Ctrl-C it in the first pause after the checkpoint reaches ``step``: the
    run cannot finish between the look and the signal, however fast the machine."""
    deadline = time.time() + limit
    while time.time() < deadline and proc.poll() is None:
        proc.send_signal(signal.SIGSTOP)
        while not _stopped(proc.pid):
            time.sleep(0.001)
        if latest.exists() and int(latest.read_text().split("_")[1]) >= step:
            proc.send_signal(signal.SIGINT)
            proc.send_signal(signal.SIGCONT)
            return
        proc.send_signal(signal.SIGCONT)
        time.sleep(0.02)
    proc.send_signal(signal.SIGCONT)


def test_ctrl_c_then_resume_matches_an_uninterrupted_run(tmp_path):
    steps = "2048"  # 16 rollouts; the Ctrl-C lands after the 8th whatever the machine's pace
    cmd = [
        sys.executable, "-m", "pirl", "train", "--method", "ppo-ewri", "--config",
        str(TEST_CFG), "--seed", "2", "--steps", steps,
    ]  # fmt: skip
    out = tmp_path / "interrupted"
    # A shell that starts the suite in the background ignores SIGINT, and children inherit
    # that; a user's terminal does not: give the child the terminal's default.
    proc = subprocess.Popen(
        [*cmd, "--out", str(out)],
        stdout=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    latest = out / "checkpoints" / "LATEST"
    _interrupt_at(proc, latest, 1024)
    proc.communicate(timeout=120)
    assert proc.returncode == 130, "Ctrl-C must stop the run and report the checkpoint"
    assert not (out / "model.zip").exists()
    stopped_at = int(latest.read_text().split("_")[1])
    assert 1024 <= stopped_at < int(steps)

    resumed = subprocess.run([*cmd, "--out", str(out), "--resume"], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    straight = tmp_path / "straight"
    subprocess.run([*cmd, "--out", str(straight)], check=True, capture_output=True)
    assert _same_weights(out / "model.zip", straight / "model.zip")
    rows = (out / "episodes.csv").read_text().splitlines()
    assert rows == (straight / "episodes.csv").read_text().splitlines()


def test_config_errors_name_the_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("ppo:\n  n_env: 4\n")
    with pytest.raises(ConfigError, match="unknown setting 'n_env' in section 'ppo'"):
        RunConfig.from_yaml(bad)
    with pytest.raises(ConfigError, match="ppo.n_envs=0"):
        RunConfig.from_dict({"ppo": {"n_envs": 0}})
    with pytest.raises(ConfigError, match="pare.mode='later'"):
        RunConfig.from_dict({"pare": {"mode": "later"}})
    with pytest.raises(ConfigError, match="does not exist"):
        train("ppo-sr", RunConfig(), tmp_path / "missing", resume=True, show_progress=False)
    with pytest.raises(ConfigError, match="PPO methods"):
        train("ppo", RunConfig(), tmp_path / "x", show_progress=False)
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("preset", sorted((ROOT / "configs").glob("*.yaml")), ids=lambda p: p.name)
def test_every_preset_loads(preset):
    cfg = RunConfig.from_yaml(preset)
    assert cfg.env.size == (15, 15, 3)  # every profile trains on the paper's world
    assert cfg.pare.advisor in ("local", "openai", "oracle")


def test_a_checkpoint_from_before_the_named_world_state_is_refused_in_one_line(tmp_path):
    from pirl.agents import checkpoint
    from pirl.config import safe_state

    step = tmp_path / "step_64"
    step.mkdir()
    (step / "model.zip").write_bytes(b"")
    safe_state.save(
        {"num_timesteps": 64, "world": {}, "weights": None, "rngs": []}, step / "state.npz"
    )
    (tmp_path / "LATEST").write_text("step_64")
    with pytest.raises(ConfigError, match="older pirl"):
        checkpoint.load_latest(tmp_path)


def test_a_pickled_checkpoint_is_refused_unread(tmp_path):
    import pickle

    from pirl.agents import checkpoint

    step = tmp_path / "step_64"
    step.mkdir()
    (step / "model.zip").write_bytes(b"")
    (step / "state.pkl").write_bytes(pickle.dumps({"num_timesteps": 64}))
    (tmp_path / "LATEST").write_text("step_64")
    with pytest.raises(ConfigError, match="state.pkl .a checkpoint.: it is a pickle"):
        checkpoint.load_latest(tmp_path)
