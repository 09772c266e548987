"""Shared by the bench scripts: write a run's results as JSON and Markdown and print the table."""

from __future__ import annotations

import json
from pathlib import Path


def write_results(out: str | Path, name: str, result: dict, md: str, default=None) -> None:
    """Write ``OUT/NAME.json`` (``result``) and ``OUT/NAME.md`` (``md``), then print ``md``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.json").write_text(json.dumps(result, indent=1, default=default))
    (out / f"{name}.md").write_text(md)
    print(md)


def fmt(v, digits: int = 3, *, style: str = "f", none: str = "–") -> str:
    """A table cell: ``none`` for None, floats with ``digits`` in ``style`` ("f" or "g"), else str."""
    if v is None:
        return none
    if isinstance(v, float):
        return f"{v:.{digits}{style}}"
    return str(v)
