"""Load any method as a :class:`~pirl.agents.policy.Policy`: a run folder or a method name."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from pirl.agents.policy import Policy, RandomPolicy
from pirl.world.config import ConfigError, UserError

BUILTIN = ("boustrophedon", "random", "llm-only")
LABELS = {
    "pirl": "PIRL",
    "ppo-sr": "PPO-SR",
    "ppo-ewri": "PPO-EWRI",
    "il": "IL",
    "llm-only": "LLM-only",
    "boustrophedon": "boustrophedon (planner)",
    "random": "random",
}


class PPOPolicy(Policy):
    """A trained Stable-Baselines3 PPO model acting deterministically."""

    def __init__(self, model_path: Path, name: str, device: str = "cpu") -> None:
        from stable_baselines3 import PPO

        try:
            self.model = PPO.load(model_path, device=device)
        except Exception as exc:  # noqa: BLE001 - any failure to read the file is reported
            raise UserError(f"{model_path} cannot be loaded ({_short(exc)}); {_RETRAIN}") from None
        self.name = name
        self.label = LABELS.get(name, name)

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        action, _ = self.model.predict(obs, deterministic=True)
        return int(action)


class TabNetPolicy(Policy):
    """The imitation-learning TabNet classifier, choosing its most likely action."""

    name = "il"
    label = "IL"

    def __init__(self, model_path: Path) -> None:
        from pytorch_tabnet.tab_model import TabNetClassifier

        self.model = TabNetClassifier(device_name="cpu")
        try:
            self.model.load_model(str(model_path))
        except Exception as exc:  # noqa: BLE001 - any failure to read the file is reported
            raise UserError(f"{model_path} cannot be loaded ({_short(exc)}); {_RETRAIN}") from None

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        return int(self.model.predict(np.asarray(obs, dtype=np.float32)[None])[0])


_RETRAIN = "train the run again into a new --out (or restore the file from a copy)"


def _short(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:160] if text else type(exc).__name__


def run_meta(run: Path) -> dict[str, Any]:
    """The meta.json of a finished run folder."""
    meta_path = Path(run) / "meta.json"
    if not meta_path.is_file():
        raise ConfigError(f"{run} is not a run folder (no meta.json)")
    try:
        meta = json.loads(meta_path.read_text())
    except (ValueError, OSError) as exc:
        raise UserError(f"{meta_path} is damaged ({_short(exc)}); {_RETRAIN}") from None
    if not isinstance(meta, dict) or "method" not in meta:
        raise UserError(f"{meta_path} names no method; {_RETRAIN}")
    if not meta.get("complete"):
        raise ConfigError(f"run {run} is not finished; continue it with --resume")
    return meta


def run_method(run: Path) -> str:
    """The method a finished run folder holds (from its meta.json)."""
    return str(run_meta(run)["method"])


def model_file(run: Path) -> Path:
    """The model file of a finished run, checked to be a whole zip archive (cheap: no torch)."""
    run = Path(run)
    path = run / ("tabnet.zip" if run_method(run) == "il" else "model.zip")
    if not path.is_file():
        raise UserError(f"run {run} has no {path.name}; {_RETRAIN}")
    try:
        with zipfile.ZipFile(path) as archive:
            bad = archive.testzip()
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        raise UserError(f"{path} is damaged ({_short(exc)}); {_RETRAIN}") from None
    if bad is not None:
        raise UserError(f"{path} is damaged (member {bad} fails its checksum); {_RETRAIN}")
    return path


def load_policy(
    source: str | Path,
    advisor: Any | None = None,
    seed: int | None = None,
    device: str = "cpu",
    max_calls: int = 0,
    prompt_variant: str = "paper",
) -> Policy:
    """A policy from a run folder (PPO methods, IL) or a built-in method name.

    Built-ins: ``boustrophedon``, ``random`` and ``llm-only`` (which needs ``advisor``;
    ``max_calls`` limits its LLM calls per episode, 0 = no limit; ``prompt_variant`` picks
    the prompt).
    """
    if str(source) in BUILTIN:
        name = str(source)
        if name == "boustrophedon":
            from pirl.agents.boustrophedon import BoustrophedonPolicy

            return BoustrophedonPolicy()
        if name == "random":
            return RandomPolicy(seed)
        if advisor is None:
            raise ConfigError("llm-only needs an advisor")
        from pirl.agents.llm_only import LLMOnlyPolicy

        return LLMOnlyPolicy(advisor, prompt_variant, max_calls=max_calls)
    run = Path(source)
    if not run.exists():
        raise ConfigError(f"{source!r} is neither a run folder nor a method ({', '.join(BUILTIN)})")
    method = run_method(run)
    model = model_file(run)
    if method == "il":
        return TabNetPolicy(model)
    return PPOPolicy(model, method, device)
