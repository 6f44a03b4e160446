"""Every method PIRL trains or plays, by name, with the facts the rest of the code reads.

An entry (:class:`Method`) says how the method trains (PPO on a reward, imitation of another
method's run, or not at all for a built-in), whether PARE shapes its reward with advice, the
file its policy is saved in, its label, its place in the reports and its run folders' names.
``pirl train``'s choices, ``pirl reproduce``'s plan, the policy loader, the report's order and
labels all read this table; nothing else compares method names. Its order is the reports'
order.

The functions that train and load (:func:`pirl.agents.runs.train_run`,
:func:`pirl.agents.loading.load_policy`) choose by the entry's ``training``, so a new method
that trains like an existing one is one entry here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from pirl.advice.registry import BUILTIN as BUILTIN_ADVISORS
from pirl.config.errors import ConfigError

if TYPE_CHECKING:
    from pirl.config.world import VCPPConfig

TRAIN_PPO = "ppo"
"""``training`` of a method trained by :func:`pirl.agents.train.train` (SB3 PPO)."""
TRAIN_IMITATION = "imitation"
"""``training`` of a method fitted by :func:`pirl.agents.imitation.train_il` on its expert."""
PLAYED = ""
"""``training`` of a built-in method: a planner or rule, played as it is."""

PPO_ARTIFACT = "model.zip"
"""The file that holds a PPO policy (SB3's save): a finished run's and each checkpoint's."""
IMITATION_ARTIFACT = "tabnet.zip"
"""The file that holds an imitation (TabNet) policy."""


@dataclass(frozen=True)
class Method:
    """One method and what the code needs to know about it."""

    name: str
    """What ``--method``, ``reproduce.methods`` and run folders say."""
    label: str
    """What reports and progress lines call it."""
    training: str = TRAIN_PPO
    """How it trains: :data:`TRAIN_PPO`, :data:`TRAIN_IMITATION` or :data:`PLAYED` (not at all)."""
    reward: str = "ewri"
    """PPO: the reward weights it trains on (``env.reward``)."""
    advised: bool = False
    """PARE shapes its reward with an advisor's advice (the pare and advisor sections apply,
    and the run needs an advisor)."""
    expert: str = ""
    """Imitation: the method whose finished run of the same seed it learns from."""
    artifact: str = PPO_ARTIFACT
    """The file of a finished run that holds the policy."""
    paper: bool = True
    """A method of the paper's tables (the others come after them in reports)."""
    asks: bool = False
    """Played by asking an advisor at every step (LLM-only): it takes ``--advisor``, plays
    ``reproduce.llm_only_episodes`` scenarios and its calls are counted."""
    policy: str = ""
    """Played methods: the :class:`~pirl.agents.policy.Policy` class that plays it, as
    ``module:Class`` (imported only when the method is played)."""
    planner: bool = False
    """The coverage planner: the reference learned methods are measured against (the
    report's gap, the missions, the states a teacher phase asks about)."""
    animated: bool = True
    """``pirl reproduce`` records a GIF of it (a random walk's animation shows nothing)."""
    fleet: bool = True
    """It can fly in a fleet (``--uavs``): a learned policy shared by every UAV, the planner
    over the area split, one random walk or LLM-only (its prompt naming the teammates) per
    UAV. A method registered with False is refused ``--uavs`` in one line."""
    options: tuple[str, ...] = ()
    """The ``pirl train`` options of this method beyond those every method takes (``--out``,
    ``--config``, ``--steps``, ``--seed``, ``--resume``); any other is refused."""
    short: str = ""
    """What the HTML report's tables, findings and figures call it (the label when empty);
    the page's legend gives the full label once."""
    views: bool = False
    """PPO: it chooses among candidate views (macro actions, :mod:`pirl.env.views`), not
    among the 12 primitive actions; its ``train.total_steps`` counts choices."""

    @property
    def plays_alone(self) -> bool:
        """A built-in that plays by its own rule, with no run folder and no advisor: what
        ``pirl render``, ``pirl plan --method`` and ``pirl distill --policy`` can fly."""
        return self.training == PLAYED and not self.asks

    def check_options(self, **given: object) -> None:
        """Refuse, in one line, a ``pirl train`` option this method does not use (given = not
        None)."""
        for name, value in given.items():
            if value is not None and name not in self.options:
                takes = ", ".join(f"--{o}" for o in self.options) or "none of its own"
                raise ConfigError(
                    f"--{name} is not an option of --method {self.name} (it takes {takes})"
                )

    def check_expert(self, run: str, expert_method: str) -> None:
        """Imitation: refuse an expert run of another method than :attr:`expert`."""
        if expert_method != self.expert:
            raise ConfigError(
                f"--expert {run} is a {expert_method} run; --method {self.name} learns from a "
                f"finished {self.expert} run"
            )

    def folder(self, seed: int) -> str:
        """The run folder of this method and seed in ``pirl reproduce``'s ``runs/``."""
        return f"{self.name}-s{seed}"

    def expert_folder(self, seed: int) -> str:
        """Imitation: the run folder of the expert it learns from."""
        return method(self.expert).folder(seed)

    def trains_on(self, env: VCPPConfig) -> VCPPConfig:
        """``env`` as this PPO method trains and is judged on it: its reward weights, and the
        LLM weight switched on for an advised method."""
        return env.replace(reward=self.reward, llm_weight=self.advised)


METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method("ppo-sr", "PPO-SR", reward="static"),
        Method("ppo-ewri", "PPO-EWRI"),
        Method(
            "llm-only",
            "LLM-only",
            training=PLAYED,
            asks=True,
            policy="pirl.agents.llm_only:LLMOnlyPolicy",
        ),
        Method(
            "il",
            "IL",
            training=TRAIN_IMITATION,
            expert="ppo-ewri",
            artifact=IMITATION_ARTIFACT,
            options=("expert",),
        ),  # fmt: skip
        Method("pirl", "PIRL", advised=True, options=("advisor", "student")),
        Method(
            "ppo-views",
            "PPO over candidate views (macro actions)",
            short="PPO-views",
            reward="static",
            paper=False,
            fleet=False,
            views=True,
        ),
        Method(
            "boustrophedon",
            "boustrophedon (planner)",
            short="Planner",
            training=PLAYED,
            paper=False,
            policy="pirl.agents.boustrophedon:BoustrophedonPolicy",
            planner=True,
        ),
        Method(
            "random",
            "random",
            short="Random",
            training=PLAYED,
            paper=False,
            policy="pirl.agents.policy:RandomPolicy",
            animated=False,
        ),
    )
}
"""Every method, in the reports' order."""

