"""The context-manager protocol shared by visloc's sources, writers and loggers, and the
staging of output files (written under a temporary name, renamed when closed)."""

from __future__ import annotations

import os
from pathlib import Path
from types import TracebackType
from typing import Self

__all__ = ["Closing", "commit_staged", "staged_path"]


def staged_path(path: Path) -> Path:
    """Where an output file is written until it is complete: ``dir/.name.partial.ext`` next to
    ``path`` (the extension kept for codecs and formats that go by it). An earlier file at
    ``path`` stays as it is until :func:`commit_staged`."""
    return path.with_name(f".{path.name}.partial{path.suffix}")


def commit_staged(staged: Path, path: Path, keep: bool) -> None:
    """Rename the staged file over ``path`` when ``keep`` (something was written: an
    interrupted run keeps its frames), else remove it and leave ``path`` untouched."""
    if keep and staged.exists():
        os.replace(staged, path)
    else:
        staged.unlink(missing_ok=True)


class Closing:
    """Base class: ``with obj:`` calls ``obj.close()`` on the way out, even on errors."""

    def close(self) -> None:  # pragma: no cover - overridden
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
