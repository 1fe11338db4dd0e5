"""The thermal-noise error budget (dsp.gnss.budget): the discriminator noise against a Monte
Carlo of the discriminators, the loop sums against their analogue limits and the textbook
DLL formula, the closed loop of the fixed-point tracker on the fast path against the
predicted code and Doppler noise, and the weighted-least-squares covariance."""
import numpy as np
import pytest

from cosim.gnss.dynamics import from_doppler
from cosim.gnss.loopsim import track_fast, truth_for
from dsp.gnss.ephemeris import CHIP_M
from dsp.gnss.budget import (TrackingLoops, betz_dll_sigma_chips, channel_sigmas,
                             code_sigma_chips, costas_discriminator_variance, dll_response,
                             doppler_sigma_hz, nelp_discriminator_variance, predicted_errors,
                             solution_covariance)
from dsp.gnss.discriminators import costas_atan, dll_nelp
from dsp.gnss.loops_fixed import ChannelCore, FixedArith
from dsp.gnss.pvt import dop_enu, enu_geometry

T = 1e-3
D = 2 * 1.023e6 / 5e6           # the channel's 2-sample E-L spacing at 5 MS/s (chips)


def _correlations(cn0_dbhz, d, n, seed):
    """E, P, L at zero errors with unit noise per component, E/L noise correlated 1 - d."""
    rng = np.random.default_rng(seed)
    a = np.sqrt(2 * 10 ** (cn0_dbhz / 10) * T)
    cov = np.array([[1, 1 - d / 2, 1 - d], [1 - d / 2, 1, 1 - d / 2], [1 - d, 1 - d / 2, 1]])
    c = np.linalg.cholesky(cov)
    n_i, n_q = c @ rng.standard_normal((3, n)), c @ rng.standard_normal((3, n))
    amp = a * np.array([1 - d / 2, 1.0, 1 - d / 2])[:, None]
    return amp + n_i + 1j * n_q


@pytest.mark.parametrize("cn0", [40.0, 45.0, 48.0])
def test_discriminator_noise_matches_monte_carlo(cn0):
    e, p, l_ = _correlations(cn0, D, 400_000, seed=int(cn0))
    tau = dll_nelp(e.real, e.imag, l_.real, l_.imag, D)
    # 400 000 draws: the variance's relative standard error is ~0.3 %
    assert tau.var() / nelp_discriminator_variance(cn0, T, D) == pytest.approx(1, abs=0.012)
    ph = costas_atan(p.real, p.imag)
    assert ph.var() / costas_discriminator_variance(cn0, T) == pytest.approx(1, abs=0.012)


def test_dll_sum_is_the_analogue_loop_and_the_textbook_formula():
    # sum h^2 -> 2 Bn T as Bn T -> 0 (first-order loop: K T / (2 - K T) with K = 4 Bn)
    h = dll_response(1.0, T, 0)
    assert np.sum(h ** 2) == pytest.approx(4e-3 / (2 - 4e-3), rel=1e-6)
    # with the latency of the FPGA channel: 0.6 % above it
    assert np.sum(dll_response(1.0, T, 1) ** 2) == pytest.approx(2.012e-3, rel=1e-3)
    # Betz & Kolodziejski / Kaplan, d = 1 chip, Bn 1 Hz, T 20 ms, 45 dB-Hz: 3.98e-3 chips
    assert betz_dll_sigma_chips(45.0, 1.0, 1.0, 0.02) == pytest.approx(3.98e-3, abs=5e-6)
    # the budget's DLL against the textbook at the receiver's d and T: the squaring terms
    # differ by 0.4 % at 45 dB-Hz, the loop sums by 0.1 %
    loops = TrackingLoops(spacing_chips=D)
    assert code_sigma_chips(45.0, loops) == pytest.approx(
        betz_dll_sigma_chips(45.0, 1.0, D, T), rel=6e-3)
    pr, _ = channel_sigmas(np.array([40.0, 45.0, 50.0]), loops)
    # 1 / sqrt(C/N0) and the squaring term (1 + 1 / (c T))
    assert pr[0] / pr[1] == pytest.approx(10 ** 0.25 * np.sqrt(1.1 / (1 + 10 ** -1.5)))
    assert pr[1] == pytest.approx(code_sigma_chips(45.0, loops) * CHIP_M)


