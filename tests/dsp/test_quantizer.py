"""Quantiser theory (:mod:`dsp.quantizer`): the correlation efficiency of a b-bit ADC for
Gaussian noise against the published figures (Van Vleck's 2/pi, Thompson-Moran-Swenson's
four-level optimum, Max's uniform optimum steps) and against numerical integration."""
import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import ndtr

import dsp.quantizer as q

LOSS_2BIT = 0.55


@pytest.mark.parametrize("step", [1e-3, 0.5, 1.0, 1.6, 7.0])
def test_one_bit_is_the_sign_for_any_step(step):
    assert q.quantizer_efficiency(1, step) == pytest.approx(2 / math.pi, rel=1e-12)
    assert q.theoretical_loss_db(1, step) == pytest.approx(1.9612, abs=1e-4)
    t, lv = q.quantizer_cells(1, step)
    np.testing.assert_allclose(t, [0.0])
    np.testing.assert_allclose(lv, [-step / 2, step / 2])


def test_two_bit_optimum_and_tms_four_level():
    step = q.optimal_step(2)
    assert step == pytest.approx(0.9957, abs=2e-4)           # thresholds at +-0.996 sigma
    eta = q.quantizer_efficiency(2, step)
    assert eta == pytest.approx(0.8812, abs=1e-4)             # uniform levels (ratio 3)
    assert eta == pytest.approx(0.8825, abs=2e-3)
    assert q.theoretical_loss_db(2, step) == pytest.approx(LOSS_2BIT, abs=0.01)
    # Thompson, Moran & Swenson ch. 8: optimum four-level (ratio 3.34, thresholds 0.98 sigma)
    tms = q.efficiency([-0.98, 0, 0.98], [-3.34, -1, 1, 3.34])
    assert tms == pytest.approx(0.8825, abs=1e-4)
    assert q.efficiency([0.0], [-1.0, 1.0]) == pytest.approx(2 / math.pi, rel=1e-12)


@pytest.mark.parametrize("bits, max_step", [(3, 0.5860), (4, 0.3352), (5, 0.1881), (6, 0.1041)])
def test_optimal_step_is_max_uniform_optimum(bits, max_step):
    step = q.optimal_step(bits)
    assert step == pytest.approx(max_step, abs=2e-4)
    # it is a maximum of eta
    eta = q.quantizer_efficiency(bits, step)
    assert eta >= q.quantizer_efficiency(bits, step * 1.02)
    assert eta >= q.quantizer_efficiency(bits, step / 1.02)


@pytest.mark.parametrize("quantizer", q.QUANTIZERS)
@pytest.mark.parametrize("bits, step", [(1, 0.7), (2, 0.9), (3, 0.6), (4, 0.2), (4, 1.3)])
def test_efficiency_matches_numerical_integration(quantizer, bits, step):
    t, lv = q.quantizer_cells(bits, step, quantizer)
    edges = np.concatenate(([-np.inf], t, [np.inf]))
    pdf = lambda x: math.exp(-0.5 * x * x) / math.sqrt(2 * math.pi)  # noqa: E731
    e1 = exq = e2 = 0.0
    for lo, hi, level in zip(edges[:-1], edges[1:], lv):
        p = quad(pdf, lo, hi, epsabs=1e-14, epsrel=1e-12)[0]
        xm = quad(lambda x: x * pdf(x), lo, hi, epsabs=1e-14, epsrel=1e-12)[0]
        e1, exq, e2 = e1 + level * p, exq + level * xm, e2 + level * level * p
    eta_quad = exq * exq / (e2 - e1 * e1)
    assert q.quantizer_efficiency(bits, step, quantizer=quantizer) == pytest.approx(eta_quad, rel=1e-9)


@pytest.mark.parametrize("quantizer", q.QUANTIZERS)
@pytest.mark.parametrize("bits", [6, 8, 10, 12])
def test_high_resolution_expansion_matches_exact(quantizer, bits):
    step = q.optimal_step(bits, quantizer=quantizer)
    ex = q.quantizer_efficiency(bits, step, quantizer=quantizer, method="exact")
    hr = q.quantizer_efficiency(bits, step, quantizer=quantizer, method="high_resolution")
    assert 1 - hr == pytest.approx(1 - ex, rel=1e-4)


def test_theory_decreases_with_bits_up_to_24():
    losses = [q.theoretical_loss_db(b, q.optimal_step(b)) for b in range(1, 25)]
    assert all(a > b > 0 for a, b in zip(losses, losses[1:]))
    assert losses[7] < 1e-3                                  # 8 bits: 0.0004 dB


def test_clip_fraction_is_the_outer_cells_probability():
    for quantizer in q.QUANTIZERS:
        t, _ = q.quantizer_cells(3, 0.6, quantizer)
        expect = ndtr(t[0]) + ndtr(-t[-1])
        assert q.clip_fraction(3, 0.6, quantizer) == pytest.approx(expect, rel=1e-12)
    assert q.clip_fraction(1, 1.0) == pytest.approx(1.0)     # the sign: both cells are outer


def test_published_reference_losses():
    assert q.REFERENCE_LOSS_DB[1] == pytest.approx(q.theoretical_loss_db(1, 1.0), rel=1e-12)
    assert q.REFERENCE_LOSS_DB[2] == pytest.approx(
        q.theoretical_loss_db(2, q.optimal_step(2)), abs=0.01)


def test_bad_theory_arguments():
    with pytest.raises(ValueError, match="bits"):
        q.optimal_step(0)
    with pytest.raises(ValueError, match="bits"):
        q.quantizer_efficiency(25, 0.1)
    with pytest.raises(ValueError, match="step"):
        q.quantizer_efficiency(3, 0.0)
    with pytest.raises(ValueError, match="no optimal step"):
        q.optimal_step(1, quantizer="mid_tread")
    with pytest.raises(ValueError, match="increasing"):
        q.efficiency([1.0, 0.0], [0, 1, 2])
    with pytest.raises(ValueError, match="len"):
        q.efficiency([0.0], [1.0])
