"""torch as PIRL runs it, set once per process before a policy is built or loaded.

Two of torch's defaults cost time in every process that trains or loads a policy and change
no number:

- **The argument checks of ``torch.distributions``.** Every action distribution PPO builds
  (one per rollout step and per minibatch, two per masked step in sb3-contrib) checks that its
  logits are finite reals, about 0.3 ms a call. PIRL turns them off (torch's own switch). A
  NaN still stops a run where it matters: sampling an action from NaN logits raises in
  ``torch.multinomial``.
- **The optimizers' hooks for ``torch.compile``.** ``Optimizer.add_param_group``,
  ``zero_grad``, ``state_dict``, ``load_state_dict`` and ``Adam.step`` are wrapped
  so that a compiled graph breaks around them; the first call of any of them imports
  ``torch._dynamo``, 1.2-2.3 CPU-s per process (PPO builds its Adam when a policy is built or
  loaded). PIRL never compiles, so :func:`configure` rebinds them to the functions they wrap
  (``step`` keeps its one effect outside compilation: gradients off while it runs). The
  weights are the same to the bit (``tests/test_agents_policies.py``).
"""

from __future__ import annotations

import functools
from typing import Any

__all__ = ["configure"]


def _without_compile_hooks() -> None:
    import inspect

    import torch
    from torch.optim.optimizer import Optimizer

    for name in ("add_param_group", "zero_grad", "state_dict", "load_state_dict"):
        setattr(Optimizer, name, inspect.unwrap(getattr(Optimizer, name)))
    # Adam is the optimizer PIRL's code builds (PPO's policies, the student); an Adam made
    # after this gets torch's step hooks (``profile_hook_step``) around this step again.
    step = inspect.unwrap(torch.optim.Adam.step)

    @functools.wraps(step)
    def no_grad_step(self: Any, closure: Any = None) -> Any:
        with torch.no_grad():
            return step(self, closure)

    torch.optim.Adam.step = no_grad_step


@functools.cache
def configure() -> None:
    """Set this process's torch for training and inference (idempotent, cheap)."""
    from torch.distributions import Distribution

    Distribution.set_default_validate_args(False)
    _without_compile_hooks()
