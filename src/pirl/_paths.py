"""The one folder where PIRL keeps what it computes once: converted models, compiled
kernels, the advice cache and the teacher dataset."""

from __future__ import annotations

import os
from pathlib import Path


def cache_root(override: str | os.PathLike[str] | None = None) -> Path:
    """The PIRL cache folder: ``override``, else ``$PIRL_CACHE_DIR``, else ``~/.cache/pirl``.

    An empty ``$PIRL_CACHE_DIR`` counts as unset; ``~`` is expanded in either.
    """
    if override is not None:
        return Path(override).expanduser()
    env = os.environ.get("PIRL_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    return Path.home() / ".cache" / "pirl"
