"""Discriminators, loop filters and the tracking channel: Kaplan's figures on the fast path,
a short IF-path closed loop through the golden correlator."""
import numpy as np
import pytest

from cosim.gnss.dynamics import aukf_patent_dynamics
from cosim.gnss.loopsim import (cycle_slips, jerk_cycles_s3, kaplan_threshold_dbhz, track_fast,
                                tracking_threshold, truth_for)
from cosim.gnss.signal import GnssSignalConfig, GnssSignalGenerator, SampleStream
from dsp.gnss.correlator import GoldenCorrelator
from dsp.gnss.discriminators import costas_atan, dll_nelp, fll_cross_dot, pll_atan2
from dsp.gnss.loops import (TrackingChannel, hz_to_word, jerk_stress_deg, kaplan_jitter_deg,
                            noise_bandwidth, pli)

T = 1e-3


def test_discriminators_noise_free():
    e = np.array([-0.2, -0.05, 0.0, 0.1, 0.24])
    p = 7.0 * np.exp(2j * np.pi * e)
    assert np.allclose(costas_atan(p.real, p.imag), e)
    assert np.allclose(costas_atan(-p.real, -p.imag), e)          # data bit flip
    e4 = np.array([-0.45, 0.3, 0.49])
    p4 = np.exp(2j * np.pi * e4)
    assert np.allclose(pll_atan2(p4.real, p4.imag), e4)
    f = 123.0
    p1, p2 = 3 * np.exp(0.3j), 3 * np.exp(0.3j + 2j * np.pi * f * T)
    assert fll_cross_dot(p1.real, p1.imag, p2.real, p2.imag, T) == pytest.approx(f)
    assert fll_cross_dot(p1.real, p1.imag, -p2.real, -p2.imag, T, four_quadrant=False) == pytest.approx(f)
    for d in (0.5, 1.0):
        for tau in (-0.2, 0.0, 0.17):
            E, L = 1 - abs(tau - d / 2), 1 - abs(tau + d / 2)
            assert dll_nelp(E, 0.0, L, 0.0, d) == pytest.approx(tau)
    assert pli(10.0, 0.0) == 1.0 and pli(0.0, 3.0) == -1.0
    assert pli(np.cos(0.3), np.sin(0.3)) == pytest.approx(np.cos(0.6))


def test_nco_word_error_is_bounded():
    fs = 16.368e6
    f = np.random.default_rng(1).uniform(-fs / 2 + 1, fs / 2 - 1, 1000)
    w, err = hz_to_word(f, fs, 32)
    assert np.all(np.abs(err) <= fs / 2 ** 33 * (1 + 1e-9))
    assert np.allclose(w * fs / 2 ** 32 - f, err)
    with pytest.raises(ValueError, match="outside the 32-bit NCO range"):
        hz_to_word(fs * 0.6, fs)


def test_noise_bandwidth_of_the_digital_loop():
    """Actual Bn of the Euler-integrator loops at Bn T = 0.015 (pinned), a few % above the
    nominal; the one-epoch write latency of the FPGA channel adds ~5 % more."""
    assert noise_bandwidth(3, 15, T) == pytest.approx(15.478, abs=0.005)
    assert noise_bandwidth(2, 15, T) == pytest.approx(15.579, abs=0.005)
    assert noise_bandwidth(3, 15, T, latency=1) == pytest.approx(16.221, abs=0.005)
    assert noise_bandwidth(3, 2, T) == pytest.approx(2, rel=0.01)   # BnT -> 0: nominal


@pytest.mark.parametrize("latency", [0, 1])
def test_jerk_stress_within_5_percent_of_kaplan(latency):
    """Constant 5 g/s jerk on top of the AUKF patent's start, noise
    free: the steady-state
    phase error vs 0.4828 J / Bn^3 (J in deg/s^3 -> deg)."""
    tr = truth_for(aukf_patent_dynamics(q=0, jerk_g_per_s=5.0, jerk_start_s=0.0), 4.1)
    r = track_fast(tr, None, 4000, bn_hz=15.0, latency=latency)
    J = jerk_cycles_s3(5.0) * 360.0
    theory = jerk_stress_deg(J, 15.0)
    assert theory == pytest.approx(0.4828 * J / 15.0 ** 3, rel=1e-4)
    meas = r.phase_err_cycles[3000:] * 360.0   # the complex poles decay at ~2.8 /s
    assert np.ptp(meas) < 0.01 * theory                     # settled
    assert abs(meas.mean() / theory - 1) < 0.05, (meas.mean(), theory)


