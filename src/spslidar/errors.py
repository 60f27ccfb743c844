"""Exceptions raised for bad input.

Every user-facing error is a :class:`SpslidarError`; the command-line tool prints its message as
one line on stderr and exits with status 2.
"""

from __future__ import annotations


class SpslidarError(ValueError):
    """A user-facing error with a one-line message (bad config, bad scene, bad code length...)."""


class ConfigError(SpslidarError):
    """An invalid configuration value."""


class SceneError(SpslidarError):
    """A scene that cannot be read or is physically invalid (NaN or negative depth...)."""
