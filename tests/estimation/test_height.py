"""Ultrasound height map, report eqs. 3.12-3.13, with its blind zones."""

import numpy as np
import pytest

from visloc.estimation import ultrasound_height, ultrasound_reading
from visloc.estimation.height import A_Z, B_Z, C_Z

U_MAX = (C_Z - B_Z) / A_Z  # reading at the largest measurable depth, ~335.5


def test_report_constants_and_range():
    assert (A_Z, B_Z, C_Z) == (-0.0076, -0.2, -2.75)
    assert U_MAX == pytest.approx(2.55 / 0.0076)


def test_reading_at_blind_zone_edges():
    # lower blind zone: depth z >= b_z (height <= 0.2 m) reads 0
    assert ultrasound_reading(0.0) == 0.0
    assert ultrasound_reading(0.2) == 0.0
    assert ultrasound_reading(0.2 + 0.0076) == pytest.approx(1.0)
    # measurable up to the largest depth c_z (2.75 m) inclusive, then 0 again
    assert ultrasound_reading(2.75) == pytest.approx(U_MAX)
    assert ultrasound_reading(2.7501) == 0.0
    assert ultrasound_reading(5.0) == 0.0
    assert ultrasound_reading(1.0) == pytest.approx((-1.0 - B_Z) / A_Z)  # eq. 3.12, z = -h


def test_height_inverts_reading_in_range():
    h = np.linspace(0.21, 2.75, 50)
    est = ultrasound_height(ultrasound_reading(h))
    assert np.all(est.valid)
    assert np.allclose(est.height, h, atol=1e-12)


def test_height_at_blind_zones_and_bad_readings_is_flagged_not_nan():
    est = ultrasound_height([0.0, 1.0, U_MAX, U_MAX + 0.01, 1e6, -3.0, np.nan, np.inf])
    assert est.valid.tolist() == [False, True, True, False, False, False, False, False]
    assert np.allclose(est.height, [0.2, 0.2076, 2.75, 2.75, 2.75, 0.2, 0.2, 0.2])
    assert np.all(np.isfinite(est.height))


def test_scalar_in_scalar_out_and_blind_value():
    est = ultrasound_height(100.0)
    assert isinstance(est.height, float) and est.valid is True
    assert est.height == pytest.approx(0.2 + 0.76)
    on_ground = ultrasound_height(0.0, b=0.0)  # choose "on the ground" for a zero reading
    assert on_ground.height == 0.0 and on_ground.valid is False


def test_bad_parameters_named():
    with pytest.raises(ValueError, match="a_z"):
        ultrasound_height(1.0, a_h=0.0076)
    with pytest.raises(ValueError, match="c_z"):
        ultrasound_reading(1.0, c_z=0.0)
    with pytest.raises(ValueError, match="height"):
        ultrasound_reading([1.0, np.nan])
    with pytest.raises(TypeError, match="u_sens"):
        ultrasound_height(object())