def test_loops_refuse_bad_options():
    with pytest.raises(ValueError, match="order"):
        TrackingLoops(order=4)
    with pytest.raises(ValueError, match="dll_bn_hz"):
        TrackingLoops(dll_bn_hz=0.0)
    with pytest.raises(ValueError, match="spacing_chips"):
        TrackingLoops(spacing_chips=1.5)
    with pytest.raises(ValueError, match="cn0_dbhz"):
        code_sigma_chips(np.nan, TrackingLoops())


class _Recording:
    """The fixed-point tracker, keeping the Doppler it reports after every dump."""

    def __init__(self, core):
        self.core, self.v1 = core, []

    def step(self, *iq):
        out = self.core.step(*iq)
        self.v1.append(np.array(self.core.doppler_hz(), dtype=float))
        return out

    def frequencies_hz(self, out):
        return self.core.frequencies_hz(out)


def test_fixed_tracker_closed_loop_noise_matches_the_budget():
    """The fixed-point pll3 + DLL closed loop on the correlation-domain fast path (latency 1,
    the receiver's E-L spacing, 45 dB-Hz, a satellite-like Doppler and rate): the code
    error and the Doppler state's error against the budget's sigmas."""
    cn0, n_ep, trials, skip = 45.0, 1400, 500, 600
    loops = TrackingLoops(spacing_chips=D)
    f0, rate = 1200.0, -0.6
    tr = truth_for(from_doppler(f0, rate), n_ep * T + 0.01, nav_data=False)
    core = ChannelCore(FixedArith(), 5e6, T, 3, 15.0, 1.0, D, 0.0, False,
                       np.full(trials, f0), np.full(trials, rate))
    rec = _Recording(core)
    r = track_fast(tr, cn0, n_ep, T, shape=(trials,), spacing_chips=D, latency=1,
                   tracker=rec, seed=5, fs_hz=5e6)
    code = r.code_err_chips[skip:]
    sc = code.std()
    assert abs(code.mean()) < 0.2 * sc
    # the loops start on the truth; after 0.6 s the DLL's variance (time constant 0.25 s)
    # has built up. ~3 independent samples per trial x 500 trials: ~2 % standard error
    assert sc / code_sigma_chips(cn0, loops) == pytest.approx(1, abs=0.08)
    # v1 after dump k is the Doppler in force at epoch k + 2 (latency 1), the truth over
    # that epoch is the replica's Doppler plus the frequency error
    v1 = np.array(rec.v1)
    true_f = r.doppler_hz + r.freq_err_hz
    dv = v1[skip:-2] - true_f[skip + 2:]
    assert dv.std() / doppler_sigma_hz(cn0, loops) == pytest.approx(1, abs=0.08)


def test_weighted_covariance():
    rng = np.random.default_rng(3)
    el = np.array([80.0, 45.0, 30.0, 20.0, 60.0, 15.0, 35.0])
    az = np.array([10.0, 70.0, 140.0, 200.0, 250.0, 300.0, 330.0])
    g = enu_geometry(el, az)
    # equal weights and equal noise: the DOPs times the sigma
    cov = solution_covariance(g, np.ones(7), np.full(7, 2.0))
    dop = dop_enu(el, az)
    assert np.sqrt(np.trace(cov[:3, :3])) == pytest.approx(2.0 * dop.pdop)
    assert np.sqrt(cov[2, 2]) == pytest.approx(2.0 * dop.vdop)
    # unequal weights: against the Monte Carlo of the weighted least squares
    ws, ns = rng.uniform(1, 3, 7), rng.uniform(0.5, 2, 7)
    w = 1 / ws ** 2
    a = np.linalg.solve(g.T @ (w[:, None] * g), (g * w[:, None]).T)
    x = a @ (ns[:, None] * rng.standard_normal((7, 200_000)))
    pred = predicted_errors(el, az, ws, ns)
    assert x[0].std() == pytest.approx(pred["east"], rel=0.01)
    assert np.sqrt((x[:3] ** 2).sum(0).mean()) == pytest.approx(pred["3d"], rel=0.01)
    # the matched weights are the minimum-variance ones
    assert predicted_errors(el, az, ns, ns)["3d"] <= pred["3d"]
    with pytest.raises(ValueError, match="rows"):
        solution_covariance(g[:3], np.ones(3), np.ones(3))
