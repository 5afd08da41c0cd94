"""Exceptions raised by roft_sim.

Every message says what was received, what was expected, and how to fix it. The CLI maps
`ConfigError` to exit code 2 (usage/config problem) and any other `RoftSimError` to exit code 1.
"""

from __future__ import annotations


class RoftSimError(Exception):
    """Base class of every error roft_sim raises on purpose."""


class ConfigError(RoftSimError, ValueError):
    """A configuration value, file or command-line argument is invalid."""


class DatasetFormatError(RoftSimError):
    """A file on disk (dataset, trajectory, asset) does not follow its documented format."""


class PluginError(RoftSimError):
    """A tracker plugin could not be found, loaded or registered."""


class RenderBackendError(RoftSimError):
    """No offscreen OpenGL backend (EGL or OSMesa) could be initialised."""


class AssetNotFoundError(RoftSimError):
    """An object mesh or asset archive is missing."""


def located(path: object, line: int | None = None) -> str:
    """Formats a file location for messages: ``'path'`` or ``'path', line 12``."""
    return f"{str(path)!r}" + (f", line {line}" if line is not None else "")
