"""Bifilar-pendulum inertia (eq. 2.14 / D.13) against every row of the report's Appendix D."""

import math

import numpy as np
import pytest

from visloc.model import ARDRONE2, bifilar_inertia, inertia_from_measurements

# Printed I that eq. (D.13) with the printed (m, r, L, t, n) and g = 9.81 does NOT reproduce at
# the printed 4 decimals: seed line -> (printed, computed). The printed f all reproduce.
MISMATCHED = {
    "690": (0.0071, 0.0070448),
    "692": (0.0066, 0.0065338),
    "696": (0.0070, 0.0069290),
    "697": (0.0070, 0.0069205),
    "698": (0.0070, 0.0069460),
    "706": (0.0033, 0.0032457),
}


def _measured(row):
    return [float(row[k]) for k in ("m_kg", "r_m", "L_m", "t_s", "n")]


def test_appendix_d_has_all_rows(table):
    rows = table("appendix_d_bifilar.csv")
    assert len(rows) == 20
    assert {r["line"] for r in rows} >= set(MISMATCHED)


def test_each_appendix_d_row(bifilar_row, printed_decimals):
    row, decimals = bifilar_row, printed_decimals
    res = inertia_from_measurements([_measured(row)])
    f, inertia = float(res.f[0]), float(res.inertia[0])
    assert round(f, decimals(row["f_hz"])) == float(row["f_hz"]), (f, row["f_hz"])
    printed = float(row["I_kgm2"])
    if row["line"] in MISMATCHED:
        assert round(inertia, decimals(row["I_kgm2"])) != printed
        assert inertia == pytest.approx(MISMATCHED[row["line"]][1], abs=1e-7)
        assert abs(inertia - printed) < 1e-4  # within one unit of the last printed digit
    else:
        assert round(inertia, decimals(row["I_kgm2"])) == printed, (inertia, printed)


def test_means_of_table_2_2(table):
    all_rows = table("appendix_d_bifilar.csv")
    means = {r["axis"]: r for r in table("appendix_d_means.csv")}
    for axis in ("xx", "yy", "zz"):
        rows = [r for r in all_rows if r["configuration"] == "hull" and r["axis"] == axis]
        res = inertia_from_measurements([_measured(r) for r in rows])
        printed = float(means[axis]["I_mean_kgm2"])
        mean_of_printed = np.mean([float(r["I_kgm2"]) for r in rows])
        assert round(mean_of_printed, 4) == printed  # the printed rows average to the mean
        if axis == "zz":
            # NOT reproduced from the raw measurements: 0.006734, printed 0.0068 (-6.6e-5)
            assert res.mean == pytest.approx(0.0067336, abs=1e-7)
            assert round(res.mean, 4) != printed
        else:
            assert round(res.mean, 4) == printed, (axis, res.mean)
    assert ARDRONE2.Ixx == 0.0033 and ARDRONE2.Iyy == 0.0037 and ARDRONE2.Izz == 0.0068


def test_r_is_half_the_cord_distance():
    """Two point masses m/2 at the cords (radius r): I = m r^2, and each swings as a simple
    pendulum of length L, f = sqrt(g / L) / (2 pi)."""
    m, r, L, g = 0.4, 0.12, 1.5, 9.81
    f = math.sqrt(g / L) / (2 * math.pi)
    assert bifilar_inertia(m, r, L, f, g=g) == pytest.approx(m * r**2, rel=1e-12)


def test_bifilar_inertia_broadcasts_and_scales():
    out = bifilar_inertia(0.456, np.array([0.1, 0.2]), 1.0, 0.5)
    assert out.shape == (2,) and out[1] == pytest.approx(4 * out[0])
    assert isinstance(bifilar_inertia(0.456, 0.1, 1.0, 0.5), float)


@pytest.mark.parametrize("name", ["m", "r", "L", "f", "g"])
def test_bifilar_inertia_rejects_non_positive(name):
    args = {"m": 0.456, "r": 0.1, "L": 1.0, "f": 0.5, "g": 9.81}
    args[name] = 0.0
    with pytest.raises(ValueError, match=name):
        bifilar_inertia(**args)


def test_inertia_from_measurements_checks_rows():
    one = inertia_from_measurements([0.456, 0.1240, 1.4250, 120.02, 50])
    assert one.inertia.shape == (1,) and one.mean == one.inertia[0]
    with pytest.raises(ValueError, match="rows"):
        inertia_from_measurements(np.ones((3, 4)))
    with pytest.raises(ValueError, match="rows"):
        inertia_from_measurements([[0.456, 0.1, 1.0, -5.0, 10]])
    with pytest.raises(TypeError, match="rows"):
        inertia_from_measurements([["a"] * 5])
