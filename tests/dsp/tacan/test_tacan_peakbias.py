"""The peak-amplitude bias model (dsp.tacan.peakbias) and the filter's use of it."""
import dataclasses

import numpy as np
import pytest

from cosim.tacan.signal import TacanSignalConfig, pulse_observations
from dsp.tacan.kalman import EnvelopeKalman
from dsp.tacan.kalman_config import KalmanConfig, KalmanFixedConfig
from dsp.tacan.peakbias import PAIR_PEAK_BIAS, PeakBias
from dsp.tacan.receiver import ReceiverConfig


def test_bias_curve_knots_hold_and_extrapolation():
    pb = dataclasses.replace(PAIR_PEAK_BIAS, u_min=0.0)
    np.testing.assert_allclose(pb.bias(np.array(pb.u)), pb.beta)
    assert pb.bias(np.array([9.0]))[0] == pb.beta[-1]                # flat beyond the table
    g = np.array([0.1, 0.3]) + pb.bias(np.array([0.1, 0.3]))        # expected report below
    assert 0 <= g[0] < g[1] < pb.u[0] + pb.beta[0]                   # falls, stays >= 0
    held = PAIR_PEAK_BIAS.bias(np.array([0.2, 0.5, 0.7]))
    assert held[0] == held[1] == held[2] == pytest.approx(PAIR_PEAK_BIAS.bias(np.array([0.7]))[0])
    # the model's expected report rises with the pulse amplitude (a usable measurement)
    u = np.linspace(0.7, 6, 400)
    assert np.all(np.diff(u + PAIR_PEAK_BIAS.bias(u)) > 0)


@pytest.mark.parametrize("kw, msg", [
    (dict(u=(1.0,), beta=(0.1,)), "2 knots"),
    (dict(u=(1.0, 0.5), beta=(0.1, 0.2)), "ascending"),
    (dict(u=(0.5, 1.0), beta=(0.1, np.nan)), "finite"),
    (dict(u=(0.5, 1.0), beta=(0.1, 0.2), quantile=0.7), "quantile"),
    (dict(u=(0.5, 1.0), beta=(0.1, 0.2), entries=8), "entries"),
    (dict(u=(0.5, 1.0), beta=(0.1, 0.2), noise_report=2.0, noise_predicted=1.5), "noise rule"),
    (dict(u=(0.5, 1.0), beta=(0.1, 0.2), noise_report=-1.0), "noise rule"),
])
def test_bad_bias_model_is_refused(kw, msg):
    with pytest.raises(ValueError, match=msg):
        PeakBias(**kw)
    with pytest.raises(ValueError, match="peak_bias must be a PeakBias"):
        ReceiverConfig(peak_bias=(0.5, 0.1))


def test_threshold_is_the_lower_edge_of_the_reports_and_ignores_a_settling_start():
    rng = np.random.default_rng(5)
    T = 0.25
    reports = T + rng.exponential(0.05, 12000)           # nothing below the threshold
    reports[:1500] = 0.18 + rng.exponential(0.05, 1500)  # the floor still settling
    est = PAIR_PEAK_BIAS.threshold(reports)
    assert est == pytest.approx(T, rel=0.01)
    assert float(np.quantile(reports, PAIR_PEAK_BIAS.quantile)) < 0.2    # a plain quantile
    assert PAIR_PEAK_BIAS.threshold(reports[:100]) is None              # too few reports


def test_table_covers_the_span_in_power_of_two_steps():
    for T in (0.01, 0.3, 7.0):
        tab, k = PAIR_PEAK_BIAS.table(T)
        step = 2.0 ** -k
        assert tab.size == PAIR_PEAK_BIAS.entries
        assert PAIR_PEAK_BIAS.span * T <= tab.size * step < 2 * PAIR_PEAK_BIAS.span * T
        a = np.arange(tab.size) * step
        np.testing.assert_allclose(tab, PAIR_PEAK_BIAS.bias(a / T) * T)
    with pytest.raises(ValueError, match="threshold"):
        PAIR_PEAK_BIAS.table(0.0)


