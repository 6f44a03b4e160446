"""Faults never stick: answers cached per server and only when they parse, damaged
or unusable caches degrade in one line, one writer per folder, deadlines on a silent server,
any path, OS errors in one line, Ctrl-C in one line. Real subprocesses, real SQLite files and
OpenAI-compatible fake servers on 127.0.0.1 only."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest
import yaml

from chat_server import completion_body

ROOT = Path(__file__).resolve().parents[1]
TEST_CFG = ROOT / "configs" / "test.yaml"
PIRL = [sys.executable, "-m", "pirl"]
GOOD = "pan: 15, tilt: 45, zoom: 1.0, X: 1, Y: 0, Z: 0"


class FakeLLM:
    """An OpenAI-compatible chat server on loopback. ``reply``: the answer text; ``hang``:
    accept requests and never answer (after ``answer_first`` answered ones)."""

    def __init__(self, reply: str = GOOD, hang: bool = False, answer_first: int = 0) -> None:
        self.reply, self.hang, self.answer_first = reply, hang, answer_first
        self.requests = 0
        self.stopping = threading.Event()
        fake = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 - http.server's name
                self.rfile.read(int(self.headers.get("content-length") or 0))
                fake.requests += 1
                if fake.hang and fake.requests > fake.answer_first:
                    fake.stopping.wait(600)  # accepted, never answered
                    return
                usage = {"prompt_tokens": 3, "completion_tokens": 5, "total_tokens": 8}
                body = completion_body(fake.reply, usage)
                self.send_response(200)
                self.send_header("content-type", "application/json")
                self.send_header("content-length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args: object) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/v1"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.stopping.set()
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def fake() -> Iterator[type[FakeLLM]]:
    made: list[FakeLLM] = []

    def make(*args: object, **kwargs: object) -> FakeLLM:
        made.append(FakeLLM(*args, **kwargs))  # type: ignore[arg-type]
        return made[-1]

    yield make  # type: ignore[misc]
    for server in made:
        server.close()


def _env(tmp_path: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("OPENAI_API_KEY", "OPENAI_BASE_URL")}
    env.update({"PIRL_CACHE_DIR": str(tmp_path / "cache"), "COLUMNS": "200", **extra})
    return env


def _pirl(*args: str, cwd: Path, env: dict[str, str], timeout: float = 300):
    return subprocess.run(
        [*PIRL, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env
    )


def _config(tmp_path: Path, name: str = "cfg.yaml", **sections: dict) -> Path:
    data = yaml.safe_load(TEST_CFG.read_text())
    for section, values in sections.items():
        data.setdefault(section, {}).update(values)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def _error_line(proc: subprocess.CompletedProcess, code: int = 2) -> str:
    """Exit ``code``, no traceback, exactly one line on stderr."""
    assert proc.returncode == code, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stdout + proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    return lines[0]


def _advise(url: str, tmp_path: Path, *extra: str, env: dict | None = None):
    return _pirl(
        "advise", "--advisor", "openai", "--base-url", url, "--model", "m", "--config", "test",
        *extra, cwd=tmp_path, env=env or _env(tmp_path),
    )  # fmt: skip


# -- 1. the answer cache: per server, parsed answers only ------------------------------------
def test_cache_is_per_server_and_never_replays_an_unparseable_answer(tmp_path, fake):
    turtles, other = fake("I like turtles"), fake(GOOD)
    first = _advise(turtles.url, tmp_path)
    assert first.returncode == 1 and "I like turtles" in first.stdout
    # Another server is asked, not answered from the first one's cache.
    proc = _advise(other.url, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "from cache:  False" in proc.stdout and "I like turtles" not in proc.stdout
    assert other.requests == 1
    # The first server, fixed, is heard: its bad answer was never stored.
    turtles.reply = GOOD
    proc = _advise(turtles.url, tmp_path)
    assert proc.returncode == 0 and "from cache:  False" in proc.stdout
    proc = _advise(turtles.url, tmp_path)
    assert proc.returncode == 0 and "from cache:  True" in proc.stdout
    assert turtles.requests == 2


def test_a_fixed_server_lets_resume_continue(tmp_path, fake):
    server = fake("I like turtles")
    cfg = _config(
        tmp_path, pare={"advisor": "openai", "mode": "sync", "failure_window": 20},
        advisor={"openai_base_url": server.url, "openai_model": "m"},
    )  # fmt: skip
    run = tmp_path / "run"
    args = ("train", "--method", "pirl", "--config", str(cfg), "--out", str(run))
    proc = _pirl(*args, cwd=tmp_path, env=_env(tmp_path))
    assert proc.returncode == 3, proc.stderr
    assert "fix the advisor, then continue with --resume" in proc.stderr
    server.reply = GOOD
    proc = _pirl("train", "--method", "pirl", "--out", str(run), "--resume", cwd=tmp_path,
                 env=_env(tmp_path))  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert json.loads((run / "meta.json").read_text())["complete"] is True


def test_openai_base_url_from_the_environment_is_honoured(tmp_path, fake):
    server = fake(GOOD)
    env = _env(tmp_path, OPENAI_BASE_URL=server.url)
    proc = _pirl("advise", "--advisor", "openai", "--model", "m", "--config", "test",
                 cwd=tmp_path, env=env)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert server.requests == 1 and f"127.0.0.1:{server.url.split(':')[2]}" in proc.stdout


# -- 2. damaged, unusable caches: one warning line, then go on -------------------------------
def test_damaged_advice_cache_is_moved_aside_in_one_line(tmp_path, fake):
    server = fake(GOOD)
    cache = tmp_path / "cache"
    cache.mkdir()
    (cache / "advice.sqlite").write_bytes(os.urandom(8192))
    proc = _advise(server.url, tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("warning: advice cache")
    assert "advice.sqlite.corrupt" in lines[0] and "Traceback" not in proc.stderr
    assert (cache / "advice.sqlite.corrupt").is_file()
    proc = _advise(server.url, tmp_path)  # the fresh cache works
    assert proc.returncode == 0 and "from cache:  True" in proc.stdout and not proc.stderr


def test_unusable_cache_folder_runs_without_a_cache(tmp_path, fake):
    server = fake(GOOD)
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file where the cache folder should be")
    env = _env(tmp_path, PIRL_CACHE_DIR=str(blocker))
    proc = _advise(server.url, tmp_path, env=env)
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "going on without it" in lines[0], proc.stderr
    assert str(blocker / "advice.sqlite") in lines[0]


@contextlib.contextmanager
def _tmpfs(path: Path, options: str) -> Iterator[bool]:
    """A small tmpfs at ``path`` (True), or False where this machine cannot mount one."""
    path.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)],
                          capture_output=True)  # fmt: skip
    try:
        yield done.returncode == 0
    finally:
        if done.returncode == 0:
            subprocess.run(["umount", "-l", str(path)], capture_output=True)


def test_read_only_cache_folder_runs_without_a_cache(tmp_path, fake):
    server = fake(GOOD)
    with _tmpfs(tmp_path / "ro", "ro,size=64k") as mounted:
        if not mounted:
            pytest.skip("cannot mount a read-only tmpfs here")
        proc = _advise(
            server.url, tmp_path, env=_env(tmp_path, PIRL_CACHE_DIR=str(tmp_path / "ro"))
        )
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "going on without it" in lines[0], proc.stderr


def test_damaged_student_dataset_is_moved_aside_and_training_goes_on(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    (cache / "student.sqlite").write_bytes(os.urandom(4096))
    cfg = _config(tmp_path, pare={"advisor": "oracle", "mode": "student"})
    proc = _pirl("train", "--method", "pirl", "--config", str(cfg), "--out",
                 str(tmp_path / "run"), cwd=tmp_path, env=_env(tmp_path))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    warnings = [line for line in proc.stderr.splitlines() if "student.sqlite" in line]
    assert len(warnings) == 1 and "student.sqlite.corrupt" in warnings[0]
    assert "Traceback" not in proc.stderr and (cache / "student.sqlite.corrupt").is_file()


def test_teacher_dataset_in_an_unusable_place_lives_in_memory(tmp_path, capsys):
    import numpy as np

    from pirl.advice.student import TeacherDataset

    blocker = tmp_path / "file"
    blocker.write_text("x")
    data = TeacherDataset(blocker / "student.sqlite", timeout_s=1)
    assert data.in_memory and "going on without it" in capsys.readouterr().err
    assert data.add("t", np.zeros((2, 3), np.float32), np.zeros((2, 6), np.int64)) == 2
    assert data.count("t") == 2


# -- 3. one writer per folder ----------------------------------------------------------------
def _hold_lock(*folders: Path) -> subprocess.Popen:
    """One process that holds the write lock of each of ``folders`` until killed."""
    code = (
        "import sys, time; from pathlib import Path; from pirl.agents.run_folder import "
        "lock_folder\nfor a in sys.argv[1:]:\n p = Path(a); p.mkdir(parents=True, "
        "exist_ok=True); lock_folder(p)\nprint('locked', flush=True); time.sleep(600)"
    )
    holder = subprocess.Popen([sys.executable, "-c", code, *map(str, folders)],
                              stdout=subprocess.PIPE, text=True)  # fmt: skip
    assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
    return holder


def test_second_training_writer_is_refused_with_the_holders_pid(tmp_path):
    run = tmp_path / "run"
    env = _env(tmp_path)
    first = subprocess.Popen(
        [*PIRL, "train", "--method", "ppo-sr", "--config", "test", "--steps", "400000",
         "--out", str(run)], cwd=tmp_path, env=env, stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while not (run / "checkpoints" / "LATEST").exists():
            assert first.poll() is None and time.monotonic() < deadline, first.stderr
            time.sleep(0.2)
        proc = _pirl("train", "--method", "ppo-sr", "--out", str(run), "--resume",
                     cwd=tmp_path, env=env)  # fmt: skip
        line = _error_line(proc)
        assert f"PID {first.pid}" in line and str(run) in line
    finally:
        first.send_signal(signal.SIGKILL)
        first.wait()
    # The kernel released the dead writer's lock: no stale lock is left behind.
    from pirl.agents.run_folder import lock_folder, release_folder

    lock_folder(run)
    release_folder(run)


def test_evaluate_reproduce_and_distill_are_one_writer_too(tmp_path):
    env = _env(tmp_path)
    out = tmp_path / "ev"
    student = tmp_path / "student"
    holder = _hold_lock(out, tmp_path / "student.tmp")  # one holder process for both
    try:
        proc = _pirl("evaluate", "--methods", "boustrophedon", "--sizes", "16", "--episodes",
                     "1", "--out", str(out), "--overwrite", cwd=tmp_path, env=env)  # fmt: skip
        assert f"PID {holder.pid}" in _error_line(proc)
        proc = _pirl("reproduce", "--config", "test", "--out", str(out), cwd=tmp_path, env=env)
        assert f"PID {holder.pid}" in _error_line(proc)
        proc = _pirl("distill", "--teacher", "oracle", "--states", "10", "--config", "test",
                     "--out", str(student), cwd=tmp_path, env=env)  # fmt: skip
        assert f"PID {holder.pid}" in _error_line(proc)
    finally:
        holder.kill()
        holder.wait()


# -- 4. deadlines on a server that accepts and never answers ---------------------------------
def test_probe_gives_up_at_its_deadline_and_makes_no_folder(tmp_path, fake):
    server = fake(hang=True)
    cfg = _config(tmp_path, pare={"advisor": "openai"},
                  advisor={"openai_base_url": server.url, "openai_model": "m",
                           "probe_timeout_s": 3.0})  # fmt: skip
    started = time.monotonic()
    proc = _pirl("train", "--method", "pirl", "--config", str(cfg), "--out",
                 str(tmp_path / "run"), cwd=tmp_path, env=_env(tmp_path))  # fmt: skip
    line = _error_line(proc)
    assert "no answer to its probe call within 3 s" in line
    assert "probing openai:m@127.0.0.1" in proc.stdout and server.url in proc.stdout
    assert not (tmp_path / "run").exists()
    assert time.monotonic() - started < 60
    proc = _pirl("advise", "--advisor", "openai", "--base-url", server.url, "--model", "m",
                 "--config", str(cfg), cwd=tmp_path, env=_env(tmp_path))  # fmt: skip
    assert "gave no answer within 3 s" in _error_line(proc)


def test_a_teacher_that_stops_answering_stops_training_resumably(tmp_path, fake):
    server = fake(hang=True, answer_first=1)  # the probe is answered, then silence
    cfg = _config(
        tmp_path, pare={"advisor": "openai", "mode": "sync"},
        advisor={"openai_base_url": server.url, "openai_model": "m", "openai_timeout_s": 1.0,
                 "openai_deadline_s": 2.0},
    )  # fmt: skip
    run = tmp_path / "run"
    started = time.monotonic()
    proc = _pirl("train", "--method", "pirl", "--config", str(cfg), "--out", str(run),
                 cwd=tmp_path, env=_env(tmp_path))  # fmt: skip
    elapsed = time.monotonic() - started
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert "answered none of its last 3 batches" in proc.stderr and "Traceback" not in proc.stderr
    assert elapsed < 90, elapsed
    server.hang = False
    proc = _pirl("train", "--method", "pirl", "--out", str(run), "--resume", cwd=tmp_path,
                 env=_env(tmp_path))  # fmt: skip
    assert proc.returncode == 0, proc.stderr


# -- 5. any path: spaces, commas, non-ASCII ---------------------------------------------------
def test_paths_with_spaces_commas_and_non_ascii_end_to_end(tmp_path):
    env = _env(tmp_path)
    run = tmp_path / "my run, ü"
    proc = _pirl("train", "--method", "ppo-sr", "--config", "test", "--out", str(run),
                 cwd=tmp_path, env=env)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    results = tmp_path / "résultats, 1"
    proc = _pirl("evaluate", "--runs", str(run), "--methods", "boustrophedon", "--sizes", "16",
                 "--episodes", "1", "--act", "greedy", "--out", str(results), cwd=tmp_path,
                 env=env)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert (results / "summary.csv").is_file()
    student = tmp_path / "élève, 1"
    proc = _pirl("distill", "--teacher", "oracle", "--states", "40", "--fit-steps", "20",
                 "--policy", str(run), "--policy", "boustrophedon", "--config", "test",
                 "--out", str(student), cwd=tmp_path, env=env)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    record = json.loads((student / "student.json").read_text())
    assert record["policies"] == [str(run), "boustrophedon"]


# -- 6. checks before folders; OS errors and Ctrl-C in one line ------------------------------
def test_impossible_obstacle_layout_is_refused_before_any_folder(tmp_path):
    cfg = _config(tmp_path, env={"size": [3, 3, 3], "obstacles_min": 30, "obstacles_max": 30,
                                 "radius_min": 2.0, "radius_max": 2.0})  # fmt: skip
    run = tmp_path / "run"
    proc = _pirl("train", "--method", "ppo-sr", "--config", str(cfg), "--out", str(run),
                 cwd=tmp_path, env=_env(tmp_path))  # fmt: skip
    assert "could not place" in _error_line(proc) and not run.exists()
    proc = _pirl("evaluate", "--methods", "random", "--config", str(cfg), "--sizes", "3x3x3",
                 "--episodes", "1", "--out", str(tmp_path / "ev"), cwd=tmp_path,
                 env=_env(tmp_path))  # fmt: skip
    assert "could not place" in _error_line(proc) and not (tmp_path / "ev").exists()


def test_os_errors_are_one_line_naming_the_path(tmp_path):
    env = _env(tmp_path)
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    proc = _pirl("train", "--method", "ppo-sr", "--config", "test", "--out",
                 str(blocker / "run"), cwd=tmp_path, env=env)  # fmt: skip
    assert str(blocker / "run") in _error_line(proc)
    with _tmpfs(tmp_path / "ro", "ro,size=64k") as mounted:
        if mounted:
            proc = _pirl("train", "--method", "ppo-sr", "--config", "test", "--out",
                         str(tmp_path / "ro" / "run"), cwd=tmp_path, env=env)  # fmt: skip
            line = _error_line(proc)
            assert "Read-only file system" in line and str(tmp_path / "ro" / "run") in line
    with _tmpfs(tmp_path / "full", "size=96k") as mounted:
        if not mounted:
            pytest.skip("cannot mount a small tmpfs here")
        proc = _pirl("train", "--method", "ppo-sr", "--config", "test", "--out",
                     str(tmp_path / "full" / "run"), cwd=tmp_path, env=env)  # fmt: skip
        line = _error_line(proc)
        assert "No space left on device" in line and str(tmp_path / "full" / "run") in line


def _interrupt(args: list[str], tmp_path: Path, ready: Path) -> subprocess.CompletedProcess:
    """Start ``pirl args`` in a session of its own, wait for ``ready`` to exist, then Ctrl-C
    the whole process group as a terminal does."""
    proc = subprocess.Popen(
        [*PIRL, *args], cwd=tmp_path, env=_env(tmp_path), stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, start_new_session=True,
        # A shell that starts the suite in the background ignores SIGINT; children inherit it.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip
    deadline = time.monotonic() + 240
    while not ready.exists():
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.2)
    time.sleep(1.0)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def test_ctrl_c_in_reproduce_and_evaluate_is_one_line(tmp_path):
    cfg = _config(tmp_path, train={"total_steps": 200_000, "checkpoint_every": 128},
                  reproduce={"train_workers": 2, "methods": ["ppo-sr", "ppo-ewri"]})  # fmt: skip
    out = tmp_path / "res"
    proc = _interrupt(["reproduce", "--config", str(cfg), "--out", str(out)], tmp_path,
                      out / "runs" / "ppo-sr-s0" / "checkpoints" / "LATEST")  # fmt: skip
    line = _error_line(proc, 130)
    assert line.startswith("interrupted:") and "run the same command to resume" in line
    assert f"pirl reproduce --config {cfg} --out {out}" in line
    proc = _interrupt(["evaluate", "--methods", "random", "--sizes", "60", "--episodes", "400",
                       "--workers", "2", "--out", str(tmp_path / "ev")], tmp_path,
                      tmp_path / "ev" / ".pirl.lock")  # fmt: skip
    line = _error_line(proc, 130)
    assert line.startswith("interrupted:") and "run the same command" in line


# -- 7. the small ones -----------------------------------------------------------------------
def test_small_surprises_are_said(tmp_path):
    env = _env(tmp_path)
    ev = tmp_path / "ev"
    args = ["evaluate", "--methods", "boustrophedon", "--sizes", "16", "--episodes", "1",
            "--act", "greedy", "--out", str(ev)]  # fmt: skip
    assert _pirl(*args, cwd=tmp_path, env=env).returncode == 0
    before = (ev / "summary.csv").read_bytes()
    assert "--overwrite" in _error_line(_pirl(*args, cwd=tmp_path, env=env))
    assert (ev / "summary.csv").read_bytes() == before
    assert _pirl(*args, "--overwrite", cwd=tmp_path, env=env).returncode == 0
    for workers in ("0", "-2"):
        proc = _pirl(*args, "--overwrite", "--workers", workers, cwd=tmp_path, env=env)
        assert "--workers" in _error_line(proc)
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    proc = _pirl("train", "--method", "ppo-sr", "--config", str(empty), "--out",
                 str(tmp_path / "run"), cwd=tmp_path, env=env)  # fmt: skip
    assert "is empty" in _error_line(proc) and not (tmp_path / "run").exists()


def test_meta_steps_csv_line_endings_n_updates_and_the_differing_setting(tmp_path):
    import shutil
    import zipfile

    from pirl.agents.train import train
    from pirl.config.errors import ConfigError
    from pirl.config.run import RunConfig
    from pirl.evaluate.runner import distinct_specs, spec_for_run

    cfg = RunConfig.from_yaml(TEST_CFG).with_overrides(train={"total_steps": 1500})
    run = tmp_path / "run"
    train("ppo-sr", cfg, run, seed=0, show_progress=False)
    meta = json.loads((run / "meta.json").read_text())
    assert meta["total_steps"] == meta["timesteps"] == 1536  # whole rollouts of 128 steps
    rows = (run / "episodes.csv").read_bytes().count(b"\n")
    # Resumed and extended: one line ending throughout, SB3's update count carried on.
    train("ppo-sr", cfg.with_overrides(train={"total_steps": 3072}), run, seed=0, resume=True,
          show_progress=False)  # fmt: skip
    data = (run / "episodes.csv").read_bytes()
    assert data.count(b"\n") == data.count(b"\r\n") > rows > 1
    n_epochs = cfg.ppo.n_epochs
    with zipfile.ZipFile(run / "model.zip") as zf:  # SB3's saved attributes, any PPO class
        saved = json.loads(zf.read("data"))
    assert saved["_n_updates"] == 3072 // 128 * n_epochs
    # Same label, same seed, another config: the refusal names the setting, not "copies".
    other = tmp_path / "other"
    shutil.copytree(run, other)
    text = (other / "config.yaml").read_text().replace("learning_rate: 0.0003",
                                                       "learning_rate: 0.001")  # fmt: skip
    (other / "config.yaml").write_text(text)
    with pytest.raises(ConfigError, match=r"ppo\.learning_rate") as info:
        distinct_specs([spec_for_run(run), spec_for_run(other)])
    assert "copies" not in str(info.value)


def test_cache_locked_beyond_its_timeout_is_skipped_in_one_line(tmp_path, capsys):
    import sqlite3

    from pirl.advice.cache import CachedAdvisor
    from pirl.advice.oracle import OracleAdvisor

    path = tmp_path / "advice.sqlite"
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute("CREATE TABLE t (x)")
    holder.execute("BEGIN EXCLUSIVE")  # another process in the middle of a long write
    try:
        cached = CachedAdvisor(OracleAdvisor(), path, timeout_s=0.5)
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "going on without it" in err[0] and str(path) in err[0]
    assert cached.disabled and len(cached) == 0
