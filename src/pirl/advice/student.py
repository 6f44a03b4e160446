"""The distilled advisor (student): a small torch model that imitates a teacher advisor.

A teacher (the embedded LLM, an OpenAI-compatible server, the oracle) is slow or paid; PARE
wants advice about the current state at every step. The student maps what its teacher sees to
a :class:`~pirl.advice.recommendation.Recommendation` in microseconds, so PARE can shape every
step with advice about the state the drone is in, while the teacher is asked about a few
sampled states only (the pattern of ONI and Motif: distil LLM labels into a small model).

Input (:func:`student_features`, fixed size for any world): the environment's observation
(local coverage and obstacle windows, the coarse global coverage map, normalised position,
camera, battery, coverage, steps left) plus the world size and the absolute position, which
the prompt shows. Obstacles far outside the local window are not in it; the oracle plans from
the coverage map, which the observation summarises.

Output: one classification head per field over its allowed values: pan in 15 degree steps,
tilt in 5 degree steps, zoom in 0.1 steps (the camera grid the drone can reach) and -1/0/1 for
each move component. A teacher's answer is snapped to the nearest class.

Teacher answers live with the state they were asked about in a :class:`TeacherDataset`
(SQLite, WAL, beside the answer cache), shared by runs and processes and keyed by the teacher
and everything that changes its answers or the features.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from pirl._atomic import replacing
from pirl._torch import configure as configure_torch
from pirl.advice.prompt import prompt_id
from pirl.advice.recommendation import Recommendation
from pirl.advice.teacher_dataset import TeacherDataset, default_dataset_path
from pirl.config import grid, safe_state
from pirl.config.run import PareSettings
from pirl.config.world import OBS_BLOCKS
from pirl.world.state import WorldBatch

FIELDS = ("pan", "tilt", "zoom", "dx", "dy", "dz")
"""The six fields of a recommendation, in the student's head order."""
CLASSES: tuple[np.ndarray, ...] = (
    np.array(grid.pan_steps(), dtype=np.float64),
    np.array(grid.tilt_steps(), dtype=np.float64),
    np.array(grid.zoom_steps(), dtype=np.float64),
    np.array(grid.MOVE_VALUES, dtype=np.float64),  # dx
    np.array(grid.MOVE_VALUES, dtype=np.float64),  # dy
    np.array(grid.MOVE_VALUES, dtype=np.float64),  # dz
)
"""The allowed values of each field (the camera grid of the world and the one-cell moves)."""
N_EXTRA = 6
"""Features after the observation: world size X, Y, Z and absolute position x, y, z (/64)."""
FEATURE_VERSION = 1
"""Bumped when the features change, so old dataset rows are not mixed with new ones."""
CONSTANT_SHARE = 0.9
"""A field is uninformative when one value takes more than this share of the held-out answers:
matching it says nothing about the state."""


def _agreement_and_chance(
    pred: np.ndarray, truth: np.ndarray, n_classes: int
) -> tuple[float, float]:
    """Observed agreement of two label vectors, and the agreement their label frequencies give
    at random."""
    observed = float((pred == truth).mean())
    p_pred = np.bincount(pred, minlength=n_classes) / len(pred)
    p_true = np.bincount(truth, minlength=n_classes) / len(truth)
    return observed, float((p_pred * p_true).sum())


def cohen_kappa(pred: np.ndarray, truth: np.ndarray, n_classes: int) -> float:
    """Cohen's kappa of two label vectors: (agreement - chance) / (1 - chance), with chance
    the agreement their label frequencies give at random; 0 when chance is 1."""
    if not len(truth):
        return 0.0
    observed, chance = _agreement_and_chance(pred, truth, n_classes)
    return 0.0 if chance >= 1.0 - 1e-12 else (observed - chance) / (1.0 - chance)


def kappa_error(pred: np.ndarray, truth: np.ndarray, n_classes: int) -> float:
    """Large-sample standard error of :func:`cohen_kappa`: sqrt(p_o (1 - p_o) / n) / (1 - p_e)
    (Cohen 1960); 1 when there is nothing to measure it on."""
    if not len(truth):
        return 1.0
    observed, chance = _agreement_and_chance(pred, truth, n_classes)
    if chance >= 1.0 - 1e-12:
        return 1.0
    return math.sqrt(observed * (1.0 - observed) / len(truth)) / (1.0 - chance)


