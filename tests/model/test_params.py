"""ARDrone2Params against the report's tables (datasets/ardrone2/*.csv)."""

import dataclasses

import numpy as np
import pytest

from visloc.model import ARDRONE2, ARDrone2Params


def test_masses_match_table_2_1(table):
    rows = {r["component"]: float(r["mass_kg"]) for r in table("table_2_1_mass.csv")}
    assert ARDRONE2.mass == rows["complete_with_indoor_hull"]
    assert ARDRONE2.mass_base == rows["base"]
    assert ARDRONE2.mass_battery == rows["battery"]
    assert ARDRONE2.mass_indoor_hull == rows["indoor_hull"]
    # the components add up to the printed total
    parts = rows["base"] + rows["battery"] + rows["indoor_hull"]
    assert parts == pytest.approx(rows["complete_with_indoor_hull"], abs=1e-12)


def test_inertia_matches_table_2_2_and_appendix_d_means(table):
    exp = {r["axis"]: r for r in table("table_2_2_inertia.csv") if r["source"] == "experimental"}
    means = {r["axis"]: float(r["I_mean_kgm2"]) for r in table("appendix_d_means.csv")}
    got = {"xx": ARDRONE2.Ixx, "yy": ARDRONE2.Iyy, "zz": ARDRONE2.Izz}
    for axis, value in got.items():
        assert value == float(exp[axis]["I_kgm2"]) == means[axis]
        assert float(exp[axis]["m_kg"]) == ARDRONE2.mass
    np.testing.assert_array_equal(ARDRONE2.J, np.diag([0.0033, 0.0037, 0.0068]))


@pytest.mark.parametrize(
    ("configuration", "mass_field", "inertia_field"),
    [("no_hull", "mass_no_hull", "inertia_no_hull"),
     ("hull_markers", "mass_hull_markers", "inertia_hull_markers")],
)
def test_other_configurations_match_appendix_d(table, configuration, mass_field, inertia_field):
    rows = {r["axis"]: r for r in table("appendix_d_bifilar.csv")
            if r["configuration"] == configuration}
    assert getattr(ARDRONE2, mass_field) == float(rows["xx"]["m_kg"])
    expected = tuple(float(rows[a]["I_kgm2"]) for a in ("xx", "yy", "zz"))
    assert getattr(ARDRONE2, inertia_field) == expected


def test_variants():
    bare = ARDRONE2.without_hull()
    assert bare.mass == 0.398 and (bare.Ixx, bare.Iyy, bare.Izz) == (0.0023, 0.0026, 0.0045)
    marked = ARDRONE2.with_markers()
    assert marked.mass == 0.502 and marked.Izz == 0.0117
    assert ARDRONE2.mass == 0.456  # frozen original untouched


def test_propulsion_matches_table_e_1(table):
    rows = table("table_e_1_propulsion.csv")
    c3 = tuple(float(r["c_N_per_pct2"]) for r in rows if r["quadrotor"] == "3")
    c4 = tuple(float(r["c_N_per_pct2"]) for r in rows if r["quadrotor"] == "4")
    d4 = tuple(float(r["d_Nm_per_pct2"]) for r in rows if r["quadrotor"] == "4")
    assert ARDRONE2.c_quad3 == c3
    assert ARDRONE2.c_quad4 == c4
    assert ARDRONE2.d_quad4 == d4
    assert all(r["d_Nm_per_pct2"] == "" for r in rows if r["quadrotor"] == "3")
    assert {float(r["k_pct"]) for r in rows} == {ARDRONE2.k}
    assert [int(r["motor"]) for r in rows] == [1, 2, 3, 4] * 2


def test_propulsion_summary_matches_tables_2_3_and_e_1(table):
    rows = table("propulsion_summary.csv")
    by = {(r["table"], r["statistic"]): r for r in rows}
    for tab in ("2.3", "E.1"):
        mean, std = by[(tab, "mean")], by[(tab, "std")]
        assert float(mean["c_N_per_pct2"]) == ARDRONE2.c_mean
        assert float(mean["d_Nm_per_pct2"]) == ARDRONE2.d_mean
        assert float(mean["k_pct"]) == ARDRONE2.k
        assert float(std["c_N_per_pct2"]) == ARDRONE2.c_std
        assert float(std["d_Nm_per_pct2"]) == ARDRONE2.d_std
        assert float(std["k_pct"]) == ARDRONE2.k_std
    # Table 2.3 and the summary rows of Table E.1 print the same numbers
    strip = [{k: v for k, v in r.items() if k not in ("table", "line")} for r in rows]
    assert strip[:2] == strip[2:]


def test_nominal_motor_coefficients_and_arm():
    np.testing.assert_array_equal(ARDRONE2.c_motors, np.full(4, 0.1318e-3))
    np.testing.assert_array_equal(ARDRONE2.d_motors, np.full(4, 0.8722e-5))
    assert ARDRONE2.c_all.shape == (8,)
    assert ARDRONE2.g == 9.81
    assert ARDRONE2.arm is None  # the report prints no arm distance


def test_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        ARDRONE2.mass = 1.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("field", "value", "error"),
    [("mass", -1.0, ValueError), ("Ixx", 0.0, ValueError), ("k", float("nan"), ValueError),
     ("mass", "heavy", TypeError), ("c_quad3", (1e-4, 1e-4), TypeError),
     ("arm", -0.1, ValueError), ("c_std", -1e-6, ValueError)],
)
def test_validation_names_the_field(field, value, error):
    with pytest.raises(error, match=field):
        ARDrone2Params(**{field: value})
