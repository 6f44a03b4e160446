"""Ray: evaluation episodes and training runs on more than one machine (``pirl[distributed]``).

``--ray-address ADDR`` on ``pirl evaluate`` and ``pirl reproduce`` lands here. ADDR is

- ``HOST:PORT`` (or ``ray://HOST:PORT``) of a running cluster's head (``ray start --head``),
- ``auto`` for the cluster this machine already belongs to, or
- ``local`` to start a private Ray instance on this machine with ``--workers`` CPUs.

Evaluation: :func:`ray_executor` is an ``executor_factory`` for
:func:`pirl.evaluate.runner.evaluate`; each chunk of episodes becomes one Ray task running the
same :func:`~pirl.evaluate.runner.run_chunk` as the local worker processes, so the numbers are
identical. Training: :func:`train_on_ray` runs one task per method x seed, calling the same
``train``/``train_il`` with the same arguments as the sequential loop; an IL run waits for its
PPO-EWRI expert.

Every node needs the same ``pirl`` installed, and the output folder must be on a filesystem
that all nodes share at the same path (NFS or similar): workers read and write run folders
there, and run tasks in the driver's working directory, so relative paths mean the same thing.
On a local instance this holds trivially. Secrets such as ``OPENAI_API_KEY`` are not sent to
the cluster: set them in the environment of ``ray start`` on each node.

Ray is imported only when one of these functions is called, so ``pirl`` works without it.
"""

from __future__ import annotations

import contextlib
import os
import socket
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, as_completed
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from pirl.config.errors import ConfigError

if TYPE_CHECKING:
    from pirl.config.run import RunConfig

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


# -- training -------------------------------------------------------------------------------
class TrainJob(NamedTuple):
    """One run of :func:`pirl.evaluate.reproduce.train_all`'s plan."""

    name: str
    method: str
    advisor: str
    seed: int
    run: Path
    resume: bool
    pare: tuple[tuple[str, Any], ...] = ()


def _train_job(job: TrainJob, cfg: RunConfig, *expert_done: Any) -> float:
    """Remote side: the same call as the sequential loop makes. ``expert_done`` only orders."""
    from pirl.agents.runs import train_one

    start = time.perf_counter()
    train_one(job.method, job.advisor, job.seed, cfg, job.run, job.resume, False, dict(job.pare))
    return time.perf_counter() - start


def train_on_ray(
    address: str,
    cfg: RunConfig,
    jobs: list[TrainJob],
    log: Callable[[str], None],
    workers: int | None = None,
) -> None:
    """Run ``jobs`` in parallel on Ray; an imitation job (IL) starts once its expert's run
    (PPO-EWRI) has finished.

    Every job runs to its end even when another fails (finished runs are kept, so a second
    reproduction resumes); then the first failure is raised.
    """
    from pirl.agents.methods import trained_method

    if not jobs:
        return
    jobs = [job._replace(run=Path(job.run).resolve()) for job in jobs]
    with RayExecutor(address, workers) as pool:
        refs: dict[str, Any] = {}
        futures: dict[Future, TrainJob] = {}
        for job in sorted(jobs, key=lambda j: bool(trained_method(j.method).expert)):
            entry = trained_method(job.method)  # an imitation run waits for its expert's
            after = refs.get(entry.expert_folder(job.seed)) if entry.expert else None
            refs[job.name] = pool.submit_ref(
                _train_job, job, cfg, *([after] if after is not None else [])
            )
            futures[refs[job.name].future()] = job
        log(f"ray: {len(jobs)} training runs submitted to {address}")
        failure: BaseException | None = None
        for future in as_completed(futures):
            job = futures[future]
            try:
                seconds = future.result()
            except Exception as exc:
                log(f"{job.name}: failed on Ray ({type(exc).__name__})")
                failure = failure or exc
                continue
            log(f"{job.name}: done in {seconds:.0f} s")
        if failure is not None:
            raise failure
