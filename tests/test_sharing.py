"""Safe to share, bounded everywhere: a run folder, checkpoint or student from anyone
loads without running code; answers and worlds have limits; every mistake is one line. The
payloads are real pickles that would write a marker file; CLI cases run as real subprocesses
and the LLM server is a real HTTP server on loopback."""

from __future__ import annotations

import base64
import json
import os
import pickle
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import cloudpickle
import numpy as np
import pytest
import torch
import yaml

from chat_server import ChatServer
from cli_checks import one_error_line as _one_line
from pirl.agents import checkpoint
from pirl.agents.train import train
from pirl.config import safe_state
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig

ROOT = Path(__file__).resolve().parents[1]
TEST_CFG = ROOT / "configs" / "test.yaml"
PIRL = [sys.executable, "-m", "pirl"]
GOOD = "pan: 15, tilt: 45, zoom: 1.0, X: 1, Y: 0, Z: 0"


def _pirl(*args: str, cwd: Path, env: dict | None = None, timeout: float = 300):
    env = {**os.environ, "COLUMNS": "200", **(env or {})}
    return subprocess.run(
        [*PIRL, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env
    )


class Payload:
    """What the probe planted: unpickling it writes ``marker``."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """A finished masked PPO-EWRI run and one stopped after its checkpoints (test.yaml)."""
    root = tmp_path_factory.mktemp("shared")
    cfg = RunConfig.from_yaml(TEST_CFG)
    done = root / "ewri"
    train("ppo-ewri", cfg, done, seed=0, show_progress=False)
    return {"done": done}


def _copy(run: Path, dest: Path) -> Path:
    shutil.copytree(run, dest)
    return dest


def _serialized_keys(model: Path) -> list[str]:
    with zipfile.ZipFile(model) as archive:
        data = json.loads(archive.read("data"))
    return [k for k, v in data.items() if isinstance(v, dict) and ":serialized:" in v]


def _plant_in_zip(model: Path, key: str, marker: Path) -> None:
    """Replace entry ``key`` of an SB3 zip by a cloudpickled payload (as the probe did)."""
    with zipfile.ZipFile(model) as archive:
        members = {n: archive.read(n) for n in archive.namelist()}
    data = json.loads(members["data"])
    blob = base64.b64encode(cloudpickle.dumps(Payload(marker))).decode()
    data[key] = {":type:": "<class 'object'>", ":serialized:": blob}
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(model, "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)


# -- 1. nothing in a run folder, checkpoint or student runs code ------------------------------
def test_a_payload_in_any_serialized_entry_of_model_zip_is_refused(runs, tmp_path):
    from pirl.agents.loading import load_policy

    keys = _serialized_keys(runs["done"] / "model.zip")
    assert {"lr_schedule", "observation_space", "action_space", "policy_class"} <= set(keys)
    for key in keys:
        run = _copy(runs["done"], tmp_path / f"evil-{key}")
        marker = tmp_path / f"marker-{key}"
        _plant_in_zip(run / "model.zip", key, marker)
        with pytest.raises(safe_state.UnsafeFile, match=f"entry {key!r} would run code"):
            load_policy(run)
        assert not marker.exists(), key
    # The probe's command, as it was run: one line, exit 2, no marker, no results folder.
    run, marker = tmp_path / "evil-lr_schedule", tmp_path / "marker-lr_schedule"
    proc = _pirl(
        "evaluate", "--runs", str(run), "--sizes", "15", "--episodes", "1",
        "--out", str(tmp_path / "eval"), cwd=tmp_path,
    )  # fmt: skip
    _one_line(proc, "refused", str(run / "model.zip"), "'lr_schedule'")
    assert not marker.exists() and not (tmp_path / "eval").exists()


def test_a_clean_run_loads_and_plays_without_unpickling(runs, tmp_path, monkeypatch):
    from pirl.agents.loading import load_policy

    def refuse(*_a, **_k):
        raise AssertionError("cloudpickle.loads was called")

    monkeypatch.setattr(cloudpickle, "loads", refuse)
    monkeypatch.setattr(pickle, "loads", refuse)
    policy = load_policy(runs["done"], act="greedy")
    obs = np.zeros((2, policy.obs_size), dtype=np.float32)
    masks = np.ones((2, policy.model.action_space.n), dtype=bool)
    assert policy.act_batch(obs, None, masks).shape == (2,)


def test_model_zip_holds_no_generator_and_numpy_2s_is_read_without_unpickling(
    runs, tmp_path, monkeypatch
):
    """A model.zip pirl writes names no numpy.random global (under numpy 1 and 2 alike); one
    written by numpy 2 with its spaces' generators (a real entry, tests/data) still loads."""
    from pirl.agents.loading import load_policy

    models = [runs["done"] / "model.zip", *sorted(runs["done"].glob("checkpoints/*/model.zip"))]
    assert len(models) >= 2
    for model in models:
        with zipfile.ZipFile(model) as archive:
            data = json.loads(archive.read("data"))
        for key, value in data.items():
            if isinstance(value, dict) and ":serialized:" in value:
                names = safe_state.pickle_globals(base64.b64decode(value[":serialized:"]))
                assert not [n for n in names if n.startswith("numpy.random")], (model, key)
    run = _copy(runs["done"], tmp_path / "numpy2")
    entry = json.loads((ROOT / "tests" / "data" / "numpy2_action_space.json").read_text())
    with zipfile.ZipFile(run / "model.zip") as archive:
        members = {n: archive.read(n) for n in archive.namelist()}
    data = json.loads(members["data"])
    data["action_space"] = entry["action_space"]
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(run / "model.zip", "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)

    def refuse(*_a, **_k):
        raise AssertionError("cloudpickle.loads was called")

    monkeypatch.setattr(cloudpickle, "loads", refuse)
    monkeypatch.setattr(pickle, "loads", refuse)
    assert load_policy(run, act="greedy").model.action_space.n > 0


def test_an_il_expert_with_a_payload_is_refused(runs, tmp_path):
    run = _copy(runs["done"], tmp_path / "expert")
    marker = tmp_path / "marker"
    _plant_in_zip(run / "model.zip", "clip_range", marker)
    proc = _pirl(
        "train", "--method", "il", "--config", str(TEST_CFG), "--expert", str(run),
        "--out", str(tmp_path / "il"), cwd=tmp_path,
    )  # fmt: skip
    _one_line(proc, "refused", "clip_range")
    assert not marker.exists() and not (tmp_path / "il").exists()


def test_a_tabnet_run_with_a_payload_is_refused(runs, tmp_path):
    import io

    from pirl.agents.imitation import train_il

    cfg = RunConfig.from_yaml(TEST_CFG)
    il = tmp_path / "il"
    train_il(cfg, runs["done"], il, seed=0)
    marker = tmp_path / "marker"
    with zipfile.ZipFile(il / "tabnet.zip") as archive:
        members = {n: archive.read(n) for n in archive.namelist()}
    buf = io.BytesIO()
    torch.save({"w": Payload(marker)}, buf)
    members["network.pt"] = buf.getvalue()
    with zipfile.ZipFile(il / "tabnet.zip", "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)
    proc = _pirl(
        "evaluate", "--runs", str(il), "--sizes", "15", "--episodes", "1",
        "--out", str(tmp_path / "ev"), cwd=tmp_path,
    )  # fmt: skip
    _one_line(proc, "refused", "network.pt")
    assert not marker.exists() and not (tmp_path / "ev").exists()


def _stopped_run(runs: dict[str, Path], dest: Path) -> Path:
    """A copy of the finished run made resumable: no final model, not complete."""
    run = _copy(runs["done"], dest)
    (run / "model.zip").unlink()
    meta = json.loads((run / "meta.json").read_text())
    (run / "meta.json").write_text(json.dumps({**meta, "complete": False}))
    return run


def test_a_pickle_in_a_checkpoint_is_refused_on_resume(runs, tmp_path):
    run = _stopped_run(runs, tmp_path / "evilstate")
    newest = checkpoint.latest(run / "checkpoints")
    marker = tmp_path / "marker"
    (newest / "state.npz").unlink()
    (newest / "state.pkl").write_bytes(pickle.dumps(Payload(marker)))
    proc = _pirl("train", "--method", "ppo-ewri", "--out", str(run), "--resume", cwd=tmp_path)
    _one_line(proc, "refused", "state.pkl", "pickle")
    assert not marker.exists()


def test_a_checkpoint_named_npz_holding_a_pickle_is_refused(tmp_path):
    marker = tmp_path / "marker"
    path = tmp_path / "state.npz"
    path.write_bytes(pickle.dumps(Payload(marker)))
    with pytest.raises(safe_state.UnsafeFile, match="pickle"):
        safe_state.load(path)
    # An npz whose array is an object array would need unpickling too.
    np.savez(path, __structure__=np.array([Payload(marker)], dtype=object))
    with pytest.raises(safe_state.UnsafeFile):
        safe_state.load(path)
    assert not marker.exists()


def test_resume_from_the_safe_checkpoint_is_exact(runs, tmp_path):
    """Resuming the stopped copy from its last safe checkpoint gives the same weights."""
    from pirl.agents.loading import load_model

    run = _stopped_run(runs, tmp_path / "resumed")
    proc = _pirl("train", "--method", "ppo-ewri", "--out", str(run), "--resume", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    a = load_model(run / "model.zip").policy.state_dict()
    b = load_model(runs["done"] / "model.zip").policy.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_safe_state_round_trips_what_checkpoints_hold(tmp_path):
    from pirl.advice.base import Answer
    from pirl.advice.recommendation import Recommendation

    rng = np.random.default_rng(7)
    rng.random(3)
    state = {
        "ints": (1, 2**100, -3),
        "floats": [0.1, float("inf"), float("nan")],
        "arr": np.arange(6, dtype=np.uint64).reshape(2, 3),
        "scalar": np.float32(1.5),
        "tensor": torch.arange(4, dtype=torch.float64),
        "rng": rng,
        "numpy_rng": np.random.get_state(),
        "int_keys": {0: "a", (1, 2): "b"},
        "answer": Answer("x", Recommendation(15, 45, 1.0, 1, 0, 0), latency_s=0.5),
        "__odd": None,
    }
    path = safe_state.save(state, tmp_path / "s.npz")
    back = safe_state.load(path)
    assert back["ints"] == (1, 2**100, -3)
    assert back["floats"][:2] == [0.1, float("inf")] and np.isnan(back["floats"][2])
    assert back["arr"].dtype == np.uint64 and np.array_equal(back["arr"], state["arr"])
    assert back["scalar"] == np.float32(1.5) and back["scalar"].dtype == np.float32
    assert torch.equal(back["tensor"], state["tensor"])
    assert back["rng"].random() == rng.random()
    assert back["int_keys"] == {0: "a", (1, 2): "b"}
    assert back["answer"] == state["answer"]
    assert "__odd" in back


def test_safe_state_rebuilds_only_pirls_own_dataclasses(tmp_path):
    path = safe_state.save({"x": 1}, tmp_path / "s.npz")
    members = dict(np.load(path, allow_pickle=False))
    doc = {"format": "pirl-safe-state/1", "data": {"__dataclass__": "subprocess:Popen"}}
    members["__structure__"] = np.frombuffer(json.dumps(doc).encode(), dtype=np.uint8)
    np.savez(path, **members)
    with pytest.raises(safe_state.UnsafeFile, match="not pirl's"):
        safe_state.load(path)


def test_a_student_saved_with_torch_save_is_refused(tmp_path):
    from pirl.advice.student import Student

    marker = tmp_path / "marker"
    folder = tmp_path / "student"
    folder.mkdir()
    torch.save({"teacher": Payload(marker)}, folder / "student.npz")
    with pytest.raises(safe_state.UnsafeFile, match="pickle"):
        Student.load(folder / "student.npz", None)
    assert not marker.exists()


def test_a_student_round_trips_without_pickle(tmp_path):
    from pirl.advice.student import Student

    student = Student("t", 12, label="x", hidden=8, seed=3)
    student.save(tmp_path / "student.npz")
    back = Student.load(tmp_path / "student.npz", None)
    a, b = student.state_dict(), back.state_dict()
    assert a["teacher"] == b["teacher"] and a["last_id"] == b["last_id"]
    assert all(torch.equal(a["net"][k], b["net"][k]) for k in a["net"])


def test_pickle_globals_reads_without_loading(tmp_path):
    marker = tmp_path / "marker"
    names = safe_state.pickle_globals(cloudpickle.dumps(Payload(marker)))
    assert any(n.endswith(".system") for n in names)
    assert safe_state.pickle_globals(pickle.dumps({"a": [1, 2]})) == set()
    assert not marker.exists()


# -- 2. bounded answers ------------------------------------------------------------------------
def test_a_6_mb_answer_is_cut_counted_unparseable_and_never_stored_whole(tmp_path):
    from pirl.advice.cache import CachedAdvisor
    from pirl.advice.openai_advisor import MAX_REPLY_BYTES, OpenAIAdvisor

    server = ChatServer(GOOD + "\n" + "x" * 6_000_000)
    try:
        env = {"PIRL_CACHE_DIR": str(tmp_path / "cache")}
        proc = _pirl(
            "advise", "--advisor", "openai", "--base-url", server.url, "--model", "m",
            "--config", "test", cwd=tmp_path, env=env,
        )  # fmt: skip
        assert proc.returncode == 1, proc.stderr
        answer_part = proc.stdout.split("answer from", 1)[1]
        assert len(answer_part.encode()) < 2048, len(answer_part)
        assert "6,000," in answer_part and "could not parse" in answer_part
        cache_bytes = sum(p.stat().st_size for p in (tmp_path / "cache").rglob("*") if p.is_file())
        assert cache_bytes < 2_000_000, cache_bytes
        adv = OpenAIAdvisor("m", base_url=server.url, max_retries=0)
        answers = CachedAdvisor(adv, tmp_path / "c.sqlite").advise(["a", "b"])
        assert all(a.recommendation is None and a.cut for a in answers)
        assert all(len(a.text) <= 1024 and a.reply_chars > MAX_REPLY_BYTES for a in answers)
        assert (tmp_path / "c.sqlite").stat().st_size < 1_000_000
    finally:
        server.close()


def test_every_answer_keeps_a_bounded_head():
    from pirl.advice.base import MAX_ANSWER_CHARS, Answer
    from pirl.advice.recommendation import Recommendation

    rec = Recommendation(15, 45, 1.0, 1, 0, 0)
    long = Answer(GOOD + "y" * 5000, rec)
    assert len(long.text) == MAX_ANSWER_CHARS and long.recommendation is None
    assert long.reply_chars == len(GOOD) + 5000
    assert Answer(GOOD, rec).recommendation == rec and not Answer(GOOD, rec).cut


# -- 3. bounded worlds -------------------------------------------------------------------------
def test_huge_worlds_are_refused_fast_and_leave_nothing(tmp_path):
    started = time.monotonic()
    proc = _pirl("render", "--size", "2000", "2000", "10", "--out", "x.gif", cwd=tmp_path)
    _one_line(proc, "2000x2000x10", "GB", "env.max_memory_gb")
    proc = _pirl(
        "evaluate", "--methods", "random", "--sizes", "2000x2000x10", "--out", "ev", cwd=tmp_path
    )
    _one_line(proc, "2000x2000x10", "over the limit")
    assert time.monotonic() - started < 30  # two interpreters; each refusal is immediate
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_the_memory_limit_is_a_setting():
    from pirl.config.world import VCPPConfig
    from pirl.world.memory import check_memory, world_bytes

    small = VCPPConfig(size=(60, 60, 3))
    assert check_memory(small, 4) >= 4 * world_bytes(small)
    with pytest.raises(ConfigError, match="over the limit of 0.0 GB"):
        check_memory(small.replace(max_memory_gb=1e-6), 1)
    with pytest.raises(ConfigError, match="env.max_memory_gb"):
        VCPPConfig(max_memory_gb=-1)


# -- 4-6. seeds, method options, one-line errors -----------------------------------------------
def test_seeds_out_of_range_are_refused_before_any_folder(tmp_path):
    out = tmp_path / "run"
    for seed in ("-1", "4294967296"):
        proc = _pirl(
            "train", "--method", "ppo-sr", "--config", "test", "--seed", seed, "--out", str(out),
            cwd=tmp_path,
        )  # fmt: skip
        _one_line(proc, f"--seed {seed}", "4294967295")
        assert not out.exists()
    _one_line(_pirl("render", "--seed", "-1", "--out", "x.gif", cwd=tmp_path), "--seed")
    _one_line(_pirl("advise", "--advisor", "oracle", "--seed", "-1", cwd=tmp_path), "--seed")


def test_a_run_that_failed_before_its_first_checkpoint_starts_again(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "config.yaml").write_text(yaml.safe_dump(RunConfig().to_dict()))
    (out / "meta.json").write_text(json.dumps({"method": "ppo-sr", "complete": False}))
    proc = _pirl("train", "--method", "ppo-sr", "--config", "test", "--out", str(out), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "starting it again" in proc.stdout
    assert json.loads((out / "meta.json").read_text())["complete"] is True


def test_options_a_method_does_not_use_are_refused(runs, tmp_path):
    from pirl.agents.runs import train_run

    proc = _pirl(
        "train", "--method", "ppo-sr", "--expert", str(runs["done"]), "--config", "test",
        "--out", str(tmp_path / "r"), cwd=tmp_path,
    )  # fmt: skip
    _one_line(proc, "--expert", "ppo-sr")
    with pytest.raises(ConfigError, match="--advisor is not an option of --method ppo-ewri"):
        train_run("ppo-ewri", tmp_path / "r", TEST_CFG, TEST_CFG, advisor="oracle")
    with pytest.raises(ConfigError, match="--student is not an option of --method il"):
        train_run("il", tmp_path / "r", TEST_CFG, TEST_CFG, student=tmp_path)
    assert not (tmp_path / "r").exists()


def test_il_refuses_an_expert_of_another_method(runs, tmp_path):
    expert = _copy(runs["done"], tmp_path / "sr")
    meta = json.loads((expert / "meta.json").read_text())
    (expert / "meta.json").write_text(json.dumps({**meta, "method": "ppo-sr"}))
    proc = _pirl(
        "train", "--method", "il", "--config", "test", "--expert", str(expert),
        "--out", str(tmp_path / "il"), cwd=tmp_path,
    )  # fmt: skip
    _one_line(proc, "ppo-sr run", "ppo-ewri")
    assert not (tmp_path / "il").exists()


def test_distill_mistakes_leave_no_student_folder(tmp_path):
    out = tmp_path / "students" / "s3"
    base = ["distill", "--teacher", "oracle", "--config", "test", "--out", str(out)]
    _one_line(_pirl(*base, "--fit-steps", "0", cwd=tmp_path), "--fit-steps 0")
    _one_line(_pirl(*base, "--policy", "notarun", cwd=tmp_path), "notarun")
    assert not (tmp_path / "students").exists() or list((tmp_path / "students").iterdir()) == []


def test_render_mistakes_are_one_line_before_the_episode(tmp_path):
    _one_line(_pirl("render", "--fps", "0", "--out", "x.gif", cwd=tmp_path), "--fps 0")
    (tmp_path / "gifs").mkdir()
    _one_line(_pirl("render", "--out", "gifs", cwd=tmp_path), "is a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gifs"]
    assert list((tmp_path / "gifs").iterdir()) == []


def test_config_files_that_are_not_utf8_or_repeat_a_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"ppo:\n  n_envs: \xff\n")
    proc = _pirl("train", "--method", "ppo-sr", "--config", str(bad), "--out", "r", cwd=tmp_path)
    _one_line(proc, "not UTF-8")
    dup = tmp_path / "dup.yaml"
    dup.write_text("ppo:\n  n_envs: 4\n  n_envs: 8\n")
    proc = _pirl("train", "--method", "ppo-sr", "--config", str(dup), "--out", "r", cwd=tmp_path)
    _one_line(proc, "'n_envs'", "lines 2 and 3")
    assert not (tmp_path / "r").exists()


def test_a_damaged_advisor_stats_is_named_and_the_report_still_says_so(tmp_path):
    from pirl.report.document import advice_table
    from pirl.reproduce.pipeline import _advisor_stats

    run = tmp_path / "pirl-s0"
    run.mkdir()
    (run / "advisor_stats.json").write_text("{not json")
    lines: list[str] = []
    stats = _advisor_stats([run], tmp_path / "none.jsonl", lines.append)
    assert len(lines) == 1 and "advisor_stats.json is damaged" in lines[0]
    assert "Stats missing for run pirl-s0" in advice_table(stats).notes[0]
