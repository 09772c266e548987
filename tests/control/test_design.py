"""Loop-shaping design, gains, Bode data (report §4.2, eqs. 4.5-4.11, Figures 4.2-4.3)."""

import numpy as np
import pytest

from visloc.control import (
    LOOPS,
    ControllerGains,
    ControlSpecs,
    LoopSpec,
    augmented_model,
    bode,
    design_gains,
    design_loop,
    loop_margins,
    lqr_gains,
    plant,
    save_bode_png,
)
from visloc.model import ARDRONE2

P = ARDRONE2


@pytest.fixture(scope="module")
def gains():
    return design_gains(P)


@pytest.mark.parametrize("loop", LOOPS)
def test_measured_margins_meet_the_specs(gains, loop):
    spec = ControlSpecs().for_loop(loop)
    wc, pm = loop_margins(loop, gains=gains)
    assert wc == pytest.approx(spec.crossover, rel=1e-6)
    assert pm == pytest.approx(spec.phase_margin, abs=1e-6)


def test_double_integrator_gains_in_closed_form(gains):
    # PD on 1/(J s^2) at crossover w with margin PM: kp = J w^2 cos PM, kd = J w sin PM
    spec = ControlSpecs().attitude
    w, pm = spec.crossover, np.deg2rad(spec.phase_margin)
    assert gains.roll.kp == pytest.approx(P.Ixx * w**2 * np.cos(pm))
    assert gains.roll.kd == pytest.approx(P.Ixx * w * np.sin(pm))
    assert gains.roll.ki == 0.0 and gains.pitch.ki == 0.0
    assert gains.x.ki > 0 and gains.y.ki > 0 and gains.height.ki > 0 and gains.yaw.ki > 0


def test_closed_loop_is_stable_and_signs_push_back(gains):
    a, b = augmented_model(P)
    k = gains.K()
    assert k.shape == (4, 16) and gains.K(integral=False).shape == (4, 12)
    assert np.max(np.linalg.eigvals(a - b @ k).real) < 0
    du = -k @ np.eye(16)[0]  # 1 m ahead (north in P): pitch up, tau_y > 0 (udot = -g theta)
    assert du[2] > 0
    du = -k @ np.eye(16)[1]  # 1 m right: roll left, tau_x < 0 (vdot = g phi)
    assert du[1] < 0
    du = -k @ np.eye(16)[2]  # 1 m low (z down): more thrust
    assert du[0] > 0


def test_loops_decouple(gains):
    # each closed loop's poles are a subset of the full closed loop's
    a, b = augmented_model(P)
    full = np.sort_complex(np.linalg.eigvals(a - b @ gains.K()))
    num, den = plant("height", P)
    g = gains.height
    char = np.polyadd(np.polymul(den, [1, 0]), np.polymul(num, [g.kd, g.kp, g.ki]))
    for root in np.roots(char):
        assert np.min(np.abs(full - root)) < 1e-6


def test_specs_and_errors():
    with pytest.raises(ValueError, match="phase_margin"):
        LoopSpec(10.0, 95.0)
    with pytest.raises(ValueError, match="crossover"):
        LoopSpec(-1.0, 45.0)
    with pytest.raises(ValueError, match="integral"):
        LoopSpec(1.0, 45.0, 1.5)
    with pytest.raises(ValueError, match="loop"):
        loop_margins("altitude")
    with pytest.raises(TypeError, match="specs"):
        design_gains(P, specs={"attitude": (10, 60)})
    # the position loop cannot cross over above the attitude loop with a PD
    with pytest.raises(ValueError, match="spec"):
        design_gains(P, specs=ControlSpecs(position=LoopSpec(30.0, 60.0)))
    with pytest.raises(ValueError, match="gains"):
        plant("x", P)
    num, den = plant("roll", P)
    assert design_loop(num, den, LoopSpec(5.0, 45.0)).kp > 0


