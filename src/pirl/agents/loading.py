"""Load any method as a :class:`~pirl.agents.policy.Policy`: a run folder or a method name."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from pirl.agents.policy import Policy, RandomPolicy
from pirl.world.config import ConfigError

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

        self.model = PPO.load(model_path, device=device)
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
        self.model.load_model(str(model_path))

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        return int(self.model.predict(np.asarray(obs, dtype=np.float32)[None])[0])


def run_method(run: Path) -> str:
    """The method a finished run folder holds (from its meta.json)."""
    meta_path = Path(run) / "meta.json"
    if not meta_path.is_file():
        raise ConfigError(f"{run} is not a run folder (no meta.json)")
    meta = json.loads(meta_path.read_text())
    if not meta.get("complete"):
        raise ConfigError(f"run {run} is not finished; continue it with --resume")
    return str(meta["method"])


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
    if method == "il":
        return TabNetPolicy(run / "tabnet.zip")
    model = run / "model.zip"
    if not model.is_file():
        raise ConfigError(f"run {run} has no model.zip")
    return PPOPolicy(model, method, device)
