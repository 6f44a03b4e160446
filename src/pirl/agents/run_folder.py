"""Run folders: what a run writes, the one reader of those files, creating one without
overwriting, resuming, and the lock that keeps one writer per folder.

:class:`RunFolder` is the only code that knows a run's layout; training (PPO in
:mod:`pirl.agents.train`, TabNet in :mod:`pirl.agents.imitation`), loading, evaluation and
``pirl reproduce`` all read and write a run through it.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import yaml
from filelock import FileLock, Timeout

from pirl._atomic import write_json
from pirl.agents import checkpoint
from pirl.agents.methods import IMITATION_ARTIFACT, METHODS, PPO_ARTIFACT
from pirl.agents.methods import method as method_entry
from pirl.config.errors import ConfigError, UserError
from pirl.config.run import RunConfig


def train_seed_base(seed: int) -> int:
    """World i of a run with ``seed`` starts from scenario seed ``base + i``.

    Evaluation scenario seeds start at 10**9, so training never sees them.
    """
    return 1_000 * seed


LOCK_NAME = ".pirl.lock"
"""The lock file in a run or output folder; it holds the writing process's PID."""
_HELD: dict[tuple[int, str], FileLock] = {}  # (pid, folder) -> the lock this process holds


class FolderBusy(ConfigError):
    """Another live process writes to the folder (exit code 2, like every user mistake)."""


def _stamp_pid(fd: int) -> None:
    """Write this process's PID into the lock file it now holds, for a refused writer's message."""
    os.ftruncate(fd, 0)
    os.lseek(fd, 0, os.SEEK_SET)
    os.write(fd, f"{os.getpid()}\n".encode())


def lock_folder(folder: Path, what: str = "run folder") -> None:
    """Become the one writer of ``folder`` (which must exist) until this process ends or
    :func:`release_folder`; raise :class:`FolderBusy` naming the holder's PID otherwise.

    A native :class:`filelock.FileLock` (``flock``) on ``folder/.pirl.lock``: the kernel drops
    the lock when its holder dies, so a run killed with ``kill -9`` never leaves a stale lock.
    Taking it again in the same process is a no-op.
    """
    key = (os.getpid(), str(Path(folder).resolve()))
    if key in _HELD:
        return
    path = Path(folder) / LOCK_NAME
    # preserve_lock_file and on_acquired also refuse filelock's soft (PID file) fallback, which
    # a kill -9 would leave behind as a stale lock.
    lock = FileLock(path, mode=0o644, thread_local=False, preserve_lock_file=True,
                    on_acquired=_stamp_pid)  # fmt: skip
    try:
        lock.acquire(timeout=0)
    except Timeout:
        try:
            holder = path.read_text(errors="replace").strip() or "unknown"
        except OSError:
            holder = "unknown"
        raise FolderBusy(
            f"{what} {folder} is in use by another pirl process (PID {holder}); wait for it "
            "to end (or stop it), or choose another --out"
        ) from None
    _HELD[key] = lock


def release_folder(folder: Path) -> None:
    """Give up the lock this process holds on ``folder`` (if any)."""
    lock = _HELD.pop((os.getpid(), str(Path(folder).resolve())), None)
    if lock is not None:
        lock.release(force=True)


@contextlib.contextmanager
def folder_lock(folder: Path, what: str = "output folder") -> Iterator[None]:
    """Hold ``folder``'s lock for a block, creating the folder if needed; a folder made here
    that holds nothing but the lock at the end is removed (a refused command leaves nothing)."""
    folder = Path(folder)
    made = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    lock_folder(folder, what)
    try:
        yield
    finally:
        release_folder(folder)
        if made and [p.name for p in folder.iterdir()] == [LOCK_NAME]:
            with contextlib.suppress(OSError):
                (folder / LOCK_NAME).unlink()
                folder.rmdir()


def folder_contents(folder: Path) -> list[Path]:
    """What a folder holds besides its lock file (empty when it does not exist)."""
    if not Path(folder).is_dir():
        return []
    return sorted(p for p in Path(folder).iterdir() if p.name != LOCK_NAME)


def prepare_run_folder(out: Path, resume: bool, log: Any = None) -> tuple[Path, dict] | None:
    """Create ``out`` for a new run, or return the checkpoint to resume from and its state.

    A folder that exists without ``resume`` is an error: runs are never overwritten. A run
    stopped before its first checkpoint resumes from step 0 (None); a damaged latest
    checkpoint falls back to the previous complete one. Either way this process becomes the
    folder's one writer (:func:`lock_folder`).
    """
    if resume:
        if not out.is_dir():
            raise ConfigError(f"--resume: run folder {out} does not exist")
        lock_folder(out)  # before reading checkpoints: nobody else may be writing them
        found = checkpoint.load_latest(out / "checkpoints", log)
        if found is None and log is not None:
            log(f"resume: no complete checkpoint in {out / 'checkpoints'}; starting from step 0")
        return found
    if out.exists() and never_saved(out):
        # A run that failed before its first checkpoint saved nothing: start it again here.
        lock_folder(out)
        for path in folder_contents(out):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()
        if log is not None:
            log(f"{out} holds a run that stopped before its first checkpoint; starting it again")
        return None
    if out.exists():
        raise ConfigError(
            f"run folder {out} already exists; pass --resume to continue it or choose --out"
        )
    try:
        out.mkdir(parents=True)
    except FileExistsError:  # another process made it since the check above
        raise ConfigError(
            f"run folder {out} already exists; pass --resume to continue it or choose --out"
        ) from None
    lock_folder(out)
    return None


