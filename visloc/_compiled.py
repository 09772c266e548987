"""Which version of a stage runs: the compiled one (built with the package) or the Python one."""

from __future__ import annotations

from types import ModuleType

__all__ = ["use_compiled"]


def use_compiled(native: bool | None, module: ModuleType | None, name: str) -> bool:
    """Whether to run the compiled module ``name`` (e.g. ``"visloc.markers._borders"``):
    ``native=None`` when it was built, ``False`` never, ``True`` always (a ``RuntimeError``
    when it was not built: the package was installed without a C compiler)."""
    if native is None:
        return module is not None
    if native and module is None:
        raise RuntimeError(f"{name} was not built (no C compiler at install)")
    return bool(native)
