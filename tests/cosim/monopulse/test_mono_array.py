import numpy as np
import pytest

from cosim.monopulse.array import (ArrayConfig, angles_from_uv, check_visible,
                                   direction_cosines, quantise_phase)


def test_default_geometry_is_the_paper_array():
    a = ArrayConfig()
    assert (a.dx_wl, a.dy_wl) == (4.0, 4.0)
    assert a.unambiguous_offset == (0.125, 0.125)
    np.testing.assert_array_equal(a.subarray_centres_wl, [[0, 0], [0, 4], [4, 0], [4, 4]])
    off = a.element_offsets_wl
    assert off.shape == (64, 2)
    np.testing.assert_allclose(off.mean(axis=0), [0, 0], atol=1e-15)
    assert off[:, 0].max() == 1.75 and np.allclose(np.diff(np.unique(off[:, 0])), 0.5)


def test_spacing_follows_the_subarray_size_unless_given():
    a = ArrayConfig(elements_x=4, elements_y=6, element_spacing_wl=0.6,
                    subarray_spacing_y_wl=5.0)
    assert a.dx_wl == pytest.approx(2.4) and a.dy_wl == 5.0


@pytest.mark.parametrize("kw, msg", [
    (dict(phase_bits=0), "phase_bits must be an integer in [1, 24] or None (ideal), not 0"),
    (dict(element_spacing_wl=0), "element_spacing_wl must be a finite number > 0, not 0"),
    (dict(subarray_spacing_x_wl=-4.0), "subarray_spacing_x_wl must be a finite number > 0, not -4.0"),
    (dict(elements_x=0), "elements_x must be an integer >= 1, not 0"),
    (dict(gain_db=(0, 0, 0)), "gain_db must be 4 finite numbers (channels 1-4), not (0, 0, 0)"),
])
def test_bad_array_is_refused(kw, msg):
    with pytest.raises(ValueError) as e:
        ArrayConfig(**kw)
    assert str(e.value) == msg


def test_visible_region_is_refused_outside():
    check_visible(0.6, 0.79)
    with pytest.raises(ValueError, match=r"visible region u\^2 \+ v\^2 < 1, not u = 0.6, v = 0.8"):
        check_visible([0.1, 0.6], [0.1, 0.8])
    with pytest.raises(ValueError, match="steering direction must lie in the visible region"):
        ArrayConfig().steering_weights(1.0, 0.0)
    with pytest.raises(ValueError, match="target direction must lie in the visible region"):
        ArrayConfig().subarray_pattern(np.array([0.9]), np.array([0.5]), 0.1, 0.1)


def test_angles_round_trip():
    rng = np.random.default_rng(3)
    az = rng.uniform(-np.pi / 2, np.pi / 2, 1000)
    el = rng.uniform(0.01, np.pi / 2 - 0.01, 1000)
    u, v = direction_cosines(az, el)
    az2, el2 = angles_from_uv(u, v)
    np.testing.assert_allclose(az2, az, atol=1e-12)
    np.testing.assert_allclose(el2, el, atol=1e-9)


def test_phase_quantiser():
    ph = np.linspace(-7, 7, 10001)
    q, err = quantise_phase(ph, 3)
    step = 2 * np.pi / 8
    np.testing.assert_allclose(np.round(q / step), q / step, atol=1e-12)
    assert np.max(np.abs(err)) <= step / 2 + 1e-12
    assert np.max(np.abs(err)) > 0.49 * step


def test_pattern_equals_the_direct_element_sum():
    """The separable evaluation against the plain sum over elements (independent form)."""
    a = ArrayConfig(elements_x=5, elements_y=7, element_spacing_wl=0.55, phase_bits=3)
    rng = np.random.default_rng(7)
    u = rng.uniform(-0.5, 0.5, 50)
    v = rng.uniform(-0.5, 0.5, 50)
    u0, v0 = 0.21, -0.33
    p = a.element_offsets_wl
    w = np.exp(1j * quantise_phase(2 * np.pi * (p[:, 0] * u0 + p[:, 1] * v0), 3)[0])
    direct = np.array([np.sum(w * np.exp(-2j * np.pi * (p[:, 0] * uu + p[:, 1] * vv)))
                       for uu, vv in zip(u, v)]) / len(p)
    np.testing.assert_allclose(a.subarray_pattern(u, v, u0, v0), direct, atol=1e-12)


def test_pattern_peak_and_quantisation_loss():
    ideal = ArrayConfig(phase_bits=None)
    assert abs(ideal.subarray_pattern(np.array(0.3), np.array(0.2), 0.3, 0.2) - 1) < 1e-12
    # First null of an 8-element lambda/2 row at 1/(8 * 0.5) = 0.25 off the steering.
    assert abs(ideal.subarray_pattern(np.array(0.55), np.array(0.2), 0.3, 0.2)) < 1e-12
    q = ArrayConfig(phase_bits=2)
    g = abs(q.subarray_pattern(np.array(0.3), np.array(0.2), 0.3, 0.2))
    assert 0.6 < g < 0.999  # 2-bit shifters lose gain (sinc(1/4)^2 = 0.81 for uniform error)


def test_corrected_channels_follow_the_paper_model():
    """After the digital steering, channel i / channel 1 = exp(j dphi_i), dphi_i = phi_i0 - phi_i,
    with phi_2 = 2 pi Dy v, phi_3 = 2 pi Dx u, phi_4 = phi_2 + phi_3; mismatch multiplies."""
    a = ArrayConfig(phase_bits=5, gain_db=(0.0, 0.5, -0.3, 0.2), phase_deg=(0.0, 4.0, -3.0, 1.0))
    u, v, u0, v0 = 0.33, 0.12, 0.3, 0.2
    y = a.channel_response(np.array(u), np.array(v), u0, v0) * a.steering_correction(u0, v0)
    y = y / a.channel_gains
    d2, d3 = 2 * np.pi * 4 * (v0 - v), 2 * np.pi * 4 * (u0 - u)
    np.testing.assert_allclose(y / y[0], np.exp(1j * np.array([0, d2, d3, d2 + d3])), atol=1e-12)
    np.testing.assert_allclose(np.abs(a.channel_gains), 10 ** (np.array(a.gain_db) / 20))


def test_steering_in_the_elements_equals_digital_when_ideal_and_biases_when_quantised():
    u, v, u0, v0 = np.array([0.36, 0.27]), np.array([0.15, 0.22]), 0.3, 0.2
    resp = {}
    for mode in ("digital", "elements"):
        for bits in (None, 3):
            a = ArrayConfig(phase_bits=bits, subarray_steering=mode)
            resp[mode, bits] = a.channel_response(u, v, u0, v0) * a.steering_correction(u0, v0)
    np.testing.assert_allclose(resp["elements", None], resp["digital", None], atol=1e-12)
    # Quantised: digital keeps channel ratios exact, elements does not.
    d, e = resp["digital", 3], resp["elements", 3]
    ideal = resp["digital", None]
    np.testing.assert_allclose(d / d[..., :1], ideal / ideal[..., :1], atol=1e-12)
    assert np.max(np.abs(e / e[..., :1] - ideal / ideal[..., :1])) > 1e-3
    with pytest.raises(ValueError, match="subarray_steering must be 'digital' or 'elements', not 'x'"):
        ArrayConfig(subarray_steering="x")
