"""Where work runs: Ray for evaluation episodes and training jobs on more than one machine
(``pirl[distributed]``), and the serial and process-pool executors of training jobs beside it.

``--ray-address ADDR`` on ``pirl evaluate`` and ``pirl reproduce`` lands here. ADDR is

- ``HOST:PORT`` (or ``ray://HOST:PORT``) of a running cluster's head (``ray start --head``),
- ``auto`` for the cluster this machine already belongs to, or
- ``local`` to start a private Ray instance on this machine with ``--workers`` CPUs.

Evaluation: :func:`ray_executor` is an ``executor_factory`` for
:func:`pirl.evaluate.runner.evaluate`; each chunk of episodes becomes one Ray task running the
same :func:`~pirl.evaluate.runner.run_chunk` as the local worker processes, so the numbers are
identical. Training: each job of a reproduction's plan (a run, or a teacher phase) runs
:func:`pirl.reproduce.jobs.train_job`, the same function in this process, in a local process
pool or in a Ray task; :func:`open_executor` opens the one that :class:`ExecutorChoice` names, and
:func:`pirl.reproduce.schedule.run_plan` submits the jobs to it in dependency order.

Every node needs the same ``pirl`` installed, and the output folder must be on a filesystem
that all nodes share at the same path (NFS or similar): workers read and write run folders
there, and run tasks in the driver's working directory, so relative paths mean the same thing.
On a local instance this holds trivially. Secrets such as ``OPENAI_API_KEY`` are not sent to
the cluster: set them in the environment of ``ray start`` on each node (a teacher phase and
the PIRL runs ask their teacher there, so a local model must be there too).

Ray is imported only when one of these functions is called, so ``pirl`` works without it.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import socket
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any, Literal

from pirl import _quiet
from pirl.config.errors import ConfigError

INSTALL_HINT = "install the extra: pip install 'pirl[distributed]'"
ADDRESS_FORMS = "HOST:PORT, ray://HOST:PORT, auto or local"


def import_ray() -> Any:
    """The ``ray`` module, or a ConfigError saying how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise ConfigError(f"--ray-address needs Ray, which is not installed; {INSTALL_HINT}") from (
            exc
        )
    return ray


def check_address(address: str, timeout_s: float = 5.0) -> None:
    """Fail fast on an address that is malformed or where nothing listens.

    Ray itself retries an unreachable head for minutes before giving up.
    """
    if address in ("auto", "local"):
        return
    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        raise ConfigError(f"--ray-address {address!r}: expected {ADDRESS_FORMS}")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as exc:
        raise ConfigError(
            f"--ray-address {address}: cannot reach a Ray cluster there ({exc}); start one with "
            "`ray start --head` or check the address"
        ) from None


@contextlib.contextmanager
def ray_session(address: str, num_cpus: int | None = None) -> Iterator[Any]:
    """Connect to (or, for ``local``, start) Ray for the duration of the block.

    A connection the caller already made (``ray.init`` earlier in this process) is used and
    left open; one made here is shut down at the end. ``num_cpus`` applies to ``local`` only.
    """
    ray = import_ray()
    check_address(address)
    if ray.is_initialized():
        yield ray
        return
    kwargs: dict[str, Any] = {"address": address, "log_to_driver": True}
    if address == "local":
        kwargs.update(num_cpus=num_cpus, include_dashboard=False)
    try:
        ray.init(**kwargs)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise ConfigError(f"--ray-address {address}: could not connect to Ray ({exc})") from None
    try:
        yield ray
    finally:
        ray.shutdown()


def _in_dir(cwd: str, fn: Callable[..., Any], *args: Any) -> Any:
    """Run ``fn`` in the driver's working directory when this node has it (shared storage)."""
    if os.path.isdir(cwd):
        os.chdir(cwd)
    return fn(*args)


