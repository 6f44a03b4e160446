"""Run configuration: every value a user may change for training, in one YAML file.

A preset (``configs/quick.yaml``, ``paper.yaml``, ``test.yaml``) has the sections below; each
section is a dataclass with a docstring per field. Unknown keys, wrong types and impossible
values are refused with a message naming the section and key.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from pirl.physics.config import PhysicsConfig
from pirl.world.config import ConfigError, VCPPConfig, check_keys


@dataclass(frozen=True)
class PPOSettings:
    """Stable-Baselines3 PPO and the batched environment it trains on."""

    n_envs: int = 16
    """Worlds stepped together (one VCPPVecEnv)."""
    n_steps: int = 256
    """Steps per world per rollout."""
    batch_size: int = 1024
    """Minibatch size of the PPO update."""
    n_epochs: int = 4
    """Passes over each rollout."""
    learning_rate: float = 3e-4
    """Adam step size (linearly decayed to 0 when lr_schedule is 'linear')."""
    lr_schedule: str = "constant"
    """'constant' or 'linear'."""
    gamma: float = 0.99
    """Discount factor."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    clip_range: float = 0.2
    """PPO clip range."""
    ent_coef: float = 0.01
    """Entropy bonus."""
    vf_coef: float = 0.5
    """Value loss weight."""
    max_grad_norm: float = 0.5
    """Gradient clipping."""
    net_arch: tuple[int, ...] = (256, 256)
    """Hidden layers of the separate policy and value MLPs."""
    torch_threads: int = 1
    """Threads for PyTorch (the envs and an LLM share the cores)."""
    device: str = "auto"
    """'auto' (CUDA when present, else CPU), 'cpu' or 'cuda'."""
    action_masking: bool = False
    """Train with sb3-contrib's MaskablePPO on the env's valid-action masks (camera actions at
    their limit and moves out of the grid or into obstacles are never chosen); the trained
    policy acts on the same masks in every evaluation. False is the paper's action space."""


@dataclass(frozen=True)
class TrainSettings:
    """Length, checkpoints and logging of a run."""

    total_steps: int = 300_000
    """Environment steps (all worlds together)."""
    checkpoint_every: int = 50_000
    """Write a resumable checkpoint at the first rollout boundary after every this many steps."""
    log_every_s: float = 10.0
    """Seconds between plain progress lines when the output is not a terminal."""


@dataclass(frozen=True)
class PareSettings:
    """PIRL's reward shaping (DESIGN.md section 5)."""

    advisor: str = "local"
    """'local' (embedded model), 'openai' (any OpenAI-compatible server), 'oracle' or an
    installed plugin's name (pirl.advice.registry checks it when the advisor is built)."""
    mode: str = "student"
    """'student' (a distilled advisor answers every step; the teacher is asked at
    teacher_rate), 'sync' (the paper's timing: the answer about s_t shapes r_{t+1}) or 'async'
    (never waits; answers about an ended episode are dropped)."""
    query_every: int = 1
    """K: ask every K steps of each world."""
    lam_cam: float = 1.0
    """Weight of the camera alignment."""
    lam_move: float = 1.0
    """Weight of the move alignment."""
    alpha: float = 0.5
    """Direction vs position alignment."""
    timeout_s: float = 120.0
    """Sync mode: longest wait for a batch of answers."""
    cache: bool = True
    """Keep answers in the persistent SQLite cache."""
    cache_path: str = ""
    """Cache file; empty means ~/.cache/pirl/advice.sqlite (or $PIRL_CACHE_DIR)."""
    budget_calls: int = 0
    """Stop asking after this many LLM calls (0 = no limit)."""
    budget_tokens: int = 0
    """Stop asking after this many tokens (0 = no limit)."""
    prompt_variant: str = "paper"
    """Prompt variant of pirl.advice.build_prompt."""
    teacher_rate: float = 0.002
    """Student mode: teacher calls per env-step for an LLM teacher (paper: 1.0 at K = 1)."""
    oracle_teacher_rate: float = 0.02
    """Student mode: teacher calls per env-step when the teacher is the oracle (cheap)."""
    student_gate: float = 0.8
    """Student mode: held-out agreement with the teacher before the student shapes rewards."""
    student_fit_steps: int = 100
    """Student mode: Adam steps per refit (at rollout boundaries with new teacher answers)."""
    student_refit_growth: float = 0.25
    """Student mode: once past its gate, the student is refit only when the teacher's answers
    have grown by this share since its last fit (0 = at every rollout with new answers)."""
    student_hidden: int = 128
    """Student mode: width of the student's two hidden layers."""
    student_dataset: str = ""
    """Teacher answers with their states; empty = student.sqlite beside the answer cache."""
    student_wait_teacher: bool = False
    """Student mode: wait for the teacher's batch at each rollout boundary (reproducible runs;
    PPO then waits for a slow teacher)."""
    max_failure_rate: float = 0.5
    """Stop training when more than this share of the last failure_window teacher answers
    failed or did not parse (0 = never stop)."""
    failure_window: int = 200
    """Teacher answers in the rolling failure rate."""
    min_shaped: float = 0.5
    """A PIRL run with less than this share of its steps shaped (by the student or the
    teacher) ends with a warning, and its label in summaries, tables, figures and the report
    carries ``unshaped N%``: it trained mostly as PPO-EWRI."""


