"""Run configuration: every value a user may change for training, in one YAML file.

A preset (``configs/quick.yaml``, ``paper.yaml``, ``test.yaml``) has the sections below (plus
``env``, :class:`~pirl.config.world.VCPPConfig`, and ``physics``,
:class:`~pirl.config.physics.PhysicsConfig`); each is a frozen dataclass with a docstring per
field, loaded and checked by :mod:`pirl.config.load`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from pirl.config.choices import Act, DatasetScope, PareMode
from pirl.config.load import Settings, check_keys, check_seed
from pirl.config.mission import MissionSettings
from pirl.config.physics import PhysicsConfig
from pirl.config.world import VCPPConfig


@dataclass(frozen=True)
class PPOSettings(Settings, section="ppo"):
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

    def validate(self) -> None:
        """Positive sizes and rates, known schedule and device, discounts in (0, 1]."""
        self.require_positive(
            "n_envs", "n_steps", "batch_size", "n_epochs", "learning_rate", "torch_threads"
        )
        self.require_choice("lr_schedule", ("constant", "linear"))
        self.require_choice("device", ("auto", "cpu", "cuda"))
        if not all(n > 0 for n in self.net_arch):
            raise self.refuse("net_arch", "must be positive layer sizes")
        for key in ("gamma", "gae_lambda"):
            if not 0 < getattr(self, key) <= 1:
                raise self.refuse(key, "must be in (0, 1]")


@dataclass(frozen=True)
class TrainSettings(Settings, section="train"):
    """Length, checkpoints and logging of a run."""

    total_steps: int = 300_000
    """Environment steps (all worlds together)."""
    checkpoint_every: int = 50_000
    """Write a resumable checkpoint at the first rollout boundary after every this many steps."""
    log_every_s: float = 10.0
    """Seconds between plain progress lines when the output is not a terminal."""
    camera_start: str = "fixed"
    """Training episodes start with the camera at the env's start pose ('fixed', the paper) or
    at a pose drawn uniformly on the camera grid ('random': exploring starts, so a policy meets
    wide footprints it would not find by chance) or, half the time each, both ('mixed').
    Evaluation always starts at the env's pose."""
    surveyed_start: float = 0.0
    """Share of training episodes that start with all ground covered but one random box
    (``env.start_surveyed``; evaluation never does): the work left lies out of sight, as on
    large worlds and sites, where a policy must follow the target to find it."""
    obstacles: tuple[int, ...] = ()
    """Training worlds' fewest and most obstacle spheres, ``[min, max]``, in place of the env's
    (evaluation keeps the env's): denser worlds than the evaluation's, so that a policy meets
    the clutter of larger worlds and sites while it learns. Empty: the env's."""
    stall_guard: int | None = None
    """``env.stall_guard`` while training, in place of the env's (evaluation keeps the env's);
    None: the env's. 0 trains without the guard a policy that is evaluated with it, which is
    what validation chose for ``quick`` (docs/results.md, "The stall guard")."""
    uavs: tuple[int, ...] = (1,)
    """Fleet sizes trained on together (docs/fleets.md): ``[1]`` one UAV per world; ``[1, 2,
    4]`` worlds of 1, 2 and 4 UAVs side by side, one policy shared by every UAV (PIRL's advice
    is asked about each UAV, its teammates named). PPO methods and PIRL; imitation learns on
    ``[1]``."""
    steps_by_method: dict[str, int] = field(default_factory=dict)
    """Environment steps of particular methods, by name (``{ppo-ewri: 1638400}``), in place of
    total_steps: each method's own budget, as RL Zoo keeps one per algorithm. The method
    registry checks the names when a run is planned (pirl.agents.settings.check_budgets)."""
    uavs_by_method: dict[str, tuple[int, ...]] = field(default_factory=dict)
    """Fleet sizes of particular methods, by name (``{pirl: [1, 2, 4]}``), in place of
    ``uavs``: a fleet curriculum for the methods trained in an environment while imitation
    learns on ``[1]`` (docs/fleets.md, "A fleet curriculum"). Checked like
    ``steps_by_method``."""

    def validate(self) -> None:
        """A positive length and checkpoint interval, a known camera start."""
        self.require_positive("total_steps", "checkpoint_every")
        self.require_choice("camera_start", ("fixed", "random", "mixed"))
        if not 0.0 <= self.surveyed_start <= 1.0:
            raise self.refuse("surveyed_start", "must be a share in [0, 1]")
        if self.obstacles and (
            len(self.obstacles) != 2 or not 0 <= self.obstacles[0] <= self.obstacles[1]
        ):
            raise self.refuse("obstacles", "write [min, max] with 0 <= min <= max, or leave it out")
        if self.stall_guard is not None and self.stall_guard < 0:
            raise self.refuse("stall_guard", "must be >= 0 (0: off), or leave it out")
        for name, steps in self.steps_by_method.items():
            if steps <= 0:
                raise self.refuse("steps_by_method", f"{name}: must be > 0")
        if not self.uavs or any(not isinstance(k, int) or k < 1 for k in self.uavs):
            raise self.refuse("uavs", "write fleet sizes >= 1, e.g. [1, 2, 4]")
        for name, sizes in self.uavs_by_method.items():
            if not sizes or any(k < 1 for k in sizes):
                raise self.refuse(
                    "uavs_by_method", f"{name}: write fleet sizes >= 1, e.g. [1, 2, 4]"
                )