_RUN_FILES = {"config.yaml", "meta.json", "episodes.csv", "tb", "checkpoints", LOCK_NAME}


def never_saved(out: Path) -> bool:
    """Whether ``out`` is a folder that holds nothing a run saved: empty, or the first files
    of a run that stopped before its first checkpoint (no checkpoint, no model, not complete)."""
    out = Path(out)
    if not out.is_dir():
        return False
    names = {p.name for p in out.iterdir()}
    if not names <= _RUN_FILES:
        return False
    if checkpoint.latest(out / "checkpoints") is not None or any(
        (out / "checkpoints").glob("step_*")
    ):
        return False
    try:
        meta = json.loads((out / "meta.json").read_text()) if "meta.json" in names else {}
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and not meta.get("complete")


def git_commit() -> str:
    """The code's git commit (with '-dirty' when modified), or 'unknown'."""
    root = Path(__file__).resolve().parents[3]
    try:
        sha = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, timeout=10,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (sha + ("-dirty" if dirty else "")) if sha else "unknown"


_RESUME_STOP = "; resume takes the run's own settings (leave the option out) or choose a new --out"
RETRAIN = "train the run again into a new --out (or restore the file from a copy)"
"""What a message about a damaged run file tells the user to do."""


def short_error(exc: BaseException) -> str:
    """The first line of an exception's message, at most 160 characters."""
    text = str(exc).strip().splitlines()
    return text[0][:160] if text else type(exc).__name__


