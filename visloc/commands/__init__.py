"""The work behind the ``visloc`` sub-commands.

Each command function takes the parsed arguments of :mod:`visloc.cli` and returns an exit
status. Results are written and flushed frame by frame; a frame that cannot be read is reported
on one line, recorded as an error, and the run goes on.

The command modules are imported on first use (``visloc.commands.flow`` or the names below), so
that a sub-command loads only what it needs.
"""

import importlib

#: public name -> the module of visloc.commands that defines it
_WHERE = {"calibrate_camera": "calibrate", "demo": "demo", "detect": "markers", "flow": "flow",
          "localize": "localize", "model": "model", "model_summary": "model", "render": "markers",
          "robust": "robust", "sim": "sim", "track": "localize"}

__all__ = ["calibrate_camera", "demo", "detect", "flow", "localize", "model", "model_summary", "render", "robust",
           "sim", "track"]


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(importlib.import_module(f"visloc.commands.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'visloc.commands' has no attribute {name!r}")
