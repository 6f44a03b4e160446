"""torch as PIRL runs it, set once per process before a policy is built or loaded.

One of torch's defaults costs time in every process that trains or loads a policy and
changes no number: **the argument checks of ``torch.distributions``**. Every action
distribution PPO builds (one per rollout step and per minibatch, two per masked step in
sb3-contrib) checks that its logits are finite reals, about 0.3 ms a call. PIRL turns them
off (torch's own switch). A NaN still stops a run where it matters: sampling an action from
NaN logits raises in ``torch.multinomial``.
"""

from __future__ import annotations

import functools

__all__ = ["configure"]


@functools.cache
def configure() -> None:
    """Set this process's torch for training and inference (idempotent, cheap)."""
    from torch.distributions import Distribution

    Distribution.set_default_validate_args(False)