@dataclass(frozen=True)
class PareSettings(Settings, section="pare"):
    """PIRL's reward shaping (docs/advice.md)."""

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
    """Student mode, ``student_gate_on: agreement``: held-out agreement with the teacher
    before the student shapes rewards."""
    student_gate_on: str = "kappa"
    """Student mode: what opens the gate. 'kappa': the student's Cohen's kappa against the
    teacher over the fields the teacher varies reaches student_kappa_gate (what the student
    learned of the teacher's signal, so an imperfect teacher passes and a near-constant one
    does not); 'move_kappa': the same over the move fields (dx, dy, dz) only; 'best_kappa':
    the highest kappa of any informative field; 'agreement': raw held-out agreement reaches
    student_gate (a noisy teacher can never pass it). Chosen on distillation states and on a
    study's recorded answers: docs/advice.md."""
    student_kappa_gate: float = 0.1
    """Student mode, ``student_gate_on: kappa``: the kappa that opens the gate."""
    student_gate_close: float = 0.5
    """Student mode: once open, the gate closes again only when its measure falls below this
    share of the threshold that opened it (1 = no hysteresis). A noisy teacher's kappa,
    measured on a few hundred held-out answers, wanders around the threshold from refit to
    refit; without hysteresis its shaping switched on and off (docs/advice.md)."""
    student_closed_rate: float = 4.0
    """Student mode: while the student's gate is closed the teacher is asked this many times
    as often (its rate times this), so a student still short of its gate gets more answers to
    learn from; back to the rate once it opens. 1 = always the rate. Chosen on validation
    runs (docs/advice.md): the 50%- and 75%-accurate oracles' runs shaped 91-97% of their
    steps (72-89% at 1), the pure-noise teacher's none. It costs an LLM teacher's calls only
    while its student has not passed (the price gives the least and the most)."""
    student_fit_steps: int = 100
    """Student mode: Adam steps per refit (at rollout boundaries with new teacher answers)."""
    student_refit_growth: float = 0.25
    """Student mode: once past its gate, the student is refit only when the teacher's answers
    have grown by this share since its last fit (0 = at every rollout with new answers)."""
    student_hidden: int = 128
    """Student mode: width of the student's two hidden layers."""
    student_min_heldout: int = 20
    """Student mode: fewest held-out teacher answers (about one in five is held out) before
    the student's score is trusted and its gate can open."""
    student_dataset: str = ""
    """Teacher answers with their states; empty = student.sqlite beside the answer cache."""
    student_dataset_scope: str = "run"
    """Student mode: 'run': each run learns only from the answers it asked for itself, after
    a head start copied once before it trains (the first ``reproduce.teacher_phase_answers``
    answers of its teacher's phase, for an LLM teacher), so a seed's model never depends on
    what another seed stores while it trains; a fresh start drops what an earlier run of its
    folder stored. 'shared': every run of the same teacher and settings learns from every
    answer stored so far, its neighbours' included (faster to shape, not reproducible when
    seeds train side by side)."""
    student_wait_teacher: bool = True
    """Student mode: at each rollout boundary, wait for the teacher's batch sent at the
    previous one, so the student's data arrive at steps fixed by the run, not by the
    machine's load (reproducible). False: never wait (PPO runs ahead of a slow teacher; the
    answers arrive at steps that depend on load)."""
    max_failure_rate: float = 0.5
    """Stop training when more than this share of the last failure_window teacher answers
    failed or did not parse (0 = never stop)."""
    failure_window: int = 200
    """Teacher answers in the rolling failure rate."""
    min_shaped: float = 0.5
    """A PIRL run with less than this share of its steps shaped (by the student or the
    teacher) ends with a warning, and its label in summaries, tables, figures and the report
    carries ``unshaped N%``: it trained mostly as PPO-EWRI."""

    def gate(self) -> tuple[float, str]:
        """The student's gate: (threshold, ``"kappa"`` or ``"agreement"``)."""
        if self.student_gate_on == "agreement":
            return self.student_gate, "agreement"
        return self.student_kappa_gate, self.student_gate_on

    def gate_close(self) -> float:
        """The measure below which an open gate closes again (hysteresis)."""
        return self.gate()[0] * self.student_gate_close

    def validate(self) -> None:
        """Positive intervals and sizes, known mode and prompt, shares in [0, 1]."""
        self.require_positive(
            "query_every",
            "timeout_s",
            "student_fit_steps",
            "student_hidden",
            "student_min_heldout",
            "failure_window",
        )
        self.require_choice("mode", PareMode)
        if not self.prompt_variant.startswith(TEMPLATE_VARIANT):
            self.require_choice("prompt_variant", ("paper", "compact"))
        self.require_choice(
            "student_gate_on", ("kappa", "kappa_lcb", "move_kappa", "best_kappa", "agreement")
        )
        self.require_choice("student_dataset_scope", DatasetScope)
        for key in (
            "teacher_rate", "oracle_teacher_rate", "student_gate", "max_failure_rate",
            "min_shaped", "student_kappa_gate", "student_gate_close",
        ):  # fmt: skip
            if not 0 <= getattr(self, key) <= 1:
                raise self.refuse(key, "must be in [0, 1]")
        if self.student_refit_growth < 0:
            raise self.refuse("student_refit_growth", "must be >= 0")
        if self.student_closed_rate < 1:
            raise self.refuse("student_closed_rate", "must be >= 1 (a multiple of the rate)")


