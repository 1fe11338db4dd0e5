"""C/N0 estimators on prompt samples of known C/N0 (drawn from their definition)."""
import numpy as np
import pytest

from dsp.gnss.cn0 import cn0_m2m4, cn0_nwpr

T = 1e-3


def _prompt(cn0_dbhz, n, rng, bits=False, phase=0.3):
    a = np.sqrt(2 * 10 ** (cn0_dbhz / 10) * T)       # |s| for unit-variance I and Q noise
    d = np.repeat(rng.choice([-1.0, 1.0], n // 20 + 1), 20)[:n] if bits else 1.0
    return a * d * np.exp(1j * phase) + rng.standard_normal(n) + 1j * rng.standard_normal(n)


@pytest.mark.parametrize("cn0", [30.0, 40.0, 50.0])
def test_m2m4_is_unbiased_within_0p2_db(cn0):
    rng = np.random.default_rng(int(cn0))
    est = cn0_m2m4(_prompt(cn0, 40_000, rng, bits=True), T)
    assert est == pytest.approx(cn0, abs=0.2)


@pytest.mark.parametrize("cn0", [35.0, 45.0])
def test_nwpr_within_0p2_db(cn0):
    rng = np.random.default_rng(int(cn0) + 1)
    est = cn0_nwpr(_prompt(cn0, 40_000, rng, bits=True), T, m=20)
    assert est == pytest.approx(cn0, abs=0.2)


def test_batched_and_noise_only():
    rng = np.random.default_rng(3)
    p = np.stack([_prompt(40.0, 20_000, rng), _prompt(45.0, 20_000, rng)])
    np.testing.assert_allclose(cn0_m2m4(p, T), [40.0, 45.0], atol=0.2)
    np.testing.assert_allclose(cn0_nwpr(p, T), [40.0, 45.0], atol=0.2)
    noise = rng.standard_normal(20000) + 1j * rng.standard_normal(20000)
    assert cn0_m2m4(noise, T) < 25.0     # no signal: a low (or -inf) estimate, never NaN
    assert not np.isnan(cn0_m2m4(np.zeros(10) + 0j, T))


@pytest.mark.parametrize("f,kw,msg", [
    (cn0_m2m4, dict(T_s=0.0), r"T_s \(coherent interval\) must be > 0 s, not 0.0"),
    (cn0_nwpr, dict(T_s=1e-3, m=1), r"m \(intervals per NWPR block\) must be an integer >= 2, not 1"),
    (cn0_nwpr, dict(T_s=1e-3, m=20), "NWPR needs at least one block of m = 20 intervals, not 5"),
])
def test_bad_arguments(f, kw, msg):
    with pytest.raises(ValueError, match=msg):
        f(np.ones(5, complex), **kw)