def student_features(obs: np.ndarray, world: WorldBatch, worlds: Sequence[int]) -> np.ndarray:
    """Features of ``worlds`` (rows of ``obs`` are their observations now), float32."""
    rows = np.asarray(worlds, dtype=np.int64)
    return pose_features(obs, world.cfg.size, world.positions(rows))


def pose_features(obs: np.ndarray, size: Sequence[int], positions: np.ndarray) -> np.ndarray:
    """Features from observations (one row per world), the grid size and the worlds'
    positions (n, 3), float32."""
    out = np.empty((len(positions), obs.shape[1] + N_EXTRA), dtype=np.float32)
    out[:, : obs.shape[1]] = obs
    out[:, obs.shape[1] : obs.shape[1] + 3] = np.asarray(size, dtype=np.float32) / 64.0
    out[:, obs.shape[1] + 3 :] = positions / 64.0
    return out


def encode(recs: Sequence[Recommendation]) -> np.ndarray:
    """Class indices (n, 6) of recommendations: each value snapped to its nearest class."""
    values = np.array([[r.pan, r.tilt, r.zoom, r.dx, r.dy, r.dz] for r in recs], dtype=np.float64)
    values = values.reshape(-1, len(FIELDS))
    out = np.empty(values.shape, dtype=np.int64)
    for k, classes in enumerate(CLASSES):
        out[:, k] = np.abs(values[:, k : k + 1] - classes[None, :]).argmin(axis=1)
    return out


def decode(labels: np.ndarray) -> np.ndarray:
    """Values (n, 6) as (pan, tilt, zoom, dx, dy, dz) from class indices."""
    return np.stack([CLASSES[k][labels[:, k]] for k in range(len(FIELDS))], axis=1)


def teacher_key(advisor: Any, prompt_variant: str, env_cfg: Any) -> str:
    """Dataset key: the teacher and every setting that changes its answers or the features."""
    settings = advisor.settings_key() if hasattr(advisor, "settings_key") else ""
    # prompt_id: the variant and its text version, so answers to an older text never mix in.
    parts = [
        advisor.name, advisor.model, settings, prompt_id(prompt_variant), env_cfg.footprint,
        env_cfg.fov_deg, env_cfg.max_range, env_cfg.occlusion, env_cfg.obs_window,
        env_cfg.obs_global, FEATURE_VERSION,
    ]  # fmt: skip
    # Optional observation blocks change the features; the default layout keeps its old keys.
    parts += [
        f"{name}={getattr(env_cfg, name)}"
        for name in OBS_BLOCKS
        if getattr(env_cfg, name, False)
    ]  # fmt: skip
    if env_cfg.obs_visits and env_cfg.obs_visits_cap != 3:
        parts.append(f"obs_visits_cap={env_cfg.obs_visits_cap}")
    # A site's prompts list its buildings (a map prompt): answers about one site stay its own.
    if getattr(env_cfg, "site", ""):
        parts.append(f"site={env_cfg.site}")
    digest = hashlib.sha256(json.dumps(parts, default=str).encode()).hexdigest()[:16]
    return f"{advisor.name}:{advisor.model}:{digest}"


