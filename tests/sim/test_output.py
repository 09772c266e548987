"""``visloc.sim.output``: the plot's path panel shows the flown path from above."""

import numpy as np
import pytest

from visloc.sim import simulate
from visloc.sim.output import _path_panel, save_plot


def test_path_panel_draws_reference_true_and_estimate_north_up(tmp_path):
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = simulate("sidestep", seconds=1.0)
    fig, ax = plt.subplots()
    _path_panel(ax, r)
    lines = {line.get_label(): line for line in ax.get_lines()}
    for label, rows in (("reference", r.setpoint), ("true", r.state), ("estimate", r.estimate)):
        np.testing.assert_array_equal(lines[label].get_xdata(), rows[:, 1])  # east across
        np.testing.assert_array_equal(lines[label].get_ydata(), rows[:, 0])  # north up
    assert lines["end"].get_xdata()[0] == r.state[-1, 1]
    assert np.ptp(lines["reference"].get_xdata()) == pytest.approx(1.0)  # the 1 m side step east
    plt.close(fig)
    png = save_plot(r, tmp_path / "run.png")
    assert png.read_bytes()[:4] == b"\x89PNG"
