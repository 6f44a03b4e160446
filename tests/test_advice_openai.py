"""OpenAIAdvisor against a real OpenAI-compatible server: ``transformers serve`` on loopback,
serving the converted embedded model; plus dropped, refused, hanging and failing connections.
"""

from __future__ import annotations

import json
import logging
import os
import pickle
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from pirl.advice import PromptState, build_prompt
from pirl.advice.model_store import resolve_model_dir
from pirl.advice.openai_advisor import OpenAIAdvisor

SECRET = "sk-test-DoNotLeak0123456789"
STATE = PromptState(
    position=(3, 4, 1),
    tilt=90,
    pan=0,
    zoom=1.0,
    battery=0.8,
    coverage=0.1,
    size=(15, 15, 3),
    obstacles=((5.0, 5.0, 1.0, 1.5),),
)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def serve_command(model_dir: Path, port: int) -> list[str]:
    exe = Path(sys.executable).with_name("transformers")
    prefix = [str(exe)] if exe.exists() else [shutil.which("transformers") or "transformers"]
    return [*prefix, "serve", "--host", "127.0.0.1", "--port", str(port), str(model_dir)]


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    """A ``transformers serve`` process for the converted model, ready, on a free port."""
    model_dir = resolve_model_dir()
    port = free_port()
    log_path = tmp_path_factory.mktemp("serve") / "serve.log"
    env = dict(os.environ, HF_HUB_OFFLINE="1", OMP_NUM_THREADS="1", TOKENIZERS_PARALLELISM="0")
    with open(log_path, "w") as log:
        proc = subprocess.Popen(
            serve_command(model_dir, port), stdout=log, stderr=subprocess.STDOUT, env=env
        )
    deadline = time.monotonic() + 120
    while True:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=2) as r:
                if r.status == 200:
                    break
        except OSError:
            pass
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"transformers serve did not start:\n{log_path.read_text()[-3000:]}")
        time.sleep(0.25)
    yield {"proc": proc, "port": port, "model": str(model_dir), "log": log_path}
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def make_advisor(port: int, model: str = "m", **kwargs) -> OpenAIAdvisor:
    kwargs.setdefault("max_tokens", 8)
    kwargs.setdefault("timeout_s", 60.0)
    return OpenAIAdvisor(model, base_url=f"http://127.0.0.1:{port}/v1", **kwargs)


def test_answers_from_transformers_serve(server: dict, monkeypatch, caplog) -> None:
    monkeypatch.setenv("OPENAI_API_KEY", SECRET)
    caplog.set_level(logging.DEBUG)
    adv = make_advisor(server["port"], server["model"], concurrency=2)
    prompts = [build_prompt(STATE, "compact"), build_prompt(STATE, "paper")]
    answers = adv.advise(prompts)
    assert len(answers) == 2
    for a in answers:
        assert a.error is None, a.error
        assert a.text  # the unconstrained 135M model rarely keeps the format: not asserted
        assert a.prompt_tokens > 100 and 0 < a.completion_tokens <= 8
        assert a.latency_s > 0 and not a.from_cache
    assert answers[0].prompt_tokens < answers[1].prompt_tokens  # order kept
    assert SECRET not in caplog.text
    adv.close()


def test_key_is_never_shown_or_pickled(server: dict, monkeypatch) -> None:
    monkeypatch.setenv("PIRL_TEST_KEY", SECRET)
    adv = make_advisor(server["port"], server["model"], api_key_env="PIRL_TEST_KEY")
    assert adv.client.api_key == SECRET  # it is used...
    assert SECRET not in repr(adv) and SECRET not in str(adv.__dict__.keys())
    data = pickle.dumps(adv)
    assert SECRET.encode() not in data  # ...but never saved
    clone = pickle.loads(data)
    assert clone.client.api_key == SECRET  # rebuilt from the environment


def test_missing_key(monkeypatch) -> None:
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    with pytest.raises(ValueError, match="OPENAI_API_KEY"):
        OpenAIAdvisor()
    adv = OpenAIAdvisor("m", base_url="http://127.0.0.1:1/v1")
    assert adv.client.api_key == "not-needed"
    assert adv.label == "openai:m@127.0.0.1:1"
    assert OpenAIAdvisor.name == "openai" and adv.model == "m"


def test_settings_key() -> None:
    a = OpenAIAdvisor("m", base_url="http://127.0.0.1:1/v1", temperature=0.0)
    b = OpenAIAdvisor("m", base_url="http://127.0.0.1:1/v1", temperature=0.7)
    c = OpenAIAdvisor("m", base_url="http://127.0.0.1:1/v1", timeout_s=3, concurrency=9)
    assert a.settings_key() != b.settings_key()
    assert a.settings_key() == c.settings_key()  # transport settings do not change answers


