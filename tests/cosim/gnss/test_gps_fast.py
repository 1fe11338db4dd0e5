"""The GPS receiver on the correlation-domain fast path (:mod:`cosim.gnss.gps_fast`): its
counts, its refusals, its statistics against the DLL theory and the IF path's acceptance
figures on the ``gps`` command's generated scenario, a moving receiver, the aiding hook, and
(slow) the statistical comparison with the IF path (:mod:`cosim.gnss.gps_fast_check`)."""
import math

import numpy as np
import pymap3d
import pytest
from scipy.stats import chi2

from cosim.gnss.constellation import ConstellationSignal
from cosim.gnss.gps_fast import (counts_from_chips, mai_cn0_dbhz, run_fast, select_channels,
                                 spacing_for)
from cosim.gnss.gps_fast_check import effective_dof, scenario
from cosim.gnss.gps_receiver import GpsConfig
from cosim.gnss.gps_scenario import scenario_config
from cosim.gnss.config import GnssRunConfig
from cosim.gnss.fastpath import adc_efficiency
from dsp.gnss.budget import betz_dll_sigma_chips
from dsp.gnss.ca_code import CHIP_RATE_HZ
from dsp.gnss.observables import transmit_time

C = 299792458.0
CHIP_M = C / CHIP_RATE_HZ


@pytest.fixture(scope="module")
def static():
    """1.6 s of the generated scenario at 45 dB-Hz, 8 trials at 10 Hz."""
    cfg, _ = scenario_config(scenario(45.0, 1.6))
    sig = ConstellationSignal(cfg)
    return sig, run_fast(cfg, signal=sig, gps=GpsConfig(rate_hz=10.0), trials=8, seed=3)


def test_counts_from_chips_give_the_satellite_time():
    F = 345_600.0 + 30.0
    chi = np.array([0.0, 1022.999, 20460.5, 6138000.0 * 3 + 12345.678, 1.0e8 + 0.25])
    t = transmit_time(*counts_from_chips(chi, F))
    np.testing.assert_allclose(t, F + chi / CHIP_RATE_HZ, rtol=0, atol=1e-12)
    tow, nb, nc, ch = counts_from_chips(chi, F)
    assert np.all(np.mod(tow, 6.0) == 0) and nb.dtype.kind == "i" and np.all(ch < 1023)
    with pytest.raises(ValueError, match="chips_total"):
        counts_from_chips([-1.0], F)


def test_bad_input_is_refused_before_work():
    cfg, _ = scenario_config(scenario(45.0, 0.5))
    for kw, match in (({"trials": 0}, "trials"), ({"seed": -1}, "seed"),
                      ({"duration_s": 0.05}, "no measurement epoch"),
                      ({"duration_s": 2.0}, "duration_s"), ({"mai": 1}, "mai"),
                      ({"aiding": 3.0}, "aiding"), ({"tracker_options": 1}, "tracker_options"),
                      ({"doppler_instant": 1}, "doppler_instant"),
                      ({"run": GnssRunConfig(tracker="aided-kf")}, "needs an aiding"),
                      ({"adc_bits": 0}, "adc_bits")):
        with pytest.raises(ValueError, match=match):
            run_fast(cfg, **kw)


def test_the_static_scenario_meets_the_if_paths_acceptance(static):
    """What the slow IF-path test of ``gps`` asks of its fixes, asked of every trial: every
    epoch fixed with every satellite (3-D RMS within 5 m), the Doppler velocity within
    0.1 m/s, the Doppler within 2 Hz and the carrier phase's change within 0.05 cycle of
    the truth; the receiver clock steered: from the third epoch on the bias left is the
    drift over one epoch (mean over trials and epochs within 0.5 m, ~4 standard errors)."""
    sig, r = static
    assert len(r.prns) == 8 and r.series["code_chips"].shape == (15, 8, 8)
    for g in r.runs:
        assert len(g.epochs) == 15 and g.ttff_s == pytest.approx(0.1)
        sols = [e.solution for e in g.epochs]
        assert all(s.valid and len(s.used_prns) == 8 for s in sols)
        assert max(np.linalg.norm(s.velocity_enu_mps) for s in sols) < 0.1
        drift = 5e-8 * C
        assert all(abs(s.clock_drift_mps - drift) < 0.2 for s in sols)
    left = [e.solution.clock_bias_m - 0.1 * 5e-8 * C for g in r.runs for e in g.epochs[2:]]
    assert abs(np.mean(left)) < 0.5
    assert np.sqrt(np.mean(r.position_error_m() ** 2)) < 5.0
    assert np.max(np.abs(r.doppler_error_hz())) < 2.0
    dl = np.diff(r.series["carrier_cycles"], axis=0) + \
        np.diff(r.truth.carrier_phase_cycles, axis=0)[:, None, :]
    assert np.max(np.abs(dl)) < 0.05