@dataclass(frozen=True)
class RunFolder:
    """One training run's folder, and the only reader and writer of its files.

    Layout:

    - ``config.yaml``: the resolved :class:`~pirl.config.run.RunConfig` the run trains with
      (the env section as the method trains on it);
    - ``meta.json``: method, label, seed, git commit, advisor label, ``complete``,
      ``total_steps`` (whole rollouts) and, once complete, ``timesteps``;
    - ``episodes.csv``: one row per finished training episode;
    - ``advisor_stats.json``: an advised run's PARE and advisor counts;
    - the method's artifact (``model.zip``, or ``tabnet.zip`` for imitation);
    - ``checkpoints/`` and ``tb/`` (TensorBoard).

    Reading never caches: a run that is still training is read as it is now.
    """

    path: Path

    CONFIG = "config.yaml"
    META = "meta.json"
    EPISODES = "episodes.csv"
    ADVISOR_STATS = "advisor_stats.json"
    CHECKPOINTS = "checkpoints"
    TENSORBOARD = "tb"

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))

    # -- layout ---------------------------------------------------------------------------
    @property
    def config_file(self) -> Path:
        return self.path / self.CONFIG

    @property
    def meta_file(self) -> Path:
        return self.path / self.META

    @property
    def episodes_file(self) -> Path:
        return self.path / self.EPISODES

    @property
    def advisor_stats_file(self) -> Path:
        return self.path / self.ADVISOR_STATS

    @property
    def checkpoints(self) -> Path:
        return self.path / self.CHECKPOINTS

    @property
    def tensorboard(self) -> Path:
        return self.path / self.TENSORBOARD

    # -- reading --------------------------------------------------------------------------
    @property
    def meta(self) -> dict[str, Any]:
        """``meta.json`` ({} while the run has not recorded one); a damaged file is a
        :class:`UserError`."""
        if not self.meta_file.is_file():
            return {}
        try:
            meta = json.loads(self.meta_file.read_text())
        except (ValueError, OSError) as exc:
            raise UserError(
                f"{self.meta_file} is damaged ({short_error(exc)}); {RETRAIN}"
            ) from None
        if not isinstance(meta, dict):
            raise UserError(f"{self.meta_file} is damaged (not a mapping); {RETRAIN}")
        return meta

    def finished_meta(self) -> dict[str, Any]:
        """``meta.json`` of a finished run; a folder that is not a run, or one still
        training, is refused in one line."""
        if not self.meta_file.is_file():
            raise ConfigError(f"{self.path} is not a run folder (no meta.json)")
        meta = self.meta
        if "method" not in meta:
            raise UserError(f"{self.meta_file} names no method; {RETRAIN}")
        if not meta.get("complete"):
            raise ConfigError(f"run {self.path} is not finished; continue it with --resume")
        return meta

    @property
    def method(self) -> str:
        """The method a finished run holds."""
        return str(self.finished_meta()["method"])

    @property
    def seed(self) -> int:
        """The seed the run trains with (0 when it records none or cannot be read)."""
        try:
            return int(self.meta.get("seed") or 0)
        except (UserError, TypeError, ValueError):
            return 0

    @property
    def has_config(self) -> bool:
        return self.config_file.is_file()

    @property
    def config(self) -> RunConfig:
        """The run's own config (a missing or invalid file is one-line :class:`ConfigError`)."""
        try:
            return RunConfig.from_yaml(self.config_file)
        except ConfigError as exc:
            raise UserError(f"run {self.path}: {exc}") from None

    @property
    def judged_config(self) -> RunConfig:
        """The run's config as an evaluation of it starts from: the reward it trained with
        does not change the scenarios, and a run trained on a site is judged on the sizes and
        sites an evaluation asks for, not on its own."""
        cfg = self.config
        env = cfg.env.replace(reward="static", llm_weight=False, site="", ground_cells=0)
        return replace(cfg, env=env)

    @property
    def masked(self) -> bool:
        """Whether the run trains with valid-action masks (False for a run without a config:
        runs made before masking existed did not)."""
        return self.has_config and self.config.ppo.action_masking

    @property
    def advisor(self) -> str:
        """The advisor the run's config names ("" without a config)."""
        return self.config.pare.advisor if self.has_config else ""

    @property
    def advisor_stats(self) -> dict[str, Any] | None:
        """``advisor_stats.json`` (None when the run wrote none); a damaged file is a
        :class:`UserError`."""
        if not self.advisor_stats_file.is_file():
            return None
        try:
            stats = json.loads(self.advisor_stats_file.read_text())
        except (ValueError, OSError) as exc:
            raise UserError(
                f"{self.advisor_stats_file} is damaged ({short_error(exc)}); {RETRAIN}"
            ) from None
        if not isinstance(stats, dict):
            raise UserError(f"{self.advisor_stats_file} is damaged (not a mapping); {RETRAIN}")
        return stats

    @property
    def artifact(self) -> Path:
        """Where the finished policy is (the method's artifact; unchecked)."""
        return self.path / method_entry(self.method).artifact

    def model_file(self) -> Path:
        """The policy file of a finished run, checked to be a whole zip archive (cheap: no
        torch)."""
        path = self.artifact
        if not path.is_file():
            raise UserError(f"run {self.path} has no {path.name}; {RETRAIN}")
        try:
            with zipfile.ZipFile(path) as archive:
                bad = archive.testzip()
        except (zipfile.BadZipFile, OSError, EOFError) as exc:
            raise UserError(f"{path} is damaged ({short_error(exc)}); {RETRAIN}") from None
        if bad is not None:
            raise UserError(f"{path} is damaged (member {bad} fails its checksum); {RETRAIN}")
        return path

    def finished_steps(self) -> int | None:
        """Steps of the finished model, or None while the run is not complete."""
        try:
            meta = self.meta
        except UserError:
            return None
        entry = METHODS.get(str(meta.get("method")))
        if meta.get("complete") and entry and (self.path / entry.artifact).is_file():
            return int(meta.get("timesteps") or 0)
        return None

    def state(self) -> str:
        """'complete', 'resumable', 'broken' (exists, nothing to resume) or 'absent'."""
        try:
            complete = bool(self.meta.get("complete"))
        except UserError:
            complete = False
        if complete:
            return "complete"
        if checkpoint.latest(self.checkpoints) is not None:
            return "resumable"
        return "broken" if self.path.exists() else "absent"

    def file_identity(self) -> tuple:
        """Path, mtime and size of the policy files: a model trained again into the same
        folder is a new policy, never a cached old one."""
        ident = []
        for name in (PPO_ARTIFACT, IMITATION_ARTIFACT, self.META):
            path = self.path / name
            try:
                st = path.stat()
            except OSError:
                continue
            ident.append((str(path.resolve()), st.st_mtime_ns, st.st_size))
        return tuple(ident)

    def episodes(self) -> list[dict[str, float]]:
        """The rows of ``episodes.csv`` as numbers ([] before the first episode ends)."""
        import csv

        if not self.episodes_file.is_file():
            return []
        with open(self.episodes_file, newline="") as fh:
            return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]

    def check_resumes(self, method: str, seed: int) -> None:
        """``--resume`` continues this folder's run: a recorded method or seed other than
        the command's is refused in one line naming both (a :class:`UserError`: the folder, not a
        config value, is what the command got wrong)."""
        meta = self.meta
        if not meta:
            return  # stopped before it was recorded: nothing to contradict
        if meta.get("method") != method:
            raise UserError(
                f"--resume: {self.path} is a {meta.get('method')} run; this command asks for "
                f"--method {method}{_RESUME_STOP}"
            )
        if meta.get("seed") != seed:
            raise UserError(
                f"--resume: {self.path} was trained with seed {meta.get('seed')}; this command "
                f"gives --seed {seed}{_RESUME_STOP}"
            )

    # -- writing --------------------------------------------------------------------------
    def write_config(self, cfg: RunConfig) -> None:
        self.config_file.write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))

    def write_meta(self, meta: dict[str, Any]) -> None:
        write_json(self.meta_file, meta, sort_keys=True, default=str)

    def write_advisor_stats(self, stats: dict[str, Any]) -> None:
        write_json(self.advisor_stats_file, stats, sort_keys=True, default=str)
