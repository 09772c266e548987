"""Exceptions of the command line, below it so that the commands and the parser share them."""

from __future__ import annotations

__all__ = ["UsageError"]


class UsageError(ValueError):
    """A problem with the command's arguments or configuration (exit status 2)."""