def test_other_specs_scale_the_gains():
    slow = design_gains(P, specs=ControlSpecs(attitude=LoopSpec(5.0, 60.0), position=LoopSpec(1.0, 50.0)))
    assert isinstance(slow, ControllerGains)
    ratio = (5.0 / ControlSpecs().attitude.crossover) ** 2  # kp = J w^2 cos PM
    assert slow.roll.kp == pytest.approx(design_gains(P).roll.kp * ratio)
    assert loop_margins("position", gains=slow)[0] == pytest.approx(1.0)


def test_lqr_stabilises():
    a, b = augmented_model(P)
    k = lqr_gains(P)
    assert k.shape == (4, 16)
    assert np.max(np.linalg.eigvals(a - b @ k).real) < 0
    assert lqr_gains(P, integral=False).shape == (4, 12)
    with pytest.raises(ValueError, match="q"):
        lqr_gains(P, q=np.ones(3))


def test_bode_data_figure_4_2(gains):
    w, mag, ph = bode("attitude", part="plant", gains=gains)
    np.testing.assert_allclose(ph, -180.0, atol=1e-9)  # double integrator (eq. 4.7)
    np.testing.assert_allclose(mag, -20 * np.log10(P.Ixx * w**2), atol=1e-9)  # 1/(J w^2)
    w, mag, ph = bode("attitude", part="closed", gains=gains)
    assert abs(mag[0]) < 1e-3 and mag[-1] < -30  # tracks slowly, rolls off fast
    w, mag, ph = bode("position", part="open", w=np.logspace(-3, 2, 50), gains=gains)
    assert w.shape == mag.shape == ph.shape == (50,)
    assert ph[0] == pytest.approx(-270, abs=10)  # PID integrator on a double integrator
    with pytest.raises(ValueError, match="part"):
        bode("attitude", part="sensitivity")
    with pytest.raises(ValueError, match="w"):
        bode("attitude", w=[-1.0, 1.0])


def test_save_bode_png(tmp_path, gains):
    out = tmp_path / "bode.png"
    save_bode_png(out, gains=gains)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="loops"):
        save_bode_png(out, loops="attitude")


def test_lqr_weights_without_a_solution_are_a_value_error():
    # scipy's LinAlgError and its own ValueError used to leak out unnamed
    with pytest.raises(ValueError, match="q, r: no LQR gains"):
        lqr_gains(ARDRONE2, q=[-1.0] * 16)
    with pytest.raises(ValueError, match="q, r: no LQR gains"):
        lqr_gains(ARDRONE2, r=[0.0, 1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="finite"):
        lqr_gains(ARDRONE2, q=[np.nan] * 16)


def test_gains_to_dict_is_json_ready_with_numpy_specs():
    import json

    g = design_gains(ARDRONE2, specs=ControlSpecs(height=LoopSpec(np.float32(3.0), 60.0, 0.1)))
    d = json.loads(json.dumps(g.to_dict()))  # a float32 gain used to stop json
    assert d["height"]["ki"] == pytest.approx(float(g.loop("height").ki))


@pytest.mark.parametrize("crossover", [1e-300, 1e150, 1e300])
def test_design_loop_refuses_a_crossover_out_of_float_range_naming_it(crossover):
    # a LinAlgError from np.roots ("Array must not contain infs or NaNs") before
    num, den = plant("roll", ARDRONE2)
    with pytest.raises(ValueError, match="out of floating-point range"):
        design_loop(num, den, LoopSpec(crossover, 45.0, 0.1))


@pytest.mark.parametrize("num, den, exc, word", [
    ([0.0], [1.0, 0.0, 0.0], ValueError, "num"), ([np.nan], [1.0, 0.0, 0.0], ValueError, "num"),
    ([], [1.0, 0.0, 0.0], ValueError, "num"), ("ab", [1.0, 0.0, 0.0], TypeError, "num"),
    ([1.0], [0.0, 1.0, 0.0], ValueError, "den"), ([1.0], [[1.0, 0.0]], ValueError, "den"),
])
def test_design_loop_refuses_a_plant_that_is_not_two_finite_polynomials(num, den, exc, word):
    with pytest.raises(exc, match=word):
        design_loop(num, den, LoopSpec(5.0, 45.0))
