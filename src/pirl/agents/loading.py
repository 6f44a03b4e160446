"""Load any method as a :class:`~pirl.agents.policy.Policy`: a run folder or a method name."""

from __future__ import annotations

import importlib
import io
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from pirl.agents.methods import (
    BUILTIN,
    IL,
    METHODS,
    PPO_METHODS,
    TRAIN_IMITATION,
    label,
    method,
    trained_method,
)
from pirl.agents.policy import Policy
from pirl.agents.run_folder import RETRAIN, RunFolder, short_error
from pirl.agents.views import ViewsPolicy
from pirl.config.choices import Act
from pirl.config.errors import ConfigError, UserError

ACT_MODES = tuple(Act)
# A salt so the action stream of a scenario differs from the stream that drew the scenario.
_ACT_SALT = 0x5EED


def act_rng(scenario_seed: int | None) -> np.random.Generator:
    """The generator that samples a stochastic policy's actions in one scenario: seeded by the
    scenario alone, so a re-run (and the batched runner) draws the same actions."""
    return np.random.default_rng(None if scenario_seed is None else [scenario_seed, _ACT_SALT])


def check_act(mode: str) -> str:
    if mode not in ACT_MODES:
        raise ConfigError(f"--act {mode!r}: allowed values are stochastic, greedy, both")
    return mode


class LearnedPolicy(Policy):
    """A trained policy with action probabilities, acting ``greedy`` (the most likely action)
    or ``stochastic`` (sampled, seeded per scenario by :func:`act_rng`).

    ``act_batch`` chooses for many worlds at once with one forward pass; ``act`` is the batch
    of one, so the batched and the per-episode runner choose the same actions.
    """

    act_mode = "greedy"
    # Trained with valid-action masks (the run's ppo.action_masking): acts on masked
    # probabilities too, as MaskablePPO's distribution does (invalid actions get 0).
    masked = False
    # Length of the observations it was trained on (None: unknown, not checked).
    obs_size: int | None = None
    _rng: np.random.Generator | None = None

    def set_act(self, mode: str) -> LearnedPolicy:
        self.act_mode = check_act(mode)
        return self

    def reset(self, world: Any, index: int = 0, seed: int | None = None) -> None:
        self._rng = act_rng(seed)

    def probabilities(self, obs: np.ndarray) -> np.ndarray:
        """Action probabilities, shape (batch, N_ACTIONS)."""
        raise NotImplementedError

    def act_batch(
        self,
        obs: np.ndarray,
        rngs: list[np.random.Generator] | None,
        masks: np.ndarray | None = None,
    ) -> np.ndarray:
        """One action per row of ``obs``; ``masks`` (batch, N_ACTIONS) are the valid actions,
        applied when the policy is :attr:`masked`."""
        obs = np.asarray(obs, dtype=np.float32)
        if self.obs_size is not None and obs.shape[-1] != self.obs_size:
            raise ConfigError(
                f"{self.label} was trained on observations of {self.obs_size} values; this "
                f"environment gives {obs.shape[-1]} (env.obs_window, obs_global, obs_visits and "
                "obs_target must be the run's own: see its config.yaml)"
            )
        probs = self.probabilities(obs)
        if self.masked:
            if masks is None:
                raise ValueError(f"{self.label} was trained with action masks; give them")
            probs = mask_probabilities(probs, masks)
        if self.act_mode == "greedy":
            return probs.argmax(axis=1)
        if rngs is None:
            raise ValueError("stochastic acting needs one generator per world")
        return sample_actions(probs, rngs)

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> int:
        if self._rng is None:
            self._rng = act_rng(None)
        mask = info.get("action_mask") if self.masked else None
        masks = None if mask is None else np.asarray(mask, dtype=bool)[None]
        return int(self.act_batch(np.asarray(obs)[None], [self._rng], masks)[0])