class StudentNet(nn.Module):
    """An MLP trunk with one classification head per recommendation field."""

    def __init__(self, n_features: int, hidden: int = 128) -> None:
        super().__init__()
        self.trunk = nn.Sequential(
            nn.Linear(n_features, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU()
        )
        self.heads = nn.ModuleList(nn.Linear(hidden, len(c)) for c in CLASSES)

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        h = self.trunk(x)
        return [head(h) for head in self.heads]


@dataclass
class StudentScore:
    """How well the student imitates its teacher on held-out teacher answers."""

    agreement: float
    """Exact-match accuracy averaged over the six fields."""
    majority: float
    """The same score for always answering each field's most frequent training value."""
    heldout: int
    """Held-out answers scored."""
    per_field: dict[str, float]
    """Exact-match accuracy of each field."""
    kappa: float = 0.0
    """Cohen's kappa of the student against the teacher (agreement beyond what their answer
    frequencies give by chance), averaged over the informative fields; 0 when none is."""
    per_field_kappa: dict[str, float] = field(default_factory=dict)
    """Cohen's kappa of each field (0 for a field the teacher hardly varies)."""
    informative: tuple[str, ...] = ()
    """The fields on which both the teacher's held-out answers and the student's predictions
    vary (no single value takes more than :data:`CONSTANT_SHARE` of either). None: what the
    student learned carries no state information."""
    kappa_se: float = 1.0
    """Standard error of :attr:`kappa`: the mean over informative fields of each field's
    large-sample error, sqrt(p_o (1 - p_o) / n) / (1 - p_e) (the mean, not the root of the
    summed squares, because the fields of one answer are not independent); 1 when no field is
    informative or nothing was scored."""


MOVE_FIELDS = ("dx", "dy", "dz")
KAPPA_Z = 3.0
"""Standard errors below its kappa that a student's lower bound (``kappa_lcb``) sits: one-sided,
about one chance in 700 that a student which learned nothing of its teacher passes a check."""


def gate_value(score: StudentScore, on: str) -> float:
    """The gate's measure ``on`` of a score (``pare.student_gate_on``)."""
    if on == "kappa":
        return score.kappa
    if on == "move_kappa":  # the move fields only: the camera fields' noise left out
        ks = [score.per_field_kappa[f] for f in score.informative if f in MOVE_FIELDS]
        return float(np.mean(ks)) if ks else 0.0
    if on == "kappa_lcb":  # kappa's lower bound: what the held-out answers can vouch for
        return score.kappa - KAPPA_Z * score.kappa_se
    if on == "best_kappa":  # the field the student learned best
        return max((score.per_field_kappa[f] for f in score.informative), default=0.0)
    return score.agreement


class Student:
    """The distilled advisor: imitates one teacher (``teacher``, a :func:`teacher_key`).

    About one row in five is held out for scoring (chosen by a checksum of its features, so
    the split does not depend on row ids or on who stored the row); the rest trains. Its
    score is not trusted, so its gate stays shut, below ``min_heldout`` held-out rows
    (``pare.student_min_heldout``). :meth:`fit` runs a fixed number of Adam steps on seeded
    minibatches, warm-started or, with ``fresh``, from the seed's initial weights, so a run
    refits the same way every time it meets the same data.
    """

    def __init__(
        self,
        teacher: str,
        n_features: int,
        label: str = "",
        hidden: int = 128,
        lr: float = 1e-3,
        batch_size: int = 256,
        seed: int = 0,
        min_heldout: int = PareSettings.student_min_heldout,
    ) -> None:
        self.teacher, self.n_features, self.label = teacher, int(n_features), label
        self.min_heldout = int(min_heldout)
        self.hidden, self.lr, self.batch_size = int(hidden), float(lr), int(batch_size)
        self.seed = int(seed)
        self._initial_weights()
        self.gen = torch.Generator().manual_seed(seed)
        self.last_id = 0
        self._ids = np.zeros(0, dtype=np.int64)
        self._held = np.zeros(0, dtype=bool)
        self._x = np.zeros((0, self.n_features), dtype=np.float32)
        self._y = np.zeros((0, len(FIELDS)), dtype=np.int64)
        self.fitted_rows = 0
        self.score = StudentScore(0.0, 0.0, 0, {})

    def _initial_weights(self) -> None:
        configure_torch()
        with torch.random.fork_rng():
            torch.manual_seed(self.seed)
            self.net = StudentNet(self.n_features, self.hidden)
        self.opt = torch.optim.Adam(self.net.parameters(), lr=self.lr)

    # -- data -------------------------------------------------------------------------------
    @property
    def dataset_size(self) -> int:
        """Teacher answers the student has (train and held-out)."""
        return len(self._ids)

    def add(self, ids: np.ndarray, features: np.ndarray, labels: np.ndarray) -> None:
        """Take rows (ids increasing); rows of another feature width are ignored."""
        if not len(ids):
            return
        if features.shape[1] != self.n_features:
            return
        held = np.array([zlib.crc32(row.tobytes()) % 5 == 0 for row in features], dtype=bool)
        self._held = np.concatenate([self._held, held])
        self._ids = np.concatenate([self._ids, ids])
        self._x = np.concatenate([self._x, features.astype(np.float32)])
        self._y = np.concatenate([self._y, labels.astype(np.int64)])
        self.last_id = max(self.last_id, int(ids.max()))

    def pull(self, dataset: TeacherDataset, upto: int | None = None) -> int:
        """Load the rows of this teacher added to ``dataset`` since the last pull."""
        ids, x, y = dataset.load(self.teacher, after=self.last_id, upto=upto)
        before = self.dataset_size
        self.add(ids, x, y)
        return self.dataset_size - before

    def _split(self) -> tuple[np.ndarray, np.ndarray]:
        return np.flatnonzero(~self._held), np.flatnonzero(self._held)

    # -- learning ---------------------------------------------------------------------------
    def fit(self, steps: int, fresh: bool = False) -> StudentScore:
        """``steps`` Adam steps on the training rows, then score on the held-out rows.

        ``fresh``: start from the seed's initial weights and a new optimizer. Warm-started
        refits on a noisy teacher's first few hundred answers memorise its noise and stay
        there as answers pile up; a fresh fit on all of them learns what they share.
        """
        if fresh:
            self._initial_weights()
        train, _ = self._split()
        if len(train):
            x = torch.from_numpy(self._x[train])
            y = torch.from_numpy(self._y[train])
            loss_fn = nn.CrossEntropyLoss()
            self.net.train()
            for _ in range(int(steps)):
                idx = torch.randint(
                    0, len(train), (min(self.batch_size, len(train)),), generator=self.gen
                )
                logits = self.net(x[idx])
                loss = sum(loss_fn(lg, y[idx, k]) for k, lg in enumerate(logits))
                self.opt.zero_grad()
                loss.backward()
                self.opt.step()
        self.fitted_rows = self.dataset_size
        self.score = self.evaluate()
        return self.score

    def fit_closed(self, steps: int, on: str = "kappa") -> StudentScore:
        """A refit while the gate is closed: ``steps`` warm-started, and ``steps`` from the
        seed's initial weights; the student keeps whichever scores higher on the gate's
        measure ``on`` (the warm one on a tie).

        A strong teacher's rare answers are learned over many warm refits, which a fresh fit
        of a few steps misses; a noisy teacher's first answers are memorised by warm refits,
        which a fresh fit on all of them does not. Choosing on the held-out answers favours
        the student slightly (two candidates, one held-out set).
        """
        warm = self.fit(steps)
        kept = copy.deepcopy(self.net.state_dict()), copy.deepcopy(self.opt.state_dict())
        fresh = self.fit(steps, fresh=True)
        if gate_value(warm, on) >= gate_value(fresh, on):
            self.net.load_state_dict(kept[0])
            self.opt.load_state_dict(kept[1])
            self.score = warm
        return self.score

    def evaluate(self) -> StudentScore:
        """Agreement and the majority baseline on the held-out rows."""
        train, held = self._split()
        if not len(held) or not len(train):
            return StudentScore(0.0, 0.0, int(len(held)), {})
        pred = self.predict_labels(self._x[held])
        truth = self._y[held]
        per_field = {f: float((pred[:, k] == truth[:, k]).mean()) for k, f in enumerate(FIELDS)}
        majority, kappas, informative, errors = [], {}, [], []
        for k, name in enumerate(FIELDS):
            n = len(CLASSES[k])
            common = np.bincount(self._y[train, k], minlength=n).argmax()
            majority.append(float((truth[:, k] == common).mean()))
            # Informative: the teacher varies and so does the student. A field the teacher's
            # noise makes vary while the student, rightly, keeps to one value says nothing of
            # the signal either way, and would dilute the mean.
            top = np.bincount(truth[:, k], minlength=n).max() / len(truth)
            top_pred = np.bincount(pred[:, k], minlength=n).max() / len(pred)
            varies = top <= CONSTANT_SHARE and top_pred <= CONSTANT_SHARE
            kappas[name] = cohen_kappa(pred[:, k], truth[:, k], n) if varies else 0.0
            if varies:
                informative.append(name)
                errors.append(kappa_error(pred[:, k], truth[:, k], n))
        kappa = float(np.mean([kappas[f] for f in informative])) if informative else 0.0
        return StudentScore(
            float(np.mean(list(per_field.values()))), float(np.mean(majority)), len(held),
            per_field, kappa, kappas, tuple(informative),
            float(np.mean(errors)) if errors else 1.0,
        )  # fmt: skip

    def gate_after_fit(self, was_open: bool, gate: float, close: float, on: str) -> bool:
        """Whether the gate is open after a fit, with hysteresis: a closed gate opens when
        the measure ``on`` reaches ``gate``; an open one stays open while it is at least
        ``close`` (<= ``gate``)."""
        return self.passes(close if was_open else gate, on)

    def passes(self, gate: float, on: str = "agreement") -> bool:
        """Whether the student may shape rewards: ``min_heldout`` held-out answers and, ``on``
        ``"kappa"``, a kappa of at least ``gate`` over informative fields (what the student
        learned of the teacher's signal), or ``on`` ``"agreement"``, a held-out agreement of at
        least ``gate`` (which a noisy teacher cannot reach and a constant one passes)."""
        if self.score.heldout < self.min_heldout:
            return False
        return gate_value(self.score, on) >= gate

    # -- advice -----------------------------------------------------------------------------
    @torch.no_grad()
    def predict_labels(self, features: np.ndarray) -> np.ndarray:
        """Class indices (n, 6) for feature rows."""
        self.net.eval()
        logits = self.net(torch.from_numpy(np.ascontiguousarray(features, dtype=np.float32)))
        return torch.stack([lg.argmax(dim=1) for lg in logits], dim=1).numpy()

    def predict(self, features: np.ndarray) -> np.ndarray:
        """Advice values (n, 6) as (pan, tilt, zoom, dx, dy, dz)."""
        return decode(self.predict_labels(features))

    # -- state ------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue exactly (the data is reloaded from the dataset)."""
        return {
            "teacher": self.teacher,
            "n_features": self.n_features,
            "label": self.label,
            "hidden": self.hidden,
            "lr": self.lr,
            "batch_size": self.batch_size,
            "seed": self.seed,
            "net": {k: v.clone() for k, v in self.net.state_dict().items()},
            "opt": copy.deepcopy(self.opt.state_dict()),
            "gen": self.gen.get_state(),
            "last_id": self.last_id,
            "ids": self._ids.copy(),
            "fitted_rows": self.fitted_rows,
            "score": self.score,
        }

    def load_state_dict(
        self, state: dict[str, Any], dataset: TeacherDataset | None, strict: bool = True
    ) -> None:
        """Restore a :meth:`state_dict`; its rows are read back from ``dataset`` by id.

        ``strict``: every row must still be there (a resumed run); otherwise (a student copied
        to another machine) the student keeps its weights and the rows that are there.
        """
        if state["teacher"] != self.teacher:
            raise ValueError(f"student of {state['teacher']}, not of {self.teacher}")
        self.net.load_state_dict(state["net"])
        self.opt.load_state_dict(state["opt"])
        self.gen.set_state(state["gen"])
        self.fitted_rows, self.score = state["fitted_rows"], state["score"]
        ids = np.asarray(state["ids"], dtype=np.int64)
        self._ids = np.zeros(0, dtype=np.int64)
        self._held = np.zeros(0, dtype=bool)
        self._x = np.zeros((0, self.n_features), dtype=np.float32)
        self._y = np.zeros((0, len(FIELDS)), dtype=np.int64)
        self.last_id = 0
        if len(ids) and dataset is not None:
            got, x, y = dataset.load(self.teacher, after=0, upto=int(state["last_id"]))
            keep = np.isin(got, ids)
            self.add(got[keep], x[keep], y[keep])
            if strict and self.dataset_size != len(ids):
                raise ValueError(
                    f"the teacher dataset {dataset.path} lost {len(ids) - self.dataset_size} "
                    "rows this student was trained on"
                )
        self.last_id = int(state["last_id"])

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the student (weights, optimizer, score, row ids) atomically, as arrays and
        JSON (:mod:`pirl.config.safe_state`): a student from anyone loads without running code."""
        path = Path(path)
        with replacing(path) as tmp:
            safe_state.save(self.state_dict(), tmp)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike[str], dataset: TeacherDataset | None) -> Student:
        """A student saved with :meth:`save` (nothing in the file is unpickled)."""
        state = safe_state.load(Path(path))
        if not isinstance(state, dict) or "teacher" not in state:
            raise ValueError(f"{path} holds no student")
        student = cls(
            state["teacher"], state["n_features"], state["label"], state["hidden"], state["lr"],
            state["batch_size"], int(state.get("seed", 0)),
        )  # fmt: skip
        student.load_state_dict(state, dataset, strict=False)
        return student


STUDENT_FILE = "student.npz"
"""The file of a student folder that :meth:`Student.save` writes (``pirl distill``)."""


__all__ = [
    "CLASSES",
    "STUDENT_FILE",
    "FIELDS",
    "Student",
    "StudentNet",
    "StudentScore",
    "TeacherDataset",
    "decode",
    "default_dataset_path",
    "encode",
    "pose_features",
    "student_features",
    "teacher_key",
]