@dataclass(frozen=True)
class AdvisorSettings:
    """LLM backends. The API key is never here: it comes from the environment variable."""

    local_model: str = ""
    """Hugging Face model folder for 'local'; empty = embedded SmolLM2-135M-Instruct."""
    local_threads: int = 1
    """CPU threads of the local model."""
    local_batch_size: int = 32
    """Largest batch of prompts per generate call."""
    local_process: bool = True
    """Training: run the local model in a child process of its own, so that it competes with
    PPO for neither the interpreter lock nor PyTorch's process-wide thread count."""
    openai_model: str = "gpt-3.5-turbo"
    """Model name for 'openai'."""
    openai_base_url: str = ""
    """OpenAI-compatible server (Ollama, vLLM, llama.cpp...); empty = api.openai.com."""
    openai_api_key_env: str = "OPENAI_API_KEY"
    """Name of the environment variable holding the key."""
    openai_timeout_s: float = 30.0
    """Per-request timeout."""
    openai_deadline_s: float = 60.0
    """Longest time one batch of prompts may take, retries included; prompts unanswered by
    then count as failed (a server that accepts connections but never answers then stops a
    run through pare.max_failure_rate within a few minutes)."""
    probe_timeout_s: float = 30.0
    """Longest wait for the probe call that checks the advisor before a run starts (and for
    the answer of pirl advise)."""
    openai_max_retries: int = 4
    """Retries with backoff on rate limits and dropped connections."""
    openai_concurrency: int = 8
    """Requests in flight at once."""


@dataclass(frozen=True)
class ILSettings:
    """Imitation learning (TabNet on PPO-EWRI rollouts)."""

    expert_steps: int = 20_000
    """Expert transitions collected on the training world."""
    valid_fraction: float = 0.2
    """Share held out for validation and early stopping."""
    max_epochs: int = 60
    """Most TabNet epochs."""
    patience: int = 8
    """Epochs without validation improvement before stopping."""
    batch_size: int = 1024
    """TabNet batch size."""