def test_thermal_jitter_within_10_percent_of_kaplan_above_35_dbhz():
    """Closed-loop Monte Carlo (Costas, 3rd order, Bn 15 Hz, T 1 ms), static-rate AUKF
    patent dynamics, against Kaplan's formula evaluated with the *actual* Bn of the digital loop."""
    tr = truth_for(aukf_patent_dynamics(q=0), 2.2)
    bn = noise_bandwidth(3, 15.0, T)
    cn0 = np.array([35.0, 40.0, 45.0])
    r = track_fast(tr, cn0[:, None], 2000, bn_hz=15.0, shape=(3, 60), seed=11)
    e = r.phase_err_cycles[200:] * 360.0
    assert np.all(cycle_slips(r.phase_err_cycles) == 0)
    meas = e.std(axis=(0, 2))
    kap = kaplan_jitter_deg(cn0, bn, T)
    assert np.all(np.abs(meas / kap - 1) < 0.10), (meas, kap)


def _jerk_run(duration_s, n_trials, seed):
    tr = truth_for(aukf_patent_dynamics(q=0, jerk_g_per_s=5.0, jerk_start_s=0.5, jerk_duration_s=duration_s),
                   duration_s + 1.01)
    return track_fast(tr, 45.0, int(round((duration_s + 1.0) / T)), bn_hz=15.0,
                      shape=(n_trials,), seed=seed)


def test_pll3_45_dbhz_aukf_patent_jerk_no_slip_short():
    r = _jerk_run(1.5, 8, 3)
    assert np.all(cycle_slips(r.phase_err_cycles) == 0)
    assert np.abs(r.phase_err_cycles).max() < 0.125    # 45 deg: 13 deg stress + noise


@pytest.mark.slow
def test_pll3_45_dbhz_aukf_patent_jerk_10_s_no_slip():
    r = _jerk_run(10.0, 8, 4)
    assert np.all(cycle_slips(r.phase_err_cycles) == 0)
    assert np.abs(r.phase_err_cycles).max() < 0.125


def test_cycle_slip_counter_counts_a_real_slip():
    """The criterion can fail: at 22 dB-Hz through the jerk the loop slips."""
    tr = truth_for(aukf_patent_dynamics(q=0, jerk_g_per_s=5.0, jerk_start_s=0.2, jerk_duration_s=1.0), 1.6)
    r = track_fast(tr, 22.0, 1500, bn_hz=15.0, shape=(20,), seed=5)
    assert np.count_nonzero(cycle_slips(r.phase_err_cycles)) > 0
    assert cycle_slips(np.array([0.0, 0.1, 0.3, 0.5, 0.52])) == 1
    assert cycle_slips(np.array([0.0, 0.3, 0.6]), costas=False) == 1


def test_tracking_threshold_benchmark_short():
    """A coarse, short run of the benchmark: the threshold lands near Kaplan's 28.7 dB-Hz
    rule (measured: see the report in the commit log; full run = defaults)."""
    res = tracking_threshold(np.arange(24.0, 34.1, 2.0), n_trials=10, jerk_duration_s=1.0,
                             settle_s=0.2)
    assert res["kaplan_rule_dbhz"] == pytest.approx(28.7, abs=0.05)
    assert 24.0 < res["threshold_dbhz"] <= 32.0, res