@dataclass(frozen=True)
class AdvisorSettings(Settings, section="advisor"):
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
    prompt_file: str = ""
    """A Jinja2 template of your own prompt (its variables: docs/advice.md); empty = the
    built-in prompt pare.prompt_variant names. The reply format, the parser and the grammar
    stay PIRL's, so the template must ask for that format (examples/prompts/ holds the
    built-in prompts as templates). Its text's hash joins the keys of stored answers."""
    oracle_accuracy: float = 1.0
    """'oracle' only: the share of states whose answer is the oracle's own; the others get a
    valid answer drawn uniformly, seeded by the prompt (a stand-in for an imperfect LLM:
    docs/advice.md). 1.0 is the oracle itself."""

    def validate(self) -> None:
        """Positive timeouts, an accuracy in [0, 1]."""
        self.require_positive("openai_timeout_s", "openai_deadline_s", "probe_timeout_s")
        if not 0.0 <= self.oracle_accuracy <= 1.0:
            raise self.refuse("oracle_accuracy", "must be in [0, 1]")


@dataclass(frozen=True)
class ILSettings(Settings, section="il"):
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

    def validate(self) -> None:
        """Positive sizes, a validation share in (0, 1)."""
        self.require_positive("expert_steps", "max_epochs", "batch_size")
        if not 0 < self.valid_fraction < 1:
            raise self.refuse("valid_fraction", "must be in (0, 1)")