def test_pseudorange_noise_matches_the_dll_theory(static):
    """The range error's mean square after 0.5 s against the carrier-aided DLL's
    ``Bn d / (2 C/N0) (1 + 2 / ((2 - d) T C/N0))`` chips^2 (Kaplan & Hegarty, normalised
    early-minus-late envelope, ``d`` the E-L spacing) at the C/N0 the correlator sees
    (the 2-bit ADC's loss and the other satellites' interference), within the chi-square
    interval (two-sided 0.2 %) of the effective degrees of freedom."""
    sig, r = static
    k = r.t_s >= 0.5
    e = r.range_error_m()[k]
    tr = sig.truth_at(np.array([1.0]))
    total = float(np.sum(10 ** (tr.cn0_dbhz[0] / 10)))
    cn0 = mai_cn0_dbhz(45.0, total) + 10 * math.log10(adc_efficiency(2))
    theory = (betz_dll_sigma_chips(cn0, 1.0, spacing_for(sig.cfg.fs_hz), 1e-3) * CHIP_M) ** 2
    nu = effective_dof(e)
    ratio = np.mean(e ** 2) / theory
    assert chi2.ppf(0.001, nu) / nu <= ratio <= chi2.ppf(0.999, nu) / nu, (ratio, nu)
    # the C/N0 the lock windows read (M2M4, biased up ~0.5 dB on 20 prompts) is near it
    assert abs(np.nanmean(r.series["cn0_dbhz"][k]) - cn0) < 1.0


def test_same_seed_same_run_and_trials_differ(static):
    sig, r = static
    again = run_fast(sig.cfg, signal=sig, gps=GpsConfig(rate_hz=10.0), trials=8, seed=3,
                     duration_s=0.35)
    np.testing.assert_array_equal(again.series["code_chips"], r.series["code_chips"][:3])
    assert not np.array_equal(r.series["code_chips"][:, 0], r.series["code_chips"][:, 1])
    assert select_channels(sig, 12).size == 8 and select_channels(sig, 5).size == 5


def test_a_moving_receiver_and_an_aided_tracker():
    """A receiver flying along track at 300 m/s accelerating at 2 g (the INS profile's
    kinematics), the aided Kalman loop told each satellite's line-of-sight Doppler rate:
    every fix within 10 m and 0.5 m/s of the truth (the truth at the epoch: the receiver
    moves 30 m in 0.1 s)."""
    from cosim.gnss.constellation_geometry import along_track_receiver

    class Profile:
        def kinematics(self, u):
            u = np.asarray(u, float)
            a = 2 * 9.80665
            return np.stack([300 * u + a * u * u / 2, 300 + a * u, a + 0 * u, 0 * u])

    cfg, _ = scenario_config(scenario(45.0, 0.8))
    cfg = cfg.replace(receiver=along_track_receiver(Profile(), 52.0, 4.4, 30.0, 45.0))
    sig = ConstellationSignal(cfg)
    cols = select_channels(sig, 12)
    h = 5e-3
    t = np.arange(0, 200) * h
    ph = sig.truth_at(t).carrier_phase_cycles[:, cols]
    rate = np.gradient(np.gradient(ph, h, axis=0), h, axis=0)   # Hz/s, per satellite

    def aiding(k):                            # epoch k of ~1 ms: the rate at its time
        return rate[min(int(round(k * 1e-3 / h)), rate.shape[0] - 1)]

    r = run_fast(cfg, signal=sig, run=GnssRunConfig(tracker="aided-kf", dsp="float"),
                 gps=GpsConfig(rate_hz=10.0), trials=2, seed=5, aiding=aiding,
                 tracker_options={"oscillator": None, "pli_epochs": 20})
    assert len(r.runs[0].epochs) == 7
    (idx, trk), = r.trackers                  # one nominal C/N0: one tracker of (2, S)
    assert idx.size == len(r.prns) and trk.history.pli_epochs == 20
    # in phase lock (a 20-prompt block across a data-bit edge reads lower: the mean)
    assert np.mean(np.array(trk.history.pli)[5:]) > 0.95
    assert np.nanmax(r.position_error_m()) < 10.0
    for g in r.runs:
        for m, e in enumerate(g.epochs):
            v_true = r.truth.rx_velocity_mps[m]
            assert e.solution.valid
            lat, lon, _ = pymap3d.ecef2geodetic(*r.truth.rx_position_m[m])
            v_enu = np.array(pymap3d.ecef2enuv(*v_true, lat, lon))
            assert np.linalg.norm(np.asarray(e.solution.velocity_enu_mps) - v_enu) < 0.5