def test_refused_connection_gives_errors_quickly() -> None:
    adv = make_advisor(free_port(), max_retries=2, backoff_s=0.05, timeout_s=5)
    started = time.monotonic()
    answers = adv.advise(["a", "b", "c"])
    assert time.monotonic() - started < 5
    assert all(a.recommendation is None and "APIConnectionError" in a.error for a in answers)
    assert all("3 attempt" in a.error for a in answers)


def test_hanging_server_times_out() -> None:
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)  # accepts connections, never answers
    try:
        adv = make_advisor(listener.getsockname()[1], timeout_s=0.5, max_retries=1, backoff_s=0.05)
        started = time.monotonic()
        answers = adv.advise(["a", "b"])
        elapsed = time.monotonic() - started
    finally:
        listener.close()
    assert elapsed < 4  # two attempts of 0.5 s, concurrently
    assert all("Timeout" in a.error for a in answers)


class _StatusServer:
    """A loopback HTTP server answering every POST with one status code (and echoing the
    Authorization header in the error message, to check that keys are masked)."""

    def __init__(self, status: int, retry_after: str | None = None) -> None:
        self.hits = 0
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802
                outer.hits += 1
                self.rfile.read(int(self.headers.get("content-length", 0)))
                body = json.dumps(
                    {"error": {"message": f"no: {self.headers.get('authorization')}"}}
                ).encode()
                self.send_response(status)
                if retry_after is not None:
                    self.send_header("retry-after", retry_after)
                self.send_header("content-type", "application/json")
                self.send_header("content-length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args) -> None:
                pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.port = self.httpd.server_address[1]
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)

    def __enter__(self) -> _StatusServer:
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


@pytest.mark.parametrize(
    ("status", "retried", "kind"),
    [
        (503, True, "InternalServerError"),
        (500, True, "InternalServerError"),
        (429, True, "RateLimitError"),
        (400, False, "BadRequestError"),
        (401, False, "AuthenticationError"),
    ],
)
def test_retries_only_what_can_succeed_later(monkeypatch, status, retried, kind) -> None:
    monkeypatch.setenv("OPENAI_API_KEY", SECRET)
    with _StatusServer(status, retry_after="0") as srv:
        adv = make_advisor(srv.port, max_retries=2, backoff_s=0.01, concurrency=1)
        answers = adv.advise(["a"])
    assert srv.hits == (3 if retried else 1)
    assert kind in answers[0].error and str(status) in answers[0].error
    assert SECRET not in answers[0].error and "DoNotLeak" not in answers[0].error


def test_backoff_grows_and_honours_retry_after() -> None:
    adv = OpenAIAdvisor("m", base_url="http://127.0.0.1:1/v1", backoff_s=0.5, max_backoff_s=3)
    delays = [adv._delay(k, RuntimeError()) for k in range(5)]
    assert 0.5 <= delays[0] <= 0.55 and 1.0 <= delays[1] <= 1.1 and 2.0 <= delays[2] <= 2.2
    assert all(d <= 3.3 for d in delays)
    with _StatusServer(429, retry_after="2") as srv:
        adv = make_advisor(srv.port, max_retries=1, backoff_s=0.01, max_backoff_s=0.2)
        started = time.monotonic()
        adv.advise(["a"])
        assert 0.2 <= time.monotonic() - started < 2  # Retry-After capped by max_backoff_s


def test_killed_server_gives_errors_not_exceptions(server: dict) -> None:
    """Last in this file: kills the shared server while a request is in flight."""
    adv = make_advisor(
        server["port"], server["model"], max_tokens=400, timeout_s=60, max_retries=1,
        backoff_s=0.05,
    )  # fmt: skip
    result: dict = {}
    thread = threading.Thread(target=lambda: result.update(a=adv.advise(["Tell a long story."])))
    started = time.monotonic()
    thread.start()
    time.sleep(1.5)
    server["proc"].send_signal(signal.SIGKILL)
    server["proc"].wait(timeout=10)
    thread.join(timeout=30)
    assert not thread.is_alive()
    assert time.monotonic() - started < 30
    (answer,) = result["a"]
    assert answer.recommendation is None and "APIConnectionError" in answer.error
    # And afterwards, with the port closed:
    answers = adv.advise(["a", "b"])
    assert all(a.error and a.recommendation is None for a in answers)
