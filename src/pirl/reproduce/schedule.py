"""The scheduler of ``pirl reproduce``: the plan's training jobs run in dependency order.

:func:`executor_for` picks where the jobs of a :class:`~pirl.reproduce.plan.Plan` run (this
process, a pool of processes or Ray, :class:`~pirl.evaluate.executors.ExecutorChoice`);
:func:`run_plan` starts each job once the jobs it waits for have ended (a teacher phase before
its PIRL runs, an expert's run before its IL run), with one dependency order for all three.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass, field, replace

from pirl.evaluate.executors import ExecutorChoice, open_executor
from pirl.reproduce.jobs import TEACHER, TrainJob, train_job
from pirl.reproduce.plan import Log, Plan


def executor_for(plan: Plan, ray_address: str | None = None) -> ExecutorChoice:
    """Ray at ``ray_address`` when given, else ``plan.train_workers`` processes (never more
    than there are jobs), else this process."""
    if ray_address:
        return ExecutorChoice("ray", ray_address=ray_address)
    workers = max(1, min(plan.train_workers, len(plan.jobs)))
    return ExecutorChoice("serial") if workers == 1 else ExecutorChoice("processes", workers)


@dataclass
class _Board:
    """The runner's bookkeeping."""

    waiting: list[TrainJob]
    """Jobs not started yet, in plan order."""
    running: dict[Future, TrainJob] = field(default_factory=dict)
    """Jobs submitted and not ended, by their future."""
    ended: dict[str, bool] = field(default_factory=dict)
    """Jobs that ended, by name: True when they succeeded."""
    failure: BaseException | None = None
    """The first failure of a run, raised once every job has ended."""

    def next_ready(self) -> TrainJob | None:
        """The first waiting job whose every prerequisite has ended; a prerequisite that is
        not among the jobs was finished before this reproduction."""
        planned = {job.name for job in self.waiting} | {j.name for j in self.running.values()}
        for job in self.waiting:
            if all(name in self.ended or name not in planned for name in job.after):
                return job
        return None


def run_plan(
    plan: Plan, choice: ExecutorChoice, log: Log = print, show_progress: bool = False
) -> None:
    """Train the plan's jobs with the executor ``choice`` names.

    A job starts once the jobs it waits for have ended (a teacher phase before its PIRL runs,
    an expert's run before its IL run), and no more start than the executor runs at once, so
    a job says ``training`` when it really starts. Every job runs to its end even when another
    fails (finished runs are kept, so the next reproduction resumes); then the first failure
    of a run is raised. ``show_progress``: the progress bar of a run trained in this process.
    """
    (plan.out / "runs").mkdir(parents=True, exist_ok=True)
    if not plan.jobs:
        return
    board = _Board(list(plan.jobs))
    cfg_dict = plan.cfg.to_dict()
    bar = show_progress and choice.backend == "serial"  # a worker's bar would garble the log
    with open_executor(choice) as (pool, slots):
        if line := _announce(plan, choice, slots):
            log(line)

        def submit(job: TrainJob) -> Future:
            if choice.backend == "ray" and job.run is not None:
                # A Ray worker may start elsewhere: the folder must not depend on the cwd.
                job = replace(job, run=job.run.resolve())
            return pool.submit(train_job, job, cfg_dict, bar)

        while board.waiting or board.running:
            _start_ready(board, slots, submit, log)
            _collect(board, log)
    if board.failure is not None:
        raise board.failure


def _start_ready(board: _Board, slots: int, submit: Callable[[TrainJob], Future], log: Log) -> None:
    """Start ready jobs while the executor has a free slot; a job whose expert failed is not
    trained."""
    while len(board.running) < slots and (job := board.next_ready()) is not None:
        board.waiting.remove(job)
        if board.ended.get(job.expert) is False:
            log(f"{job.name}: not trained (its expert failed)")
            board.ended[job.name] = False
            continue
        _started(job, log)  # before submit: the serial executor runs the job right there
        board.running[submit(job)] = job


def _announce(plan: Plan, choice: ExecutorChoice, slots: int) -> str:
    """The runner's first line: where the jobs run."""
    runs = len(plan.jobs) - len(plan.phases)
    if choice.backend == "processes":
        return f"training {runs} runs in {slots} worker processes (1 torch + 1 numba thread each)"
    if choice.backend == "ray":
        return f"ray: training {runs} runs on {choice.ray_address}, {slots} at a time"
    return ""


def _started(job: TrainJob, log: Log) -> None:
    """Say that ``job`` started; a broken folder (nothing to resume) is removed first."""
    if job.method == TEACHER:
        log(f"{job.name}: asking the {job.advisor} teacher")
        return
    if job.state == "broken" and job.run is not None:
        log(f"{job.name}: incomplete with no checkpoint; starting again")
        shutil.rmtree(job.run)
    log(f"{job.name}: {'resuming' if job.resume else 'training'}")


def _collect(board: _Board, log: Log) -> None:
    """Wait for a running job to end and record how it ended."""
    if not board.running:
        if board.waiting:  # nothing runs and nothing is ready: jobs wait for each other
            names = ", ".join(job.name for job in board.waiting)
            raise RuntimeError(f"training jobs wait for each other: {names}")
        return  # the last jobs were not trained (their expert failed)
    done, _ = wait(board.running, return_when=FIRST_COMPLETED)
    for future in done:
        job = board.running.pop(future)
        try:
            seconds, note = future.result()
        except Exception as exc:  # noqa: BLE001 - reported, raised once every job has ended
            log(f"{job.name}: failed ({type(exc).__name__}: {exc})")
            board.ended[job.name] = False
            if job.method != TEACHER:  # a failed head start only slows PIRL down
                board.failure = board.failure or exc
            continue
        if note:
            log(note)
        log(f"{job.name}: done in {seconds:.0f} s")
        board.ended[job.name] = True