def test_if_path_closed_loop_golden_correlator():
    """Generator -> GoldenCorrelator -> TrackingChannel -> set_frequencies, 300 ms at
    45 dB-Hz with the AUKF patent's dynamics (1000 m/s, 1 g) and 5 g/s jerk from 0.1 s; the
    channel starts 4 Hz and 0.15 chip off the truth."""
    cfg = GnssSignalConfig(prn=7, cn0_dbhz=45.0, duration_s=0.32, code_phase_chips=100.25,
                           dynamics=aukf_patent_dynamics(q=0, jerk_g_per_s=5.0, jerk_start_s=0.1), seed=9)
    g = GnssSignalGenerator(cfg)
    src = SampleStream(g)
    t0 = g.truth_at(0.0)
    fd0 = float(t0["doppler_hz"][0]) + 4.0
    ch = TrackingChannel(T, 3, 15.0, 1.0, 0.5, cfg.digital_if_hz, cfg.spectrum_inverted,
                         fd0, float(t0["doppler_rate_hz_s"][0]))
    corr = GoldenCorrelator(cfg.fs_hz, 7, 0.5, cfg.digital_if_hz + fd0, ch.code_rate,
                            0.0, (100.25 - 0.15) % 1023)
    errs, taus = [], []
    for k in range(300):
        M = corr.samples_needed()
        d = corr.integrate(src(corr.n_next, M))
        nm = d.n_start + M / 2
        tm = g.truth_at(nm / cfg.fs_hz)
        sig = (cfg.digital_if_hz * nm / cfg.fs_hz) % 1.0 + tm["carrier_phase_cycles"][0]
        rep = d.carrier_phase_start + d.carrier_freq_hz / cfg.fs_hz * M / 2
        errs.append(sig - rep)
        taus.append((tm["code_phase_chips"][0] - (d.code_phase_start + d.code_freq_hz / cfg.fs_hz * M / 2)
                     + 511.5) % 1023 - 511.5)
        corr.set_frequencies(*ch.update(d.ie, d.qe, d.ip, d.qp, d.il, d.ql))
    e = np.unwrap(np.array(errs), period=1.0)
    e -= np.rint(e[50] * 2) / 2        # Costas: the lock point it chose (a half cycle)
    assert cycle_slips(e) == 0
    # the same scenario and initial errors, noise free, on the fast path: the IF loop
    # follows that trajectory to within its thermal noise (Kaplan, actual Bn)
    ref = track_fast(g.truth_at, None, 300, freq0_err_hz=4.0, code0_err_chips=0.15)
    diff = (e - ref.phase_err_cycles) * 360.0
    sig = kaplan_jitter_deg(45.0, noise_bandwidth(3, 15.0, T), T)
    assert np.std(diff) < 1.5 * sig and np.max(np.abs(diff)) < 6 * sig, (np.std(diff), sig)
    assert np.abs(ref.phase_err_cycles).max() > 0.03     # a real transient was followed
    assert np.max(np.abs(np.array(taus) - ref.code_err_chips)) < 0.02
    # lock detectors over the last 100 epochs: the PLI reads the true cos 2e (the jerk
    # transient reaches ~30 deg here); the C/N0 estimate is the generator's 45 dB-Hz less
    # the 2-bit ADC loss (~0.55 dB), the ~0.06 chip code-error loss (~0.5 dB) and the
    # phase-error loss, with ~0.4 dB rms M2M4 spread on 100 prompts
    assert abs(ch.lock.pli - np.mean(np.cos(4 * np.pi * e[200:]))) < 0.1
    assert ch.lock.cn0_lock and 41.5 < ch.lock.cn0_dbhz < 45.5


def test_lock_detectors_in_lock_and_out():
    from cosim.gnss.fastpath import correlate_fast
    from dsp.gnss.loops import LockDetector
    rng = np.random.default_rng(8)
    bits = np.repeat(rng.choice([-1.0, 1.0], 50), 20)[None, :]     # data, unaligned windows
    k = np.arange(1000)
    # (C/N0, phase error, frequency error, phase lock expected, C/N0 lock expected):
    # in lock; a 37 Hz frequency error (the phase turns 0.37 cycle per PLI block: phase
    # lock lost, C/N0 still there); 10 dB-Hz, nothing to track (neither)
    for cn0, err, freq, plock, clock in ((45.0, 0.02, 0.0, True, True),
                                         (45.0, 0.037 * k, 37.0, False, True),
                                         (10.0, 0.0, 0.0, False, False)):
        det = LockDetector(T, window=1000, m=10)
        x = correlate_fast(cn0, err, freq, 0.0, np.roll(bits, 7), T, rng=rng, shape=(16, 1000))
        closed = [det.update(x.prompt[:, j]) for j in range(1000)]
        assert closed[-1] and not any(closed[:-1])
        assert np.all(det.phase_lock == plock) and np.all(det.cn0_lock == clock), (cn0, det.pli, det.cn0_dbhz)
        if plock:
            assert np.all(np.abs(det.pli - np.cos(4 * np.pi * err)) < 0.05)
            # M2M4 on 1000 prompts at 45 dB-Hz: ~0.2 dB rms per estimate
            assert abs(np.mean(det.cn0_dbhz) - cn0) < 0.3 and np.all(np.abs(det.cn0_dbhz - cn0) < 1.0)


def test_fll_assist_pulls_in_what_the_pll_alone_cannot():
    """150 Hz initial frequency error (a fraction of an acquisition bin), 45 dB-Hz, the AUKF
    patent's dynamics: with a 10 Hz FLL assist (cross/dot, Costas-safe atan form) the loop's mean
    frequency error over the last 200 ms of 2 s is below 1 Hz in every trial; the 3rd-order
    PLL alone (Bn 15 Hz) does not pull in."""
    tr = truth_for(aukf_patent_dynamics(q=0), 2.1)
    ok = []
    for fll in (10.0, None):
        r = track_fast(tr, 45.0, 2000, shape=(12,), seed=3, freq0_err_hz=150.0, fll_bn_hz=fll)
        ok.append(np.abs(r.freq_err_hz[-200:].mean(axis=0)) < 1.0)
    assert np.all(ok[0])
    assert np.count_nonzero(ok[1]) <= 2
