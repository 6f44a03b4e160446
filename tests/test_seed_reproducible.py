"""A PIRL seed's model is a function of (code, config, seed), whatever trains beside it.

The demo trains its PIRL seeds side by side, sharing one teacher dataset. Each run learns only
from its own teacher answers plus a head start fixed before it trains
(``pare.student_dataset_scope: run``), and takes the teacher's answers at rollout boundaries
fixed in steps (``pare.student_wait_teacher``), so two seeds trained together, or one started
late beside a busy process, give the same weights.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest
import torch
import yaml

from pirl.config.run import RunConfig

ROOT = Path(__file__).resolve().parents[1]
SEEDS = (0, 1)


def _config(tmp: Path, advisor: str) -> Path:
    """The test preset with the demo's PIRL settings (student mode, the advisor's prompt) and
    a teacher rate high enough that answers arrive at every rollout of a short run."""
    quick = RunConfig.from_yaml(ROOT / "configs" / "quick.yaml")
    data = RunConfig.from_yaml(ROOT / "configs" / "test.yaml").to_dict()
    # The gate opens at the first refit with enough held-out answers, so the student shapes
    # most of the run and its answers reach the weights: the LLM from its head start, the
    # oracle after about three rollouts of its own answers. The embedded LLM's answers are
    # most of this test's time, so its runs are shorter, and five held-out answers (not 20)
    # let a head start of 40 open the gate.
    data["pare"].update(
        advisor=advisor, mode="student", prompt_variant=quick.pare.prompt_variant,
        teacher_rate=0.02, oracle_teacher_rate=0.25, student_gate_on="agreement",
        student_gate=0.0, student_closed_rate=1.0, student_fit_steps=20, student_min_heldout=5,
        student_dataset=str(tmp / "student.sqlite"), cache_path=str(tmp / "advice.sqlite"),
    )  # fmt: skip
    data["train"]["total_steps"] = 512 if advisor == "local" else 1024
    data["reproduce"]["teacher_phase_answers"] = 40 if advisor == "local" else 0
    path = tmp / f"{advisor}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _train(cfg: Path, seed: int, out: Path, env: dict[str, str]) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "pirl", "train", "--method", "pirl", "--config", str(cfg),
           "--seed", str(seed), "--out", str(out)]  # fmt: skip
    return subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _finish(proc: subprocess.Popen) -> None:
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err


def _shaped(run: Path) -> int:
    return json.loads((run / "advisor_stats.json").read_text())["steps_student"]


def _weights(run: Path) -> dict[str, torch.Tensor]:
    with zipfile.ZipFile(run / "model.zip") as z, z.open("policy.pth") as f:
        return torch.load(f, map_location="cpu", weights_only=True)


@pytest.mark.parametrize("advisor", ["local", "oracle"])
def test_seeds_side_by_side_give_the_same_weights_whatever_runs_beside_them(tmp_path, advisor):
    cfg = _config(tmp_path, advisor)
    env = {**os.environ, "PIRL_CACHE_DIR": str(tmp_path / "cache")}
    # Together: both seeds start at once and share the dataset (the demo's way).
    together = [_train(cfg, s, tmp_path / f"together-s{s}", env) for s in SEEDS]
    for proc in together:
        _finish(proc)
    # Staggered: seed 1 starts late, and both train beside a process that keeps a core busy,
    # so the teacher's answers of seed 0 are stored at other moments of seed 1's run.
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        first = _train(cfg, SEEDS[0], tmp_path / "staggered-s0", env)
        time.sleep(3)
        second = _train(cfg, SEEDS[1], tmp_path / "staggered-s1", env)
        _finish(first)
        _finish(second)
    finally:
        busy.kill()
        busy.wait()
    for s in SEEDS:
        a = _weights(tmp_path / f"together-s{s}")
        b = _weights(tmp_path / f"staggered-s{s}")
        assert a.keys() == b.keys()
        for name in a:
            assert torch.equal(a[name], b[name]), f"seed {s}: {name} differs"
        assert _shaped(tmp_path / f"together-s{s}") == _shaped(tmp_path / f"staggered-s{s}") > 0
    # The seeds learned from different answers (the test would pass trivially otherwise).
    one, two = _weights(tmp_path / "together-s0"), _weights(tmp_path / "together-s1")
    assert any(not torch.equal(one[k], two[k]) for k in one)