@pytest.mark.slow
@pytest.mark.parametrize("cn0", [45.0, 35.0])
def test_fast_path_against_the_if_path(tmp_path, cn0):
    """3 s of the generated scenario, 8 satellites, on the bit-exact channel array and on the
    fast path (20 trials), 10 Hz epochs after 1 s: the mean squares of the pseudorange error,
    the Doppler error and the 3-D position error within the F interval (two-sided 0.2 %) of
    the effective degrees of freedom, the mean C/N0 within Welch's interval. About 1.5
    minutes per C/N0 on the shared cores."""
    from cosim.gnss.gps_fast_check import compare
    r = compare(scenario(cn0, 3.0), tmp_path, trials=20)
    assert len(r["prns"]) == 8
    assert r["all_pass"], r["tests"]


def test_gps_fast_is_a_benchmark():
    from cosim.tools.bench import benchmarks
    assert "gps-fast" in benchmarks()


@pytest.mark.slow
def test_the_bench_writes_its_figures(tmp_path):
    """``bench gps-fast`` quick form: the speed rows of both scenarios and the comparison."""
    import json
    from cosim.gnss.gps_fast_bench import gps_fast
    r = gps_fast(tmp_path, quick=True)
    j = json.loads((tmp_path / "gps_fast.json").read_text())
    assert {x["satellites"] for x in j["speed"]} == {8, 12}
    assert all(x["signal_s_per_s"] > 0 for x in j["speed"])
    assert j["comparison"][0]["cn0_dbhz"] == 45.0 and "tests" in j["comparison"][0]
    assert r["if_model_signal_s_per_s"] > 0 and (tmp_path / "gps_fast.md").is_file()


@pytest.mark.slow
def test_the_comparison_can_fail_without_the_interference(tmp_path):
    """Without the other satellites' interference the fast path reads the C/N0 0.8 dB
    high at 45 dB-Hz: the C/N0 test fails."""
    from cosim.gnss.gps_fast_check import compare
    r = compare(scenario(45.0, 3.0), tmp_path, trials=20, mai=False)
    assert not r["tests"]["cn0_mean"]["pass"], r["tests"]["cn0_mean"]