def mask_probabilities(probs: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """``probs`` restricted to the valid actions and renormalised per row (what sb3-contrib's
    MaskableCategorical computes); a row whose valid actions all have probability 0 becomes
    uniform over them."""
    masked = np.where(np.asarray(masks, dtype=bool), probs, 0.0)
    total = masked.sum(axis=1, keepdims=True)
    uniform = masks / np.maximum(1, masks.sum(axis=1, keepdims=True))
    return np.where(total > 0, masked / np.where(total > 0, total, 1.0), uniform)


def sample_actions(probs: np.ndarray, rngs: list[np.random.Generator]) -> np.ndarray:
    """One action per row of ``probs``, each drawn with its row's generator (one uniform each)."""
    cdf = np.cumsum(np.asarray(probs, dtype=np.float64), axis=1)
    u = np.array([rng.random() for rng in rngs]) * cdf[:, -1]
    actions = (cdf <= u[:, None]).sum(axis=1)
    return np.minimum(actions, probs.shape[1] - 1)


class PPOPolicy(LearnedPolicy):
    """A trained Stable-Baselines3 PPO model (greedy unless :meth:`set_act` says otherwise)."""

    def __init__(
        self, model_path: Path, name: str, device: str = "cpu", masked: bool = False
    ) -> None:
        if masked:
            from sb3_contrib import MaskablePPO as PPO
        else:
            from stable_baselines3 import PPO

        self.masked = masked
        self.model = load_sb3(model_path, PPO, device)
        self.obs_size = int(self.model.observation_space.shape[0])
        self.name = name
        self.label = label(name)

    def probabilities(self, obs: np.ndarray) -> np.ndarray:
        import torch

        policy = self.model.policy
        with torch.no_grad():
            tensor = torch.as_tensor(obs, device=policy.device)
            if not self.masked:
                return policy.get_distribution(tensor).distribution.probs.cpu().numpy()
            features = policy.extract_features(tensor, policy.pi_features_extractor)
            logits = policy.action_net(policy.mlp_extractor.forward_actor(features))
            # MaskablePPO's ``get_distribution(obs).distribution.probs``, bit for bit, without
            # building its two validated Categorical objects per call (two thirds of an
            # evaluation step's cost at a batch of a few worlds): sb3-contrib normalises the
            # logits once on construction and once more when it (un)masks them.
            logits = logits.view(-1, logits.shape[-1])
            for _ in range(2):
                logits = logits - logits.logsumexp(dim=-1, keepdim=True)
            return torch.softmax(logits, dim=-1).cpu().numpy()


class LearnedViewsPolicy(ViewsPolicy):
    """A trained chooser (a ``ppo-views`` run's network, ``net``) played as a policy: its most
    likely candidate (greedy) or one drawn from its masked probabilities, seeded per scenario
    (stochastic), as every learned policy acts."""

    def __init__(self, net: LearnedPolicy) -> None:
        super().__init__(self._choose_with_net, net.label)
        self.net, self.name = net, net.name
        self._rng = act_rng(None)

    @property
    def act_mode(self) -> str:
        return self.net.act_mode

    def set_act(self, mode: str) -> LearnedViewsPolicy:
        self.net.set_act(mode)
        return self

    def reset(self, world: Any, index: int = 0, seed: int | None = None) -> None:
        super().reset(world, index, seed)
        self._rng = act_rng(seed)

    def _choose_with_net(self, c: Any) -> int:
        return int(self.net.act_batch(c.obs[None], [self._rng], c.mask[None])[0])


class TabNetPolicy(LearnedPolicy):
    """The imitation-learning TabNet classifier (greedy: its most likely action)."""

    def __init__(self, model_path: Path, name: str, masked: bool = False) -> None:
        from pytorch_tabnet.tab_model import TabNetClassifier

        self.name, self.label = name, label(name)
        self.masked = masked
        self.model = TabNetClassifier(device_name="cpu")
        check_tabnet_file(model_path)
        try:
            self.model.load_model(str(model_path))
        except Exception as exc:  # noqa: BLE001 - any failure to read the file is reported
            raise UserError(
                f"{model_path} cannot be loaded ({short_error(exc)}); {RETRAIN}"
            ) from None
        self.obs_size = int(getattr(self.model, "input_dim", 0) or 0) or None
        # Inference only, set once: ``Module.eval`` walks TabNet's ~120 modules, and at every
        # step it would cost a fifth of an IL evaluation.
        self.model.network.eval()

    def probabilities(self, obs: np.ndarray) -> np.ndarray:
        import torch

        from pirl.world.dynamics import N_ACTIONS

        # TabNet's predict_proba, without its DataLoader and with no autograd graph: the
        # same batches of batch_size rows and the same softmax, at a third of the cost per
        # evaluation step.
        net = self.model.network
        x = torch.as_tensor(np.asarray(obs)).float()
        with torch.no_grad():
            proba = np.vstack([
                torch.softmax(net(x[i : i + self.model.batch_size])[0], dim=1).numpy()
                for i in range(0, len(x), self.model.batch_size)
            ])  # fmt: skip
        # Columns follow the classes the expert showed; actions it never took get 0.
        classes = [int(self.model.preds_mapper[str(k)]) for k in range(proba.shape[1])]
        full = np.zeros((proba.shape[0], N_ACTIONS), dtype=np.float64)
        full[:, classes] = proba
        return full


def check_tabnet_file(path: Path) -> None:
    """Refuse a ``tabnet.zip`` whose weights (a ``torch.save`` pickle) name anything but
    PyTorch's tensor builders: PyTorch reads them with ``weights_only=True`` by default, and
    this keeps such a file refused even where that default is switched off."""
    from pirl.config.safe_state import UnsafeFile, pickle_globals

    try:
        with zipfile.ZipFile(path) as outer, outer.open("network.pt") as inner:
            blob = io.BytesIO(inner.read())
        with zipfile.ZipFile(blob) as weights:
            pickles = [n for n in weights.namelist() if n.endswith(".pkl")]
            names = set().union(*(pickle_globals(weights.read(n)) for n in pickles))
    except (zipfile.BadZipFile, KeyError, OSError) as exc:
        raise UserError(f"{path} cannot be loaded ({short_error(exc)}); {RETRAIN}") from None
    strange = sorted(n for n in names if not n.startswith("torch.") and n != _ORDERED_DICT)
    if strange:
        raise UnsafeFile(
            f"refused {path}: its network.pt would run code when loaded (it names "
            f"{', '.join(strange[:3])}); do not use this run"
        )


_ORDERED_DICT = "collections.OrderedDict"


def load_policy(
    source: str | Path,
    advisor: Any | None = None,
    seed: int | None = None,
    device: str = "cpu",
    max_calls: int = 0,
    prompt_variant: str = "paper",
    act: str = "greedy",
) -> Policy:
    """A policy from a run folder (PPO methods, IL) or a built-in method name.

    Built-ins: ``boustrophedon``, ``random`` and ``llm-only`` (which needs ``advisor``;
    ``max_calls`` limits its LLM calls per episode, 0 = no limit; ``prompt_variant`` picks
    the prompt). ``act`` (greedy or stochastic) sets how a trained policy acts; built-ins
    act by their own rule whatever it says.
    """
    if str(source) in BUILTIN:
        module, cls = method(str(source)).policy.split(":")
        played = getattr(importlib.import_module(module), cls)
        return played.build(
            seed=seed, advisor=advisor, prompt_variant=prompt_variant, max_calls=max_calls
        )
    run = Path(source)
    if not run.exists():
        raise ConfigError(f"{source!r} is neither a run folder nor a method ({', '.join(BUILTIN)})")
    folder = RunFolder(run)
    name, model, masked = folder.method, folder.model_file(), folder.masked
    entry = trained_method(name, f"run {run}")
    if entry.training == TRAIN_IMITATION:
        return TabNetPolicy(model, name, masked).set_act(act)
    if entry.views:
        return LearnedViewsPolicy(PPOPolicy(model, name, device, masked).set_act(act))
    return PPOPolicy(model, name, device, masked).set_act(act)


def load_model(path: Path, device: str = "cpu") -> Any:
    """The SB3 model in ``path`` (a run's model.zip): ``MaskablePPO`` when its run trained
    with action masks, else ``PPO``; loaded by :func:`load_sb3` (nothing unpickled)."""
    from stable_baselines3 import PPO

    algo: Any = PPO
    if RunFolder(Path(path).parent).masked:
        from sb3_contrib import MaskablePPO

        algo = MaskablePPO
    return load_sb3(path, algo, device)


# What SB3 (and this package) write into model.zip's cloudpickled entries, by the globals a
# pickle names: anything else there (os.system, builtins.exec, code objects) is a tampered
# file and is refused, although no entry is ever unpickled.
SB3_GLOBALS = frozenset(
    {
        "collections.deque",
        "collections.OrderedDict",
        "gymnasium.spaces.box.Box",
        "gymnasium.spaces.discrete.Discrete",
        "numpy.dtype",
        "numpy.ndarray",
        "numpy.core.numeric._frombuffer",
        "numpy._core.numeric._frombuffer",
        "numpy.core.multiarray.scalar",
        "numpy._core.multiarray.scalar",
        "numpy.core.multiarray._reconstruct",
        "numpy._core.multiarray._reconstruct",
        "numpy.random._pickle.__generator_ctor",
        "numpy.random._pickle.__bit_generator_ctor",
        # A space's generator as numpy 2 pickles it, in runs written before save_model left
        # generators out (pirl.agents.checkpoint); Cython's unpickle of a SeedSequence only
        # restores its fields.
        "numpy.random._pcg64.PCG64",
        "numpy.random.bit_generator.SeedSequence",
        "numpy.random.bit_generator.__pyx_unpickle_SeedSequence",
        "stable_baselines3.common.utils.FloatSchedule",
        "stable_baselines3.common.utils.ConstantSchedule",
        "stable_baselines3.common.utils.LinearSchedule",
        "stable_baselines3.common.policies.ActorCriticPolicy",
        "stable_baselines3.common.buffers.RolloutBuffer",
        "sb3_contrib.common.maskable.policies.MaskableActorCriticPolicy",
        "sb3_contrib.common.maskable.buffers.MaskableRolloutBuffer",
        "pirl.agents.schedules.LinearDecay",
    }
)


def sb3_entries(path: Path) -> dict[str, Any]:
    """The ``data`` entries of an SB3 zip, read as JSON; every cloudpickled entry is looked
    into (not loaded) and one naming anything outside :data:`SB3_GLOBALS` is refused."""
    import base64
    import binascii

    from pirl.config.safe_state import UnsafeFile, pickle_globals

    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data"))
    except (zipfile.BadZipFile, KeyError, OSError, ValueError) as exc:
        raise UserError(f"{path} cannot be loaded ({short_error(exc)}); {RETRAIN}") from None
    if not isinstance(data, dict):
        raise UserError(f"{path} cannot be loaded (its data entry is not a mapping); {RETRAIN}")
    for key, value in data.items():
        if not (isinstance(value, dict) and ":serialized:" in value):
            continue
        try:
            raw = base64.b64decode(value[":serialized:"])
        except (binascii.Error, TypeError, ValueError):
            raw = b""
        strange = sorted(pickle_globals(raw) - SB3_GLOBALS)
        if strange:
            raise UnsafeFile(
                f"refused {path}: its entry {key!r} would run code when loaded (it names "
                f"{', '.join(strange[:3])}); pirl never unpickles a run's files, and a "
                "model.zip written by pirl names none of these: do not use this run"
            )
    return data


def check_expert(expert_run: Path) -> RunFolder:
    """An imitation expert, checked without torch (so a wrong ``--expert`` is refused in a
    second, before IL's libraries load): an existing, finished run of the PPO method IL
    learns from, whose model.zip is whole and names nothing that would run code."""
    expert = RunFolder(Path(expert_run))
    if not expert.path.is_dir():
        raise UserError(f"--expert {expert_run}: no such run folder")
    expert_method = expert.method
    if expert_method not in PPO_METHODS:
        raise UserError(
            f"--expert {expert_run} is a {expert_method} run, not a finished PPO run "
            f"({', '.join(PPO_METHODS)})"
        )
    IL.check_expert(str(expert_run), expert_method)
    sb3_entries(expert.model_file())
    return expert


def load_sb3(path: Path, algo: Any, device: str = "cpu") -> Any:
    """An SB3 model from its zip without unpickling anything.

    The weights come from the zip's ``.pth`` members (SB3 reads them with
    ``torch.load(weights_only=True)``); every cloudpickled entry (spaces, schedules, buffers)
    is checked by :func:`sb3_entries` and then replaced by one rebuilt from the run's own
    ``config.yaml`` (the folder the zip is in), so none is ever unpickled.
    """
    import gymnasium as gym

    from pirl._torch import configure as configure_torch
    from pirl.agents.schedules import learning_rate_of
    from pirl.env.observation import obs_size_for
    from pirl.world.dynamics import N_ACTIONS

    configure_torch()
    path = Path(path)
    data = sb3_entries(path)
    try:
        folder = RunFolder(path.parent)
        cfg = folder.config
        views = METHODS[folder.method].views if folder.method in METHODS else False
    except ConfigError as exc:
        raise UserError(f"{path} cannot be loaded: {exc}; {RETRAIN}") from None
    if views:
        from pirl.env.views import views_spaces

        obs_space, action_space = views_spaces()
    else:
        obs_space = gym.spaces.Box(0.0, 1.0, (obs_size_for(cfg.env),), dtype=np.float32)
        action_space = gym.spaces.Discrete(N_ACTIONS)
    policy = algo.policy_aliases["MlpPolicy"]
    rebuilt: dict[str, Any] = {
        "policy_class": policy,
        "observation_space": obs_space,
        "action_space": action_space,
        "learning_rate": learning_rate_of(cfg.ppo),
        "lr_schedule": learning_rate_of(cfg.ppo),
        "clip_range": cfg.ppo.clip_range,
    }
    custom = {
        key: rebuilt.get(key)
        for key, value in data.items()
        if isinstance(value, dict) and ":serialized:" in value
    }
    try:
        return algo.load(path, device=device, custom_objects=custom)
    except Exception as exc:  # noqa: BLE001 - any failure to read the file is reported
        raise UserError(f"{path} cannot be loaded ({short_error(exc)}); {RETRAIN}") from None
