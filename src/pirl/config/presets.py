"""Presets: the bundled profiles (quick, paper, test, the studies) and YAML files by path."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from pirl.config.errors import ConfigError
from pirl.config.load import read_yaml
from pirl.config.run import RunConfig
from pirl.config.world import VCPPConfig

BUNDLED = Path(__file__).resolve().parents[3] / "configs"
"""The presets shipped beside the package (a source checkout or an editable install)."""


def preset_path(profile: str | Path, option: str = "--config") -> Path:
    """A preset by name (quick, paper, test) or path: a file that exists, else
    ``configs/<name>.yaml`` here, else the bundled one (whatever the working directory)."""
    given = Path(profile)
    if given.is_file():
        return given
    name = given.name if given.suffix in (".yaml", ".yml") else f"{given.name}.yaml"
    for candidate in (Path("configs") / name, BUNDLED / name):
        if candidate.is_file() and (given.parent in (Path("."), Path("configs"))):
            return candidate
    known = ", ".join(sorted(p.stem for p in BUNDLED.glob("*.yaml"))) or "quick, paper"
    raise ConfigError(f"{option} {str(profile)!r}: no such file or bundled preset (try {known})")


def load_preset(config: str | Path | None, option: str = "--config") -> RunConfig:
    """Every section of a preset by name or path; None: the defaults."""
    if not config:
        return RunConfig()
    path = preset_path(config, option)
    try:
        return RunConfig.from_yaml(path)
    except ConfigError:
        _refuse_env_only(path)
        raise


def _refuse_env_only(path: Path) -> None:
    """Say where the settings of an env-only file go: under ``env:``, as in every preset."""
    data = read_yaml(path)
    env_keys = {f.name for f in dataclasses.fields(VCPPConfig)}
    if isinstance(data, dict) and data and set(data) <= env_keys:
        raise ConfigError(
            f"--config {path}: {', '.join(map(str, data))} are env settings; a preset holds "
            "them under 'env:' (see configs/quick.yaml)"
        )


__all__ = ["BUNDLED", "load_preset", "preset_path"]
