"""Writing a :class:`visloc.sim.SimResult`: CSV, a PNG plot and a rerun recording."""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np

from visloc.model.rigid_body import STATE_NAMES
from visloc.sim.loop import SimResult
from visloc.types import FloatArray

__all__ = ["save_plot", "save_rerun", "write_csv"]


def _check_path(path: str | os.PathLike[str], suffix: str) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path: expected a str or os.PathLike, got {type(path).__name__}")
    out = Path(path)
    if out.suffix.lower() != suffix:
        raise ValueError(f"path: expected a {suffix} file, got {out}")
    out.parent.mkdir(parents=True, exist_ok=True)
    return out


def _positions_up(result: SimResult) -> list[tuple[str, FloatArray, FloatArray, FloatArray]]:
    """Per axis: label (x, y, height) and true, estimated and set-point values, height up."""
    out = []
    for j, name in enumerate("xyz"):
        sign = -1.0 if name == "z" else 1.0  # plot the height, up positive
        label = "height" if name == "z" else name
        out.append((label, sign * result.state[:, j], sign * result.estimate[:, j],
                    sign * result.setpoint[:, j]))
    return out


def write_csv(result: SimResult, path: str | os.PathLike[str]) -> Path:
    """One row per control step: time, true state, estimate (``est_`` prefix), set point, pwm.

    Angles in rad, SI units (:data:`visloc.model.STATE_NAMES`).

    Parameters
    ----------
    result : SimResult
        The run to write.
    path : str or os.PathLike
        Output file; must end in ``.csv``. Missing parent directories are created.

    Returns
    -------
    Path
        ``path`` as a :class:`pathlib.Path`.

    Raises
    ------
    TypeError
        ``path`` is not a str or os.PathLike.
    ValueError
        ``path`` does not end in ``.csv``.
    """
    out = _check_path(path, ".csv")
    header = (["t"] + list(STATE_NAMES) + [f"est_{n}" for n in STATE_NAMES]
              + ["sp_x", "sp_y", "sp_z", "sp_psi", "pwm1", "pwm2", "pwm3", "pwm4", "saturated"])
    with out.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for i in range(len(result.t)):
            w.writerow([f"{result.t[i]:.4f}"]
                       + [f"{v:.6g}" for v in result.state[i]]
                       + [f"{v:.6g}" for v in result.estimate[i]]
                       + [f"{v:.6g}" for v in result.setpoint[i]]
                       + [f"{v:.4f}" for v in result.pwm[i]] + [int(result.saturated[i])])
    return out


def save_plot(result: SimResult, path: str | os.PathLike[str]) -> Path:
    """PNG of position (true, estimated, set point), attitude and motor commands against time
    (like report Figures 4.5-4.6) beside the path seen from above (reference, true,
    estimated). Needs matplotlib (``pip install visloc[plot]``).

    Parameters
    ----------
    result, path : as :func:`write_csv`
        Except that ``path`` must end in ``.png``.

    Returns
    -------
    Path
        The ``.png`` file, as for :func:`write_csv`.

    Raises
    ------
    TypeError, ValueError
        As :func:`write_csv` (``path`` not a ``.png`` file).
    ImportError
        matplotlib is not installed.
    """
    out = _check_path(path, ".png")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - matplotlib comes with filterpy
        raise ImportError("save_plot needs matplotlib: pip install visloc[plot]") from exc
    t = result.t
    fig = plt.figure(figsize=(12, 8))
    grid = fig.add_gridspec(3, 2, width_ratios=(1.6, 1.0))
    ax = [fig.add_subplot(grid[0, 0])]
    ax += [fig.add_subplot(grid[i, 0], sharex=ax[0]) for i in (1, 2)]
    _path_panel(fig.add_subplot(grid[:, 1]), result)
    curves = _positions_up(result)
    for (label, true, est, sp), colour in zip(curves, ("C0", "C1", "C2"), strict=True):
        ax[0].plot(t, true, colour, label=f"{label} true")
        ax[0].plot(t, est, colour, ls="--", lw=0.8, label=f"{label} estimate")
        ax[0].plot(t, sp, colour, ls=":", lw=0.8)
    ax[0].set_ylabel("position, m (height up)")
    ax[0].legend(ncol=3, fontsize=7)
    for j, name in enumerate(("roll", "pitch", "yaw")):
        ax[1].plot(t, np.degrees(result.state[:, 6 + j]), label=name)
    ax[1].set_ylabel("attitude, deg")
    ax[1].legend(fontsize=7)
    for j in range(4):
        ax[2].plot(t, result.pwm[:, j], lw=0.8, label=f"motor {j + 1}")
    ax[2].set_ylabel("pwm, %")
    ax[2].set_xlabel("time, s")
    ax[2].legend(ncol=4, fontsize=7)
    fig.suptitle(f"visloc sim {result.scenario}: {result.status.value} ({result.reason})", fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def _path_panel(ax, result: SimResult) -> None:
    """The flown path seen from above (north up, east right): reference, true and estimated
    positions, and where the run started and ended."""
    north, east = result.state[:, 0], result.state[:, 1]
    ax.plot(result.setpoint[:, 1], result.setpoint[:, 0], "k:", lw=1.0, label="reference")
    ax.plot(east, north, "C0", lw=1.0, label="true")
    ax.plot(result.estimate[:, 1], result.estimate[:, 0], "C1", ls="--", lw=0.8, label="estimate")
    ax.plot(east[:1], north[:1], "C0o", ms=4, label="start")
    ax.plot(east[-1:], north[-1:], "C0s", ms=4, label="end")
    ax.set_xlabel("east, m")
    ax.set_ylabel("north, m")
    ax.set_title("path from above", fontsize=9)
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7)


