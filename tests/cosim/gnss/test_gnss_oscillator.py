"""Oscillator phase noise: the Allan variance of each power law against its formula."""
import math

import numpy as np
import pytest

from cosim.gnss.oscillator import (OSCILLATORS, Oscillator, OscillatorPhase,
                                   allan_variance_from_phase, clock_error_s, oscillator)

T = 1e-3
N = 200_000


@pytest.mark.parametrize("osc,seed", [(Oscillator(1e-19, 0, 0), 1), (Oscillator(0, 1e-20, 0), 2),
                                      (Oscillator(0, 0, 1e-20), 3)])
def test_allan_variance_of_each_power_law(osc, seed):
    x = clock_error_s(osc, N, T, np.random.default_rng(seed))
    for m in (10, 100):
        # 2e5 points: the estimate's spread is a few % at m = 100 (random-walk FM worst).
        assert allan_variance_from_phase(x, T, m) / float(osc.allan_variance(m * T)) == \
            pytest.approx(1.0, abs=0.1), m


def test_components_draw_independently():
    # Turning one coefficient off leaves the others' draws alone (own child streams).
    full = clock_error_s(Oscillator(1e-19, 0, 1e-20), 1000, T, np.random.default_rng(5))
    w = clock_error_s(Oscillator(1e-19, 0, 0), 1000, T, np.random.default_rng(5))
    r = clock_error_s(Oscillator(0, 0, 1e-20), 1000, T, np.random.default_rng(5))
    np.testing.assert_allclose(full, w + r, rtol=1e-12, atol=1e-25)


def test_tables_and_phase_scale():
    assert OSCILLATORS["tcxo"] == Oscillator(2e-19, 7e-21, 2e-20, "tcxo")
    assert OSCILLATORS["ocxo"] == Oscillator(2e-25, 7e-25, 6e-25, "ocxo")
    assert oscillator("TCXO") is OSCILLATORS["tcxo"] and oscillator(None) is None
    ph = OscillatorPhase(OSCILLATORS["tcxo"], 1.0, T, np.random.default_rng(0))
    # Phase in L1 cycles: -L1 x, linear between grid points.
    t = np.array([0.0, 0.5e-3, 1e-3])
    p = ph.phase_cycles(t)
    assert p[0] == 0.0 and p[1] == pytest.approx((p[0] + p[2]) / 2, rel=1e-12)
    assert p[2] == pytest.approx(-1575.42e6 * ph.x[1], rel=1e-12)
    # The TCXO at 1 s: h0/2 = 1e-19, 2 ln2 h-1 = 9.70e-21, 2 pi^2/3 h-2 = 1.316e-19.
    assert float(OSCILLATORS["tcxo"].allan_variance(1.0)) == pytest.approx(2.413e-19, rel=1e-3)


@pytest.mark.parametrize("kw,msg", [(dict(h0=-1e-20, h_1=0, h_2=0), "oscillator h0 must be a finite number >= 0, not -1e-20"),
                                    (dict(h0=0, h_1=math.nan, h_2=0), "oscillator h_1 must be a finite number >= 0, not nan")])
def test_bad_h_parameters(kw, msg):
    with pytest.raises(ValueError, match=msg):
        Oscillator(**kw)
