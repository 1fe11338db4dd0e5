"""The AUKF patent's tracker: the block slave's noise-floor model (the data wipe's discriminator gain),
q_hat kept inside the slave's table, and the divergence rule's frequency-loss test."""
import math

import numpy as np
import pytest

from dsp.gnss.aukf import AukfTracker
from dsp.gnss.aukf_slave import Q_TABLE, block_moments, wipe_gain
from dsp.gnss.jerk import jerk_phi, jerk_q
from dsp.gnss.trackers import TrackerContext


def test_wipe_gain():
    r32 = 1 / (2e-3 * 10 ** 3.2)
    assert wipe_gain(r32) == pytest.approx(1 - math.erfc(1 / math.sqrt(2 * r32)), rel=1e-15)
    assert wipe_gain(r32) == pytest.approx(0.925, abs=1e-3)
    assert wipe_gain(1e-9) == 1.0 and wipe_gain(0.0) == 1.0
    assert wipe_gain(1 / (2e-3 * 10 ** 2.8)) == pytest.approx(0.739, abs=1e-3)


def test_block_moments_noise_floor_grows_with_the_wipe_loss():
    Phi, Qb = jerk_phi(0.1, 1e-3), jerk_q(0.1, 1.0, 1e-3)
    r = 1 / (2e-3 * 10 ** 3.2)
    a1, b1 = block_moments(0.5, Phi, Qb, r, 500)
    ak, bk = block_moments(0.5, Phi, Qb, r, 500, kd=wipe_gain(r))
    # measured on the fast path (100 runs x 10 s, q_hat = q_true = 0.5): E[z] = 0.240 +- 0.008;
    # kd = 1 predicted 0.193, the wipe gain 0.211
    assert bk > 1.1 * b1 and ak > a1
    assert 0.5 * ak + bk == pytest.approx(0.211, rel=0.02)


def test_q_hat_kept_inside_the_table():
    ctx = TrackerContext(fs_hz=16.368e6, doppler0_hz=np.zeros(3), cn0_dbhz=32.0)
    t = AukfTracker(ctx, "float64", Pq0=9.0)
    for z in (1e9, 1e12, 1e15):
        t._slave_predict()
        t._slave_update(np.full((3, 1), z), lambda Qs: (0.2 * Qs + 1.0)[..., None],
                        np.full((3, 1, 1), 2.0))
    assert np.all(t.qhat <= Q_TABLE[1] * (1 + 1e-12)) and np.all(t.qhat > 1e3)


def _prompts(f_err_hz, cn0_dbhz, n, B, seed=3):
    """Raw prompts of a carrier ``f_err_hz`` off the NCO (unit noise, amplitude
    sqrt(2 T C/N0), random 20-ms data bits), the tracker open loop."""
    rng = np.random.default_rng(seed)
    A = math.sqrt(2e-3 * 10 ** (cn0_dbhz / 10))
    k = np.arange(n)
    bits = np.repeat(rng.choice([-1.0, 1.0], size=(n // 20 + 1, B)), 20, axis=0)[:n]
    ph = 2 * np.pi * f_err_hz * k * 1e-3 + 0.4
    return A * bits * np.exp(1j * ph)[:, None] + rng.normal(size=(n, B)) + 1j * rng.normal(size=(n, B))


@pytest.mark.parametrize("f_err, lost", [(0.0, False), (80.0, True)])
def test_frequency_loss_is_diverged(f_err, lost):
    """28 dB-Hz, 3 s: a carrier 80 Hz off (beyond the narrow master's pull-in; the wiped
    20-epoch sums still look locked to the phase test) is flagged by the narrow/wide-band
    test; a carrier on frequency is not."""
    B, n = 16, 3000
    ctx = TrackerContext(fs_hz=16.368e6, doppler0_hz=np.zeros(B), cn0_dbhz=28.0)
    t = AukfTracker(ctx, "float64", adaptive=False)
    p = _prompts(f_err, 28.0, n, B)
    z = np.zeros(B)
    for k in range(n):
        t.step(z, z, p[k].real, p[k].imag, z, z)
    rep = t.report()
    lt = rep["lock_tests"]
    assert lt["nbw_limit"] == pytest.approx(1 + 0.5 * (lt["nbw_ratio_in_lock"] - 1))
    if lost:
        assert rep["diverged_count"] == B and lt["frequency_loss_count"] == B
        assert max(lt["nbw_ratio_min_per_s"][1:]) < lt["nbw_limit"]
    else:
        assert rep["diverged_count"] == 0
        assert min(lt["nbw_ratio_min_per_s"]) > 0.8 * lt["nbw_ratio_in_lock"]