class RayExecutor:
    """A ``concurrent.futures``-style executor whose tasks are Ray tasks (1 CPU each).

    ``submit(fn, *args)`` returns a :class:`concurrent.futures.Future`, so the caller can use
    ``as_completed`` exactly as with a process pool. Unfinished tasks are cancelled when the
    block is left through an exception.
    """

    def __init__(self, address: str, workers: int | None = None) -> None:
        self.address = address
        self.workers = workers
        self._stack = contextlib.ExitStack()
        self._ray: Any = None
        self._task: Any = None
        self._refs: list[Any] = []
        self._cwd = os.getcwd()

    def __enter__(self) -> RayExecutor:
        self._ray = self._stack.enter_context(ray_session(self.address, self.workers))
        self._task = self._ray.remote(num_cpus=1)(_in_dir)
        return self

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future:
        return self.submit_ref(fn, *args).future()

    def submit_ref(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Like ``submit`` but returns the Ray ObjectRef; refs among ``args`` are awaited."""
        if self._task is None:
            raise RuntimeError("use RayExecutor in a with-block")
        ref = self._task.remote(self._cwd, fn, *args)
        self._refs.append(ref)
        return ref

    def cpus(self) -> int:
        """The CPUs of the cluster now: how many one-CPU tasks run at once."""
        if self._ray is None:
            raise RuntimeError("use RayExecutor in a with-block")
        return max(1, int(self._ray.cluster_resources().get("CPU", 1)))

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is not None:
            for ref in self._refs:
                with contextlib.suppress(Exception):
                    self._ray.cancel(ref)
        self._stack.close()


def ray_executor(address: str, workers: int) -> RayExecutor:
    """``executor_factory`` for :func:`pirl.evaluate.runner.evaluate`:
    ``functools.partial(ray_executor, address)``."""
    return RayExecutor(address, workers)


# -- where training jobs run ------------------------------------------------------------
Backend = Literal["serial", "processes", "ray"]
"""Where training jobs run: in this process, in a pool of local processes, or on Ray."""


def worker_init() -> None:
    """A training worker's thread budget: one torch thread, one numba thread (set before any
    work), so N workers never run more than N busy threads of their own."""
    os.environ["OMP_NUM_THREADS"] = "1"
    os.environ["MKL_NUM_THREADS"] = "1"
    import numba
    import torch

    torch.set_num_threads(1)
    with contextlib.suppress(RuntimeError):  # already set in this process
        torch.set_num_interop_threads(1)
    numba.set_num_threads(1)
    _quiet.install()
    _quiet.ignore_sigint()  # Ctrl-C is the parent's: one line, no worker tracebacks


class InlineExecutor:
    """The serial executor: a job runs in this process when it is submitted (with its progress
    bar and every core's threads) and its future comes back finished. A job's error is kept in
    its future, as a worker's would be; Ctrl-C during training is no job's failure, so it
    leaves at once."""

    def __enter__(self) -> InlineExecutor:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future:
        from pirl.agents.stops import TrainingInterrupted

        future: Future = Future()
        try:
            future.set_result(fn(*args))
        except TrainingInterrupted:
            raise
        except Exception as exc:  # noqa: BLE001 - the runner reports it as a worker's error
            future.set_exception(exc)
        return future


@dataclass(frozen=True)
class ExecutorChoice:
    """Where a plan's training jobs run."""

    backend: Backend
    """``serial``, ``processes`` or ``ray``."""
    workers: int = 1
    """Worker processes of the pool (``processes`` only; Ray's cluster has its own CPUs)."""
    ray_address: str = ""
    """Ray's address (``ray`` only): HOST:PORT, ray://HOST:PORT, auto or local."""


@contextlib.contextmanager
def open_executor(choice: ExecutorChoice) -> Iterator[tuple[Any, int]]:
    """The executor of ``choice`` and how many jobs it runs at once. Leaving the block by an
    exception (Ctrl-C) stops what it runs: a pool's workers are stopped by the caller's Ctrl-C
    handler, Ray's unfinished tasks are cancelled."""
    if choice.backend == "serial":
        yield InlineExecutor(), 1
    elif choice.backend == "processes":
        # spawn: workers must not inherit the parent's threads (torch, an LLM, numba).
        ctx = mp.get_context("spawn")
        with _quiet.QuietProcessPool(
            choice.workers, mp_context=ctx, initializer=worker_init
        ) as pool:
            yield pool, choice.workers
    else:
        with RayExecutor(choice.ray_address) as pool:
            yield pool, pool.cpus()