@pytest.mark.slow
@pytest.mark.parametrize("tracker", ["aided-kf", "aided-pll"])
def test_doppler_at_the_measurement_instant(tracker):
    """At 20 g along track, 70 dB-Hz (noise negligible), the aided loop told each
    satellite's true Doppler rate: the reported Doppler stands up to an epoch away from
    the measurement instant (its mean error: the Doppler rate times a fixed offset per
    channel, 0.1-1.1 ms), the Doppler interpolated to the instant (``doppler_instant``)
    has under a fifth of that error (the aided PLL's report stands 1.5 epochs after its
    epoch's end under the one-epoch loop latency: ``doppler_offset_epochs``)."""
    from cosim.gnss.constellation_geometry import along_track_receiver

    class Profile:
        def kinematics(self, u):
            u = np.asarray(u, float)
            a = 20 * 9.80665
            return np.stack([300 * u + a * u * u / 2, 300 + a * u, a + 0 * u, 0 * u])

    cfg, _ = scenario_config(scenario(70.0, 1.0))
    cfg = cfg.replace(receiver=along_track_receiver(Profile(), 52.0, 4.4, 30.0, 45.0))
    sig = ConstellationSignal(cfg)
    cols = select_channels(sig, 12)
    h = 1e-3
    t = np.arange(0, 1000) * h
    ph = sig.truth_at(t).carrier_phase_cycles[:, cols]
    rate = np.gradient(np.gradient(ph, h, axis=0), h, axis=0)

    def aiding(k):
        return rate[min(k, rate.shape[0] - 1)]

    err = {}
    for inst in (False, True):
        r = run_fast(cfg, signal=sig, run=GnssRunConfig(tracker=tracker, dsp="float"),
                     gps=GpsConfig(rate_hz=10.0), trials=4, seed=5, aiding=aiding,
                     tracker_options={"oscillator": None} if tracker == "aided-kf" else {},
                     doppler_instant=inst)
        assert r.config["doppler_instant"] is inst
        err[inst] = r.doppler_error_hz()[2:]
    rt = rate[np.round(r.t_s[2:] / h).astype(int)].mean(axis=0)       # (S,) Hz/s
    big = np.abs(rt) > 200.0
    assert big.sum() >= 3
    rep, ins = err[False].mean(axis=(0, 1))[big], err[True].mean(axis=(0, 1))[big]
    # the report stands up to one epoch (~1 ms; the PLL's 1-2.5 ms) away from the instant:
    # its mean error is the rate times that offset; interpolated, a fifth of it at most
    lag_ms = np.abs(rep / rt[big]) * 1e3
    lo, hi = (0.1, 1.1) if tracker == "aided-kf" else (0.9, 2.6)
    assert np.all((lag_ms > lo) & (lag_ms < hi)), lag_ms
    assert np.all(np.abs(ins) < 0.2 * np.abs(rep)), (ins, rep)


def test_if_series_keeps_each_assignments_epochs(monkeypatch):
    # a PRN lost and assigned again: the first assignment's epochs keep its observables,
    # the gap is NaN, the second fills its own (not NaN over the first's)
    import types
    import cosim.gnss.navigation as navigation
    from cosim.gnss.gps_fast_check import if_series
    cfg, _ = scenario_config(scenario(45.0, 1.6))
    sig = ConstellationSignal(cfg)
    prn = int(sig.prns[0])
    t_m = np.arange(1, 11) / 10.0
    inside = {1: np.arange(10) < 5, 2: np.arange(10) >= 7}

    def fake_nav(a, *args, **kw):
        i, M = a.which, t_m.size
        return types.SimpleNamespace(
            g=np.arange(5), n_p=np.arange(5) * 10, fs_hz=1000.0, doppler=np.full(5, 100.0 * i),
            win_t=np.array([0.0]), win_ok=np.array([i == 1]),
            record_at=lambda N: (np.zeros(M, np.int64), np.full(M, 7.0), inside[i]),
            cn0_at=lambda N: np.full(M, 40.0 + i), carrier_cycles=lambda N: np.full(M, -i))
    monkeypatch.setattr(navigation, "channel_navigation", fake_nav)
    m = types.SimpleNamespace(assignments=[
        types.SimpleNamespace(prn=prn, which=1, doppler_offset_epochs=0.0),
        types.SimpleNamespace(prn=prn, which=2, doppler_offset_epochs=0.0)])
    f = types.SimpleNamespace(fs_hz=1000.0, if_hz=0.0)
    ser = if_series(m, None, f, sig, (prn,), t_m)
    nan = np.nan
    np.testing.assert_array_equal(ser["doppler_hz"][:, 0, 0], [100] * 5 + [nan] * 2 + [200] * 3)
    np.testing.assert_array_equal(ser["cn0_dbhz"][:, 0, 0], [41] * 5 + [nan] * 2 + [42] * 3)
    np.testing.assert_array_equal(ser["carrier_cycles"][:, 0, 0], [1] * 5 + [nan] * 2 + [2] * 3)
    np.testing.assert_array_equal(ser["locked"][:, 0, 0], [True] * 5 + [False] * 5)
    assert np.isfinite(ser["code_chips"][:, 0, 0]).tolist() == [True] * 5 + [False] * 2 + [True] * 3
