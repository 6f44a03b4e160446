"""Any advisor in a child process of its own.

An LLM that shares the training process competes with PPO for the interpreter lock (the
token loop and constrained decoding run Python between tensor calls) and for PyTorch's
process-wide thread count. In a child process it gets its own interpreter and threads: on two
cores, PPO keeps one and the LLM the other.

The child builds the advisor itself from a picklable factory (nothing is loaded twice), then
answers ``advise`` requests over a pipe. If the child dies, every later call answers with an
error (PARE counts it as failed), never an exception.
"""

from __future__ import annotations

import multiprocessing as mp
import threading
from collections.abc import Callable, Sequence
from typing import Any

from pirl.advice.base import Advisor, Answer, error_answer


def _serve(conn: Any, factory: Callable[[], Advisor], threads: int | None) -> None:
    """The child: build the advisor, say who it is, then answer until told to stop."""
    from pirl import _quiet

    _quiet.install()  # the parent's filters do not reach a spawned child
    _quiet.ignore_sigint()  # Ctrl-C is the parent's: it closes this child (no traceback here)
    if threads:
        import torch

        torch.set_num_threads(threads)
    try:
        advisor = factory()
    except BaseException as exc:  # noqa: BLE001 - reported to the parent as one line
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    conn.send(
        (
            "ready",
            {
                "name": advisor.name,
                "model": advisor.model,
                "label": advisor.label,
                "wants_view": advisor.wants_view,
                "settings_key": advisor.settings_key(),
                "base_url": getattr(advisor, "base_url", None),
                "model_dir": str(getattr(advisor, "model_dir", "")) or None,
            },
        )
    )
    while True:
        try:
            message = conn.recv()
        except EOFError:
            break
        if message[0] == "close":
            break
        _, prompts, views = message
        try:
            answers = advisor.advise(prompts, views)
        except Exception as exc:  # noqa: BLE001 - an advisor must not raise
            answers = [error_answer(f"{type(exc).__name__}: {exc}") for _ in prompts]
        conn.send(answers)
    advisor.close()


class ProcessAdvisor(Advisor):
    """Runs ``factory()``'s advisor in a child process (spawned, so it is safe with threads).

    Arguments:
        factory: a picklable callable that builds the advisor (e.g. a ``functools.partial``).
        threads: PyTorch threads in the child (``None``: leave the default).
        start_timeout_s: longest wait for the child to load its model.
    """

    def __init__(
        self,
        factory: Callable[[], Advisor],
        threads: int | None = None,
        start_timeout_s: float = 600.0,
    ) -> None:
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_serve, args=(child, factory, threads), daemon=True, name="pirl-advisor"
        )
        self._proc.start()
        child.close()
        self._lock = threading.Lock()
        if not self._conn.poll(start_timeout_s):
            self._proc.kill()
            raise OSError(f"the advisor process did not start within {start_timeout_s:g} s")
        try:
            kind, info = self._conn.recv()
        except EOFError:
            raise OSError("the advisor process died while loading its model") from None
        if kind == "error":
            self._proc.join(timeout=10)
            raise OSError(info)
        self.name, self.model, self.label = info["name"], info["model"], info["label"]
        self.wants_view = info["wants_view"]
        self._settings = info["settings_key"]
        self.base_url = info["base_url"]
        if info["model_dir"]:
            self.model_dir = info["model_dir"]

    def settings_key(self) -> str:
        return self._settings

    def advise(self, prompts: list[str], views: Sequence[Any] | None = None) -> list[Answer]:
        """The child's answers; error answers if it has died."""
        if not prompts:
            return []
        with self._lock:
            try:
                self._conn.send(("advise", list(prompts), list(views) if views else None))
                return list(self._conn.recv())
            except (EOFError, OSError, BrokenPipeError) as exc:
                code = self._proc.exitcode
                why = f"advisor process ended (exit code {code})" if code is not None else str(exc)
                return [error_answer(why) for _ in prompts]

    def close(self) -> None:
        """Stop the child (safe to call twice)."""
        if self._proc.is_alive():
            # A call stuck past its deadline (a hung child) holds the lock: do not wait on it.
            if self._lock.acquire(timeout=5):
                try:
                    self._conn.send(("close",))
                except (OSError, BrokenPipeError):
                    pass
                finally:
                    self._lock.release()
                self._proc.join(timeout=30)
            if self._proc.is_alive():
                self._proc.kill()
        self._conn.close()


__all__ = ["ProcessAdvisor"]