@dataclass(frozen=True)
class ReproduceSettings:
    """What ``pirl reproduce`` trains and evaluates."""

    seeds: tuple[int, ...] = (0,)
    """Training seeds per method; their episodes pool into the confidence intervals."""
    sizes: tuple[str, ...] = ("30", "45", "60")
    """Evaluation worlds (N for NxNx3, or XxYxZ)."""
    episodes: int = 100
    """Scenarios per size for every method."""
    llm_only_episodes: int = 100
    """Scenarios per size for LLM-only (it calls the LLM every few steps, so it is slow)."""
    llm_only_max_calls: int = 0
    """LLM calls allowed per LLM-only episode (0 = no limit); after that it holds still."""
    oracle_pirl: bool = True
    """Also train PIRL with the oracle advisor (a labelled extra, not an LLM)."""
    physics_sizes: tuple[str, ...] = ("30", "45", "60")
    """Worlds flown in the physics simulator (empty = no physics table)."""
    physics_episodes: int = 100
    """Scenarios per size in the physics simulator (the same seeds as the grid's first ones)."""
    workers: int = 2
    """Evaluation worker processes."""
    gif_every: int = 2
    """Record every n-th frame of the report's animations."""
    methods: tuple[str, ...] = ("ppo-sr", "ppo-ewri", "pirl", "il")
    """Methods trained per seed (il needs ppo-ewri; pirl trains once per pirl_variants entry)."""
    builtins: tuple[str, ...] = ("llm-only", "boustrophedon", "random")
    """Methods evaluated without training."""
    pirl_variants: tuple[Any, ...] = ()
    """PIRL configurations, each a mapping of pare overrides (e.g. {advisor: oracle, lam_cam:
    4}); empty = one PIRL with the preset's pare section and --advisor."""
    acts: tuple[str, ...] = ("stochastic", "greedy")
    """How trained policies act in evaluation (both are reported)."""
    headline_act: str = "stochastic"
    """The mode of the report's first table and figure, the same for every learned method."""
    train_workers: int = 0
    """Training runs at once, each a process with one torch and one numba thread (0 = cores)."""
    teacher_phase_answers: int = 0
    """A head start for slow teachers: before the PIRL runs of an LLM teacher in student mode,
    it answers this many planner states into the shared teacher dataset (in a worker of its
    own while PPO-SR and PPO-EWRI train; answers already there count), so the student passes
    its gate at the run's first rollouts. 0 = no teacher phase."""


_SECTIONS = {
    "ppo": PPOSettings,
    "train": TrainSettings,
    "pare": PareSettings,
    "advisor": AdvisorSettings,
    "il": ILSettings,
    "reproduce": ReproduceSettings,
}


@dataclass(frozen=True)
class RunConfig:
    """A whole preset: the environment plus every training section."""

    env: VCPPConfig = field(default_factory=VCPPConfig)
    ppo: PPOSettings = field(default_factory=PPOSettings)
    train: TrainSettings = field(default_factory=TrainSettings)
    pare: PareSettings = field(default_factory=PareSettings)
    advisor: AdvisorSettings = field(default_factory=AdvisorSettings)
    il: ILSettings = field(default_factory=ILSettings)
    reproduce: ReproduceSettings = field(default_factory=ReproduceSettings)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    """The physics simulator (``--sim physics``): wind, cell size, energy, timeouts."""

    def __post_init__(self) -> None:
        _validate(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunConfig:
        if not isinstance(data, dict):
            raise ConfigError("a run config is a mapping of sections")
        check_keys(data, ["env", *_SECTIONS, "physics"])
        parts: dict[str, Any] = {"env": VCPPConfig.from_dict(data.get("env") or {})}
        parts["physics"] = PhysicsConfig.from_dict(data.get("physics") or {})
        for name, section in _SECTIONS.items():
            values = data.get(name) or {}
            if not isinstance(values, dict):
                raise ConfigError(f"section {name!r} must be a mapping")
            check_keys(values, [f.name for f in fields(section)], name)
            kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
            parts[name] = section(**kwargs)
        return cls(**parts)

    @classmethod
    def from_yaml(cls, path: str | Path) -> RunConfig:
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"config file not found: {path}")
        try:
            data = yaml.safe_load(path.read_text())
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: not valid YAML: {exc}") from exc
        if data is None:
            # An empty file would silently train on built-in defaults that match no preset.
            raise ConfigError(
                f"{path} is empty; give settings (or {{}} for the built-in defaults), or a "
                "preset such as quick or test"
            )
        return cls.from_dict(data)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"env": self.env.to_dict()}
        for name in _SECTIONS:
            values = asdict(getattr(self, name))
            out[name] = {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}
        out["physics"] = self.physics.to_dict()
        return out

    def with_overrides(self, **sections: dict[str, Any]) -> RunConfig:
        """A copy with some values changed, e.g. ``with_overrides(train={"total_steps": 10})``."""
        data = self.to_dict()
        for name, values in sections.items():
            data.setdefault(name, {}).update(values)
        return RunConfig.from_dict(data)


