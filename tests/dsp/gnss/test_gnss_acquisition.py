"""Acquisition: finds the PRN at 40 dB-Hz; absent PRN not reported at the stated Pfa."""
import numpy as np
import pytest
from scipy import stats

from cosim.gnss.dynamics import constant, aukf_patent_dynamics
from cosim.gnss.signal import GnssSignalConfig, GnssSignalGenerator
from dsp.gnss.acquisition import acquire, threshold
from dsp.gnss.ca_code import CODE_LENGTH
from hdl.gnss.params import DEFAULT_FS_HZ

FS = DEFAULT_FS_HZ           # the signal generator's default rate
N = round(FS * 1e-3)         # samples per 1 ms code period


def _snapshot(ms, **kw):
    cfg = GnssSignalConfig(duration_s=ms * 1e-3 + 0.002, **kw)
    g = GnssSignalGenerator(cfg)
    return cfg, g, g.samples(0, N * ms)[0]


@pytest.mark.parametrize("kw", [
    dict(prn=7, dynamics=aukf_patent_dynamics(q=0), code_phase_chips=345.6, seed=3),
    dict(prn=19, dynamics=constant(-650.0), code_phase_chips=1010.3, seed=4),
])
def test_acquires_at_40_dbhz_within_half_bin_and_half_chip(kw):
    cfg, g, x = _snapshot(10, cn0_dbhz=40.0, **kw)
    r = acquire(x, FS, cfg.prn, cfg.digital_if_hz, cfg.spectrum_inverted, n_noncoherent=10,
                pfa=1e-3)
    tr = g.truth_at(0.0)
    assert r.detected and r.peak > r.threshold
    assert abs(r.doppler_hz - tr["doppler_hz"][0]) <= r.bin_width_hz / 2
    dc = (r.code_phase_chips - tr["code_phase_chips"][0] + CODE_LENGTH / 2) % CODE_LENGTH - CODE_LENGTH / 2
    assert abs(dc) < 0.5
    init = r.channel_init()
    assert init["n_start"] == 0 and init["prn"] == cfg.prn
    # another PRN in the same snapshot is not reported
    other = acquire(x, FS, cfg.prn % 32 + 1, cfg.digital_if_hz, cfg.spectrum_inverted,
                    n_noncoherent=10, pfa=1e-3)
    assert not other.detected


def test_threshold_is_the_chi_square_quantile():
    th = threshold(0.01, 1000, 3)
    pc = 1 - (1 - 0.01) ** (1 / 1000)
    assert stats.chi2.sf(th, 6) == pytest.approx(pc, rel=1e-9)
    # per-cell Monte Carlo of the normalised statistic under H0 at a loose rate
    rng = np.random.default_rng(5)
    K, n = 3, 400000
    lam = np.sum(rng.standard_normal((n, 2 * K)) ** 2, axis=1)
    th1 = threshold(0.5, 1000, K)     # pfa_cell = 6.9e-4
    p = stats.chi2.sf(th1, 2 * K)
    cnt = np.count_nonzero(lam > th1)
    lo, hi = stats.binom.ppf([1e-4, 1 - 1e-4], n, p)
    assert lo <= cnt <= hi


def test_absent_prn_not_reported_at_the_stated_false_alarm_rate():
    """Seeded Monte Carlo of noise-only searches (signal_present=False, 2-bit ADC):
    false alarms at most the binomial 99.9 % bound of the stated per-search Pfa (the cells
    are correlated, so the rate is at or below Pfa; the bound is one-sided)."""
    pfa, n = 0.05, 200
    hits = 0
    for s in range(n):
        cfg = GnssSignalConfig(prn=7, cn0_dbhz=40.0, signal_present=False, duration_s=0.004,
                               seed=1000 + s)
        x = GnssSignalGenerator(cfg).samples(0, 2 * N)[0]
        r = acquire(x, FS, 7, cfg.digital_if_hz, n_noncoherent=2, max_doppler_hz=1500.0, pfa=pfa)
        hits += r.detected
    assert hits <= stats.binom.ppf(0.999, n, pfa), hits
    # and the search is not blind: the same statistic detects a weak 40 dB-Hz signal
    cfg = GnssSignalConfig(prn=7, cn0_dbhz=40.0, duration_s=0.004, seed=7)
    x = GnssSignalGenerator(cfg).samples(0, 2 * N)[0]
    assert acquire(x, FS, 7, cfg.digital_if_hz, n_noncoherent=2, max_doppler_hz=1500.0,
                   pfa=pfa).detected


def test_bad_input():
    x = np.random.default_rng(0).standard_normal(N * 2)
    with pytest.raises(ValueError, match="PRN"):
        acquire(x, FS, 33, 4.092e6)
    with pytest.raises(ValueError, match="whole number of samples per 1 ms"):
        acquire(x, 16.3681e6, 7, 4.092e6)
    with pytest.raises(ValueError, match=f"snapshot needs {5 * N} samples"):
        acquire(x, FS, 7, 4.092e6, n_noncoherent=5)
    with pytest.raises(ValueError, match="pfa must be in"):
        acquire(x, FS, 7, 4.092e6, n_noncoherent=2, pfa=0.0)
    with pytest.raises(ValueError, match="no noise power"):
        acquire(np.zeros(N), FS, 7, 4.092e6, n_noncoherent=1)


def test_handover_to_the_tracking_channel_pulls_in():
    """Acquisition -> channel_init -> GoldenCorrelator + FLL-assisted 3rd-order PLL: from
    the ~80 Hz / 0.04 chip acquisition error, phase lock (PLI) within 400 ms at 45 dB-Hz."""
    from cosim.gnss.signal import SampleStream
    from dsp.gnss.correlator import GoldenCorrelator
    from dsp.gnss.loops import TrackingChannel
    cfg = GnssSignalConfig(prn=7, cn0_dbhz=45.0, duration_s=0.42, code_phase_chips=345.6,
                           dynamics=aukf_patent_dynamics(q=0), seed=3)
    g = GnssSignalGenerator(cfg)
    src = SampleStream(g)
    r = acquire(src(0, N * 10), FS, 7, cfg.digital_if_hz, n_noncoherent=10)
    init = r.channel_init()
    assert r.detected and abs(r.doppler_hz - g.truth_at(0.0)["doppler_hz"][0]) > 50  # a real pull-in
    ch = TrackingChannel(1e-3, 3, 15.0, 2.0, 0.5, cfg.digital_if_hz, False, r.doppler_hz, 0.0,
                         fll_bn_hz=10.0)
    corr = GoldenCorrelator(FS, 7, 0.5, init["carrier_freq_hz"], init["code_freq_hz"], 0.0,
                            init["code_phase_chips"], init["n_start"])
    fe, te = [], []
    for _ in range(400):
        M = corr.samples_needed()
        d = corr.integrate(src(corr.n_next, M))
        tm = g.truth_at((d.n_start + M / 2) / FS)
        fe.append(tm["doppler_hz"][0] - (d.carrier_freq_hz - cfg.digital_if_hz))
        te.append((tm["code_phase_chips"][0] - (d.code_phase_start + d.code_freq_hz / FS * M / 2)
                   + 511.5) % 1023 - 511.5)
        corr.set_frequencies(*ch.update(d.ie, d.qe, d.ip, d.qp, d.il, d.ql))
    assert ch.lock.phase_lock and ch.lock.cn0_lock
    assert abs(np.mean(fe[-100:])) < 2.0 and np.max(np.abs(te[-100:])) < 0.05