def _biased_reports(T, seed=3, sigma=0.02):
    """Pulse amplitudes of 90 deg (15 and 135 Hz modulation 0.21 each) reported as the
    model says: the expected report at each amplitude plus noise."""
    cfg = TacanSignalConfig(duration_s=2.0, snr_db=10, bearing_deg=90, seed=seed)
    t, _, truth = pulse_observations(cfg)
    u = truth[0] / T
    y = (u + PAIR_PEAK_BIAS.bias(u)) * T
    y = y + np.random.default_rng(seed).standard_normal(y.size) * sigma
    return np.diff(t, prepend=t[0]), y[None, :]


@pytest.mark.parametrize("kalman", [KalmanConfig(), KalmanFixedConfig()], ids=["float", "fixed"])
def test_filter_with_the_table_recovers_the_modulation_the_bias_compresses(kalman):
    """At a threshold of 0.9 x the pulse level the troughs' reports are lifted: the plain
    filter sees the modulation shallower; with the table it recovers both depths (0.21)."""
    T = 0.9
    dts, y = _biased_reports(T)
    depths = {}
    for use in (False, True):
        kf = EnvelopeKalman(kalman)
        if use:
            kf.set_peak_bias(*PAIR_PEAK_BIAS.table(T))
        kf.run(dts, y)
        _, _, m1, m2, dc = kf.phases()
        depths[use] = (float(m1[0] / dc[0]), float(m2[0] / dc[0]), float(dc[0]))
    assert abs(depths[True][0] - 0.21) < 0.01 and abs(depths[True][1] - 0.21) < 0.01
    assert abs(depths[True][2] - 1.0) < 0.02
    assert depths[False][0] < 0.19 and depths[False][1] < 0.19     # compressed without it


@pytest.mark.parametrize("kalman", [KalmanConfig(), KalmanFixedConfig()], ids=["float", "fixed"])
def test_noise_rule_skips_low_reports_only_where_the_signal_stands_clear(kalman):
    """Noise reports (1.0-1.1 T, 5 % of the reports) mixed into a strong signal (pulses at
    1.9-4.7 T, noise 0.33 T: those near the trough lie within the innovation gate): with the
    rule they are skipped (counted) and the fit is the clean one; without it they pull the
    fit down. Where the prediction is below the rule's level (a weak signal) nothing is
    skipped."""
    T = 0.3
    dts, y = _biased_reports(T, sigma=0.1)
    rng = np.random.default_rng(9)
    noisy = y.copy()
    hit = rng.random(y.shape[1]) < 0.05
    noisy[0, hit] = T * rng.uniform(1.0, 1.1, hit.sum())
    out = {}
    pb = dataclasses.replace(PAIR_PEAK_BIAS, noise_report=1.15, noise_predicted=1.8)
    assert PAIR_PEAK_BIAS.noise_rule(T) is None           # the shipped profile has none
    for rule in (None, pb.noise_rule(T)):
        kf = EnvelopeKalman(kalman)
        kf.set_peak_bias(*PAIR_PEAK_BIAS.table(T), noise=rule)
        kf.run(dts, noisy)
        out[rule is None] = (kf.phases()[4][0], int(kf.events["noise_reports"][0]),
                             int(kf.events["gated"][0]))
    clean_dc, skipped, gated = out[False]
    assert abs(clean_dc - 1.0) < 0.002 and skipped >= 0.9 * hit.sum() and gated == 0
    dc, skipped, gated = out[True]                                  # without the rule:
    assert skipped == 0 and dc < 0.997 and gated > 100              # pulled down, gated
    weak = EnvelopeKalman(kalman)                      # threshold ~ the signal
    weak.set_peak_bias(*pb.table(0.9), noise=pb.noise_rule(0.9))
    weak.run(dts, noisy)
    assert int(weak.events["noise_reports"][0]) == 0


def test_set_peak_bias_refuses_garbage():
    kf = EnvelopeKalman(KalmanFixedConfig())
    with pytest.raises(ValueError, match="finite"):
        kf.set_peak_bias([0.1, np.inf], 4)
    with pytest.raises(ValueError, match="65536"):
        kf.set_peak_bias(np.zeros(70000), 4)
    with pytest.raises(ValueError, match="does not suit"):
        kf.set_peak_bias([0.1, 0.2], -80)
    with pytest.raises(ValueError, match="noise rule"):
        kf.set_peak_bias([0.1, 0.2], 4, noise=(0.1, -1.0))
    kf.set_peak_bias([], 0)                       # empty: no table
    assert kf._bt.size == 0
