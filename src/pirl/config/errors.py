"""The two errors a user sees as one line (the command line exits with code 2 on either)."""

from __future__ import annotations


class ConfigError(ValueError):
    """A configuration value is unknown, of the wrong type, or impossible."""


class UserError(ConfigError):
    """A mistake the user can fix that is not a config value: a missing API key, a damaged or
    missing run file, an expert run that cannot serve. The command line prints it as one line
    (like every ConfigError) and exits with code 2."""


__all__ = ["ConfigError", "UserError"]
