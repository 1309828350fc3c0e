"""The one error family of colorglove_ros: every typed error derives from ``ColorGloveError``."""
from __future__ import annotations

__all__ = ['ColorGloveError']


class ColorGloveError(Exception):
    """Base of every error this package raises on purpose (bad input, bad file, bad setting).

    Catch it where any of the package's own failures should become a clear message, e.g. at a
    tool's or a node's start-up; programming errors (``TypeError`` and the like) stay separate.
    """