def _validate(cfg: RunConfig) -> None:
    for name in _SECTIONS:
        section = getattr(cfg, name)
        for f in fields(section):
            value, default = getattr(section, f.name), f.default
            expected = type(default)
            if expected is float and isinstance(value, int) and not isinstance(value, bool):
                continue
            if not isinstance(value, expected) or (
                isinstance(value, bool) and expected is not bool
            ):
                raise ConfigError(
                    f"{name}.{f.name}={value!r} has type {type(value).__name__}; "
                    f"expected {expected.__name__}"
                )
    p, t, pare = cfg.ppo, cfg.train, cfg.pare
    positive = {
        "ppo.n_envs": p.n_envs, "ppo.n_steps": p.n_steps, "ppo.batch_size": p.batch_size,
        "ppo.n_epochs": p.n_epochs, "ppo.learning_rate": p.learning_rate,
        "ppo.torch_threads": p.torch_threads, "train.total_steps": t.total_steps,
        "train.checkpoint_every": t.checkpoint_every, "pare.query_every": pare.query_every,
        "pare.timeout_s": pare.timeout_s, "pare.student_fit_steps": pare.student_fit_steps,
        "pare.student_hidden": pare.student_hidden, "pare.failure_window": pare.failure_window,
        "il.expert_steps": cfg.il.expert_steps,
        "il.max_epochs": cfg.il.max_epochs, "il.batch_size": cfg.il.batch_size,
        "reproduce.episodes": cfg.reproduce.episodes,
        "reproduce.llm_only_episodes": cfg.reproduce.llm_only_episodes,
        "reproduce.workers": cfg.reproduce.workers, "reproduce.gif_every": cfg.reproduce.gif_every,
        "reproduce.physics_episodes": cfg.reproduce.physics_episodes,
        "advisor.openai_timeout_s": cfg.advisor.openai_timeout_s,
        "advisor.openai_deadline_s": cfg.advisor.openai_deadline_s,
        "advisor.probe_timeout_s": cfg.advisor.probe_timeout_s,
    }  # fmt: skip
    for key, value in positive.items():
        if value <= 0:
            raise ConfigError(f"{key}={value!r}: must be > 0")
    choices = {
        "ppo.lr_schedule": (p.lr_schedule, ("constant", "linear")),
        "ppo.device": (p.device, ("auto", "cpu", "cuda")),
        "pare.mode": (pare.mode, ("student", "sync", "async")),
        "pare.prompt_variant": (pare.prompt_variant, ("paper", "compact")),
    }
    for key, (value, allowed) in choices.items():
        if value not in allowed:
            raise ConfigError(f"{key}={value!r}: allowed values are {', '.join(allowed)}")
    for key, value in (
        ("pare.teacher_rate", pare.teacher_rate),
        ("pare.oracle_teacher_rate", pare.oracle_teacher_rate),
        ("pare.student_gate", pare.student_gate),
        ("pare.max_failure_rate", pare.max_failure_rate),
        ("pare.min_shaped", pare.min_shaped),
    ):
        if not 0 <= value <= 1:
            raise ConfigError(f"{key}={value!r}: must be in [0, 1]")
    if pare.student_refit_growth < 0:
        raise ConfigError(f"pare.student_refit_growth={pare.student_refit_growth!r}: must be >= 0")
    if cfg.reproduce.teacher_phase_answers < 0:
        raise ConfigError(
            f"reproduce.teacher_phase_answers={cfg.reproduce.teacher_phase_answers!r}: must be >= 0"
        )
    if not 0 < cfg.il.valid_fraction < 1:
        raise ConfigError(f"il.valid_fraction={cfg.il.valid_fraction!r}: must be in (0, 1)")
    if not all(isinstance(n, int) and n > 0 for n in p.net_arch):
        raise ConfigError(f"ppo.net_arch={list(p.net_arch)!r}: must be positive layer sizes")
    if not cfg.reproduce.seeds or not all(isinstance(v, int) for v in cfg.reproduce.seeds):
        raise ConfigError("reproduce.seeds must be a non-empty list of integers")
    if not 0 < p.gamma <= 1 or not 0 < p.gae_lambda <= 1:
        raise ConfigError("ppo.gamma and ppo.gae_lambda must be in (0, 1]")