def save_rerun(result: SimResult, path: str | os.PathLike[str]) -> Path:
    """A rerun ``.rrd`` recording: the drone's pose and track in a z-up world, and time series.

    Entities: ``world`` (right-handed, z up: NED ``(x, y, z)`` shown as ``(x, -y, -z)``),
    ``world/drone`` (Transform3D + Boxes3D), ``world/track`` and ``world/estimate`` (LineStrips3D),
    ``plots/position/<axis>/{true,estimate,setpoint}``, ``plots/attitude/<angle>`` (deg),
    ``plots/pwm/<motor>`` (%); timeline ``time`` (s).

    Parameters
    ----------
    result, path : as :func:`write_csv`
        Except that ``path`` must end in ``.rrd``.

    Returns
    -------
    Path
        The ``.rrd`` file, as for :func:`write_csv`.

    Raises
    ------
    TypeError, ValueError
        As :func:`write_csv` (``path`` not a ``.rrd`` file).
    """
    import rerun as rr
    from scipy.spatial.transform import Rotation

    out = _check_path(path, ".rrd")
    rec = rr.RecordingStream("visloc-sim")
    rec.save(out)
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    flip = np.diag([1.0, -1.0, -1.0])  # NED -> x north, y west, z up
    pos = result.state[:, :3] @ flip
    est = result.estimate[:, :3] @ flip
    rec.log("world/track", rr.LineStrips3D([pos]), static=True)
    rec.log("world/estimate", rr.LineStrips3D([est], colors=[[255, 160, 0]]), static=True)
    rec.log("world/drone", rr.Boxes3D(half_sizes=[[0.18, 0.18, 0.03]]), static=True)
    times = rr.TimeColumn("time", duration=result.t)
    euler = result.state[:, 6:9]
    R = Rotation.from_euler("ZYX", euler[:, ::-1]).as_matrix()  # report eq. (2.6)
    quat = Rotation.from_matrix(flip @ R @ flip).as_quat()  # xyzw
    rec.send_columns("world/drone", indexes=[times],
                     columns=rr.Transform3D.columns(translation=pos, quaternion=quat))
    series = {}
    for label, true, estimate, setpoint in _positions_up(result):
        series[f"plots/position/{label}/true"] = true
        series[f"plots/position/{label}/estimate"] = estimate
        series[f"plots/position/{label}/setpoint"] = setpoint
    for j, name in enumerate(("roll", "pitch", "yaw")):
        series[f"plots/attitude/{name}"] = np.degrees(result.state[:, 6 + j])
    for j in range(4):
        series[f"plots/pwm/motor{j + 1}"] = result.pwm[:, j]
    for entity, values in series.items():
        finite = np.where(np.isfinite(values), values, math.nan)
        rec.send_columns(entity, indexes=[times], columns=rr.Scalars.columns(scalars=finite))
    rec.flush()
    return out
