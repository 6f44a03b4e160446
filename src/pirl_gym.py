"""Registers ``pirl/VCPP-v0`` with Gymnasium in any interpreter, before ``import pirl``.

Gymnasium 1.x finds third-party environments only once their package is imported (it dropped
the plugin entry points of 0.26-0.29), so ``gym.make("pirl/VCPP-v0")`` alone fails. The
one-line ``pirl_gym.pth`` that ``python -m pirl_gym`` writes into the environment's
``site-packages`` (``make`` does it for the project's ``.venv``) imports this module at start-up.
It imports nothing heavy: it waits for the interpreter's first ``import gymnasium`` and
registers the environment's id then, with entry points named as strings, so PIRL itself is
imported only when an environment is made. ``pirl/__init__`` registers through the same
:func:`register`.
"""

from __future__ import annotations

import sys

# No other import at module level: every interpreter of the venv runs this at start-up
# (typing alone would cost 15 ms there).

ENV_ID = "pirl/VCPP-v0"
PTH_NAME = "pirl_gym.pth"


def register(gym) -> None:  # gym: the gymnasium module (typing costs start-up time)
    """Register ``pirl/VCPP-v0`` (single env, batched vector env) with ``gym`` once."""
    if ENV_ID not in gym.registry:
        gym.register(
            id=ENV_ID,
            entry_point="pirl.env.vcpp_env:VCPPEnv",
            vector_entry_point="pirl.env.gym_vector:VCPPVectorEnv",
        )


class _AfterGymnasium:
    """A meta path finder (duck-typed: importlib.abc costs 20 ms at every start-up) that
    finds nothing itself; when ``gymnasium`` is first imported, its module registers the id
    right after it has run."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> object:
        if name != "gymnasium":
            return None
        import importlib.util

        sys.meta_path.remove(self)  # once, and the real finders give the spec
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        run = spec.loader.exec_module

        def exec_module(module: object) -> None:
            run(module)
            register(module)

        spec.loader.exec_module = exec_module  # type: ignore[method-assign]
        return spec


def install_hook() -> None:
    """Register now if gymnasium is imported, else on its first import (the ``.pth`` line)."""
    if "gymnasium" in sys.modules:
        register(sys.modules["gymnasium"])
    elif not any(isinstance(f, _AfterGymnasium) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterGymnasium())


def write_pth(site_packages: str | None = None) -> str:
    """Write ``pirl_gym.pth`` into ``site_packages`` (default: this interpreter's)."""
    import sysconfig
    from pathlib import Path

    path = Path(site_packages or sysconfig.get_paths()["purelib"]) / PTH_NAME
    path.write_text("import pirl_gym; pirl_gym.install_hook()\n")
    return str(path)


if __name__ == "__main__":
    print(f"wrote {write_pth()}: gym.make('{ENV_ID}') works without importing pirl")