IL = METHODS["il"]
"""The imitation baseline, for its own trainer (:mod:`pirl.agents.imitation`)."""
PLANNER = next(m for m in METHODS.values() if m.planner)
"""The coverage planner (boustrophedon)."""
ADVISED = next(m for m in METHODS.values() if m.advised)
"""The advised method (PIRL): the env its advisor, teacher and student are asked about is
``ADVISED.trains_on(env)``."""

TRAINED = tuple(m.name for m in METHODS.values() if m.training != PLAYED)
"""Methods that train into a run folder."""
PPO_METHODS = tuple(m.name for m in METHODS.values() if m.training == TRAIN_PPO)
"""Methods trained with PPO."""
BUILTIN = tuple(m.name for m in METHODS.values() if m.training == PLAYED)
"""Methods played without training (by name instead of a run folder)."""
PLAYED_ALONE = tuple(m.name for m in METHODS.values() if m.plays_alone)
"""Built-ins that play alone (:attr:`Method.plays_alone`), in :data:`METHODS` order."""
PAPER_METHODS = tuple(m.name for m in METHODS.values() if m.paper)
"""The paper's methods, in its tables' order."""


def method(name: str) -> Method:
    """The entry named ``name``; :class:`ConfigError` (one line, the known names) if none."""
    found = METHODS.get(str(name))
    if found is None:
        raise ConfigError(f"unknown method {name!r} (known: {', '.join(METHODS)})")
    return found


def trained_method(name: str, what: str = "method") -> Method:
    """The entry of a method that trains; one line naming those that do if ``name`` does not."""
    found = METHODS.get(str(name))
    if found is None or found.training == PLAYED:
        raise ConfigError(f"{what}: {name!r} is not trained ({', '.join(TRAINED)})")
    return found


def is_planner(key: str) -> bool:
    """Whether an evaluation key names the coverage planner (an unknown key does not)."""
    found = METHODS.get(str(key))
    return found is not None and found.planner


def asks(name: str) -> bool:
    """Whether method ``name`` plays by asking an advisor (an unknown name does not)."""
    found = METHODS.get(str(name))
    return found is not None and found.asks


def label(name: str) -> str:
    """A method's label (an unknown name is its own label)."""
    found = METHODS.get(name)
    return found.label if found is not None else name


def advised_key(name: str, advisor: str) -> str:
    """The evaluation key of an advised method's runs: its own name, or ``<method>-<advisor>``
    for an advisor that is not an LLM (e.g. ``pirl-oracle``), which reports show apart."""
    kind = BUILTIN_ADVISORS.get(advisor)
    return f"{name}-{advisor}" if kind is not None and not kind.llm else name


def is_advised_key(key: str) -> bool:
    """Whether an evaluation key (``pirl``, ``pirl-oracle``, ``pirl:<label slug>``) belongs
    to an advised method."""
    return any(
        key == m.name or key.startswith((f"{m.name}-", f"{m.name}:"))
        for m in METHODS.values()
        if m.advised
    )


def report_order(key: str) -> tuple[int, str]:
    """Sort key of an evaluation key in reports: the paper's methods, advised methods with an
    advisor that is not an LLM, then the others, each in :data:`METHODS` order."""
    advised = [m.name for m in METHODS.values() if m.advised and m.paper]
    extras = [advised_key(m, a) for m in advised for a in BUILTIN_ADVISORS]
    order = [
        *PAPER_METHODS,
        *[k for k in extras if k not in METHODS],
        *[m.name for m in METHODS.values() if not m.paper],
    ]
    return (order.index(key) if key in order else len(order), key)


__all__ = [
    "ADVISED",
    "BUILTIN",
    "IL",
    "METHODS",
    "PAPER_METHODS",
    "PLAYED",
    "PLANNER",
    "PLAYED_ALONE",
    "PPO_METHODS",
    "TRAIN_IMITATION",
    "TRAIN_PPO",
    "TRAINED",
    "Method",
    "advised_key",
    "asks",
    "is_advised_key",
    "is_planner",
    "label",
    "method",
    "report_order",
    "trained_method",
]