@dataclass(frozen=True)
class ReproduceSettings(Settings, section="reproduce"):
    """What ``pirl reproduce`` trains and evaluates."""

    seeds: tuple[int, ...] = (0,)
    """Training seeds per method; their episodes pool into the confidence intervals."""
    sizes: tuple[str | int, ...] = ("30", "45", "60")
    """Evaluation worlds (N for NxNx3, or XxYxZ)."""
    episodes: int = 100
    """Scenarios per size for every method."""
    llm_only_episodes: int = 100
    """Scenarios per size for LLM-only (it calls the LLM every few steps, so it is slow)."""
    llm_only_max_calls: int = 0
    """LLM calls allowed per LLM-only episode (0 = no limit); after that it holds still."""
    oracle_pirl: bool = True
    """Also train PIRL with the oracle advisor (a labelled extra, not an LLM)."""
    physics_sizes: tuple[str | int, ...] = ("30", "45", "60")
    """Worlds flown in the physics simulator (empty = no physics table)."""
    physics_episodes: int = 100
    """Scenarios per size in the physics simulator (the same seeds as the grid's first ones)."""
    sites: tuple[str, ...] = ()
    """Site folders (docs/sites.md) every method is also evaluated on, zero-shot, in the grid
    simulator (relative paths: from the working folder, else from the repository)."""
    missions: bool = False
    """For each of ``sites``: write the planner's and the best learned policy's missions
    (``pirl plan``) into ``<out>/missions/``, fly them back from their files in PyFlyt
    (``pirl fly``) and put both in the report."""
    uavs: tuple[int, ...] = ()
    """Fleet sizes (docs/fleets.md) the planner and the trained runs of ``fleet_methods`` are
    also flown at on each of ``sites`` (``pirl evaluate --uavs``; K = 1 among them for the
    speed-ups), into the report's Fleets table and figure. Empty: no fleets."""
    fleet_methods: tuple[str, ...] = ("ppo-ewri",)
    """Trained methods flown in fleets (the planner always is); a method's every run flies,
    each of its variants (``pirl``: pirl-local and pirl-oracle)."""
    workers: int = 2
    """Evaluation worker processes."""
    gif_every: int = 2
    """Record every n-th frame of the report's animations."""
    methods: tuple[str, ...] = ("ppo-sr", "ppo-ewri", "pirl", "il")
    """Methods trained per seed (il needs ppo-ewri; pirl trains once per pirl_variants entry)."""
    builtins: tuple[str, ...] = ("llm-only", "boustrophedon", "random")
    """Methods evaluated without training."""
    pirl_variants: tuple[Any, ...] = ()
    """PIRL configurations, each a mapping of pare (or advisor) overrides (e.g. {advisor:
    oracle, lam_cam: 4, oracle_accuracy: 0.5}); empty = one PIRL with the preset's pare
    section and --advisor."""
    acts: tuple[str, ...] = tuple(Act)
    """How trained policies act in evaluation (both are reported)."""
    headline_act: str = "stochastic"
    """The mode of the report's first table and figure, the same for every learned method."""
    train_workers: int = 0
    """Training runs at once, each a process with one torch and one numba thread (0 = cores)."""
    score_states: int = 0
    """Score each PIRL variant's advisor against the oracle on this many validation states
    (``pirl advise --score``) and draw the advice-quality curve in the report (0 = no)."""
    teacher_phase_answers: int = 0
    """A head start for slow teachers: before the PIRL runs of an LLM teacher in student mode,
    it answers this many planner states into the shared teacher dataset (in a worker of its
    own while PPO-SR and PPO-EWRI train; answers already there count), so the student passes
    its gate at the run's first rollouts. 0 = no teacher phase."""

    def validate(self) -> None:
        """At least one seed, positive episode and worker counts."""
        self.require_positive(
            "episodes", "llm_only_episodes", "workers", "gif_every", "physics_episodes"
        )
        if self.teacher_phase_answers < 0:
            raise self.refuse("teacher_phase_answers", "must be >= 0")
        if self.score_states < 0:
            raise self.refuse("score_states", "must be >= 0")
        if not self.seeds:
            raise self.refuse("seeds", "must be a non-empty list of integers")
        for seed in self.seeds:
            check_seed(seed, "reproduce.seeds:")
        if any(not isinstance(k, int) or k < 1 for k in self.uavs):
            raise self.refuse("uavs", "write fleet sizes >= 1, e.g. [1, 2, 4], or leave it out")
        if self.uavs and not self.sites:
            raise self.refuse("uavs", "fleets fly on reproduce.sites: name at least one site")


