"""Silence third-party noise in our processes; our own progress lines stay.

What it hides: transformers' ``past_key_values`` deprecation (a FutureWarning and a logger
line per load) and its ``Loading weights`` bars, pytorch-tabnet's ``Device used : cpu`` and
``Best weights ...`` warnings (and its scipy deprecation), and PyBullet's build-time banner
(written to stderr by the C module at import). Errors still show.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import signal
import sys
import threading
import warnings
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from types import ModuleType

_WARNINGS = (
    (FutureWarning, r".*past_key_values.*"),
    (UserWarning, r"Device used : "),
    (UserWarning, r"Best weights from best epoch"),
    (DeprecationWarning, r".*scipy\.sparse.*"),
)


def install() -> None:
    """Call early (before transformers is imported where possible); safe to call again."""
    os.environ.setdefault("HF_HUB_DISABLE_PROGRESS_BARS", "1")
    # Plain tqdm bars of third-party code (transformers' GGUF conversion); ours use rich.
    os.environ.setdefault("TQDM_DISABLE", "1")
    os.environ.setdefault("TRANSFORMERS_VERBOSITY", "error")
    os.environ.setdefault("TRANSFORMERS_NO_ADVISORY_WARNINGS", "1")
    for category, message in _WARNINGS:
        warnings.filterwarnings("ignore", message=message, category=category)
    if "transformers" in sys.modules:  # imported already: switch its logging off directly
        from transformers.utils import logging as hf_logging

        hf_logging.set_verbosity_error()
        hf_logging.disable_progress_bar()


@contextlib.contextmanager
def stderr_to_devnull() -> Iterator[None]:
    """Send file descriptor 2 to /dev/null (C libraries write there directly)."""
    sys.stderr.flush()
    saved = os.dup(2)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


def import_quietly(name: str) -> ModuleType:
    """Import a module whose import prints a banner (pybullet)."""
    if name in sys.modules:
        return sys.modules[name]
    with stderr_to_devnull():
        return importlib.import_module(name)


class QuietProcessPool(ProcessPoolExecutor):
    """A ``ProcessPoolExecutor`` whose workers ignore Ctrl-C from their first instruction.

    Workers are started with SIGINT ignored in the parent for that moment: an ignored signal
    stays ignored across ``exec``, so a Ctrl-C that lands while a spawned worker is still
    importing prints no traceback (an initializer runs too late for that). Ctrl-C is the
    parent's to handle: it stops the workers and says in one line what was kept.
    """

    def _adjust_process_count(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            super()._adjust_process_count()  # type: ignore[misc]
            return
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            super()._adjust_process_count()  # type: ignore[misc]
        finally:
            signal.signal(signal.SIGINT, old)


def ignore_sigint() -> None:
    """In a worker process: leave Ctrl-C to the parent, which stops its workers and says in
    one line what was kept (instead of one ``KeyboardInterrupt`` traceback per worker)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
