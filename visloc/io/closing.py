"""The context-manager protocol shared by visloc's sources, writers and loggers, and the
staging of output files (written under a temporary name, renamed when closed)."""

from __future__ import annotations

import os
from pathlib import Path
from types import TracebackType
from typing import Self

__all__ = ["Closing", "commit_staged", "staged_path"]


def staged_path(path: Path) -> Path:
    """Where an output file is written until it is complete.

    An earlier file at ``path`` stays as it is until :func:`commit_staged`.

    Parameters
    ----------
    path : Path
        The output file.

    Returns
    -------
    Path
        ``dir/.name.partial.ext`` next to ``path`` (the extension kept for codecs and formats
        that go by it).
    """
    return path.with_name(f".{path.name}.partial{path.suffix}")


def commit_staged(staged: Path, path: Path, *, keep: bool) -> None:
    """Put a staged file in place, or drop it.

    Parameters
    ----------
    staged : Path
        The staged file (:func:`staged_path`); it may be missing.
    path : Path
        The output file.
    keep : bool
        Rename ``staged`` over ``path`` (something was written: an interrupted run keeps its
        frames); else remove it and leave ``path`` untouched.

    Returns
    -------
    None
    """
    if keep and staged.exists():
        os.replace(staged, path)
    else:
        staged.unlink(missing_ok=True)


class Closing:
    """Base class: ``with obj:`` calls ``obj.close()`` on the way out, even on errors."""

    def close(self) -> None:  # pragma: no cover - overridden
        """Release what the object holds (a subclass's own; here it raises NotImplementedError)."""
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