TEMPLATE_VARIANT = "file:"
"""``pare.prompt_variant`` of a run whose prompt is ``advisor.prompt_file``'s template."""


@dataclass(frozen=True)
class RunConfig(Settings):
    """A whole preset: the environment plus every training section."""

    env: VCPPConfig = field(default_factory=VCPPConfig)
    """The grid world and the environment (``env``)."""
    ppo: PPOSettings = field(default_factory=PPOSettings)
    """PPO and the batched environment it trains on."""
    train: TrainSettings = field(default_factory=TrainSettings)
    """Length, checkpoints and logging of a run."""
    pare: PareSettings = field(default_factory=PareSettings)
    """PIRL's reward shaping."""
    advisor: AdvisorSettings = field(default_factory=AdvisorSettings)
    """LLM backends."""
    il: ILSettings = field(default_factory=ILSettings)
    """Imitation learning."""
    reproduce: ReproduceSettings = field(default_factory=ReproduceSettings)
    """What ``pirl reproduce`` trains and evaluates."""
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    """The physics simulator (``--sim physics``): wind, cell size, energy, timeouts."""
    mission: MissionSettings = field(default_factory=MissionSettings)
    """Missions written by ``pirl plan``: speeds, battery, item and altitude limits."""

    def validate(self) -> None:
        """``advisor.prompt_file`` becomes the prompt (``pare.prompt_variant: file:<path>``,
        the path made absolute, so workers in other folders read the same file)."""
        path = self.advisor.prompt_file
        if path:
            from pathlib import Path

            file = Path(path).expanduser()
            if not file.is_file():
                raise self.advisor.refuse("prompt_file", "no such file")
            variant = TEMPLATE_VARIANT + str(file.resolve())
            if self.pare.prompt_variant != variant:
                object.__setattr__(self, "pare", self.pare.replace(prompt_variant=variant))

    def with_variant(self, variant: dict[str, Any]) -> RunConfig:
        """A copy with a PIRL variant applied: each key of ``variant`` goes to the section that
        has it, ``pare`` first, then ``advisor`` (e.g. ``{advisor: oracle, lam_cam: 4,
        oracle_accuracy: 0.5}``); a key of neither is refused naming both sections' keys."""
        pare_keys = {f.name for f in dataclasses.fields(PareSettings)}
        advisor_keys = {f.name for f in dataclasses.fields(AdvisorSettings)}
        check_keys(variant, sorted(pare_keys | advisor_keys), "reproduce.pirl_variants")
        pare = {k: v for k, v in variant.items() if k in pare_keys}
        advisor = {k: v for k, v in variant.items() if k not in pare_keys}
        return self.with_overrides(pare=pare, advisor=advisor)

    def with_overrides(self, **sections: dict[str, Any]) -> RunConfig:
        """A copy with some values changed, e.g. ``with_overrides(train={"total_steps": 10})``."""
        data = self.to_dict()
        for name, values in sections.items():
            data.setdefault(name, {}).update(values)
        return RunConfig.from_dict(data)


__all__ = [
    "AdvisorSettings",
    "ILSettings",
    "PPOSettings",
    "PareSettings",
    "ReproduceSettings",
    "RunConfig",
    "TrainSettings",
]
