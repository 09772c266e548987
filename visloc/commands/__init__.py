"""The work behind the ``visloc`` sub-commands.

Each command function takes the parsed arguments of :mod:`visloc.cli` and returns an exit
status. Results are written and flushed frame by frame; a frame that cannot be read is reported
on one line, recorded as an error, and the run goes on.
"""

from visloc.commands.calibrate import calibrate_camera
from visloc.commands.demo import demo
from visloc.commands.flow import flow
from visloc.commands.localize import localize, track
from visloc.commands.markers import detect, render
from visloc.commands.model import model, model_summary
from visloc.commands.robust import robust
from visloc.commands.sim import sim

__all__ = ["calibrate_camera", "demo", "detect", "flow", "localize", "model", "model_summary", "render", "robust", "sim", "track"]
