"""The detector's operating point measured on the golden chain (cosim.tacan.detector), against
the Rician model the bounds of dsp.tacan.bounds use."""
from dataclasses import replace

import numpy as np
import pytest

from cosim.tacan.detector import detector_bounds, operating_point
from cosim.tacan.config import TacanRunConfig
from cosim.tacan.signal import TacanSignalConfig, generate
from dsp.tacan.receiver import bearing_stats


def _op(snr_db, floor="censored"):
    sig = TacanSignalConfig(bearing_deg=90.0, duration_s=1.0, seed=100, snr_db=snr_db)
    return operating_point(TacanRunConfig(signal=sig, noise_floor=floor, settle_s=0.5,
                                          detector="pulse"))


def test_operating_point_matches_the_model_the_bounds_use():
    """10 dB: nearly every pulse detected, as the model says; 0 dB: the model's fraction
    within 15 % (the FPGA's peak picking, the largest of a few noisy envelope samples,
    detects a few more than the Rician peak of the ideal matched filter: 0.32 against
    0.29). The censored floor puts the threshold at 3.44x the noise envelope's mean,
    4.07 sigma, whatever the signal; noise peaks come at ~420/s (0.06 per pulse)."""
    hi, lo = _op(10.0), _op(0.0)
    assert hi["detected_fraction"] == pytest.approx(hi["model_detected_fraction"], abs=0.01)
    assert lo["detected_fraction"] == pytest.approx(lo["model_detected_fraction"], rel=0.15)
    for op in (hi, lo):
        assert op["threshold_sigma"] == pytest.approx(4.07, abs=0.05)
        assert 0.03 < op["false_peaks_per_pulse"] < 0.1
    b = detector_bounds(lo, 0.21, 0.21, 3600)
    assert b["crb_deg"] < b["bound_both_deg"] < b["bound_rate_deg"] < b["bound_marks_deg"]


def test_operating_point_needs_noise():
    sig = TacanSignalConfig(duration_s=2.0, snr_db=None)
    with pytest.raises(ValueError, match="noisy scenario"):
        operating_point(TacanRunConfig(signal=sig))


def _bins(u, e, edges):
    k = np.digitize(u, edges) - 1
    return np.array([e[k == q].mean() for q in range(edges.size - 1)])


def _curve(detector):
    from dsp.tacan.peakbias import BOTH_PEAK_BIAS, PAIR_PEAK_BIAS
    return {"pair": PAIR_PEAK_BIAS, "both": BOTH_PEAK_BIAS}[detector]


@pytest.mark.parametrize("detector", ["pair", "both"])
def test_pair_peak_bias_model_matches_a_record_it_was_not_calibrated_on(detector):
    """The committed bias curve of the pair search (alone, 46/16; beside the single-pulse
    one, 40/16) against one fresh record (1 dB, seed 77, not among the calibration seeds):
    the mean bias per 0.1-wide bin of u within 0.03 thresholds of the curve where it
    matters (0.75-1.45)."""
    from cosim.tacan.detector import peak_bias_samples
    run = TacanRunConfig(signal=TacanSignalConfig(bearing_deg=123.0, snr_db=1.0,
                                                  duration_s=2.0, seed=77), detector=detector)
    u, e = peak_bias_samples(run)
    edges = np.arange(0.75, 1.46, 0.1)
    got = _bins(u, e, edges)
    want = _curve(detector).bias((edges[:-1] + edges[1:]) / 2)
    assert np.all(np.abs(got - want) < 0.03), (got, want)
    assert got[0] > 0.25 and got[-1] < 0.1        # the bias the model corrects is there


@pytest.mark.slow
@pytest.mark.parametrize("detector", ["pair", "both"])
def test_pair_peak_bias_calibration_reproduces_the_committed_curve(detector):
    """`calibrate_peak_bias(bias_runs(detector, seeds=[0]))`: a third of the calibration
    records gives the committed knots within 0.02 thresholds from u = 0.65 up."""
    from cosim.tacan.detector import calibrate_peak_bias, bias_runs
    u, beta = calibrate_peak_bias(bias_runs(detector, seeds=[0]))
    import dataclasses
    m = u >= 0.65
    want = dataclasses.replace(_curve(detector), u_min=0.0).bias(u[m])   # the knots as such
    assert np.all(np.abs(beta[m] - want) < 0.02), (u[m], beta[m], want)


def test_pair_detector_runs_with_its_bias_model():
    from dsp.tacan.peakbias import PAIR_PEAK_BIAS
    assert TacanRunConfig(detector="pair").receiver.peak_bias is PAIR_PEAK_BIAS
    assert TacanRunConfig(detector="pulse").receiver.peak_bias is None


def test_both_searches_run_config():
    """--detector both: the single-pulse search of --noise-floor plus the pair search in the
    front end, the DSP decoding on the pulses and measuring on the pairs with their bias
    model; partner amplitudes cannot go with it."""
    from dsp.tacan.peakbias import BOTH_PEAK_BIAS, PAIR_PEAK_BIAS
    from dsp.tacan.frontend import NOISE_FLOORS
    run = TacanRunConfig(detector="both", noise_floor="censored")
    fe = run.frontend
    assert fe.peak == replace(NOISE_FLOORS["censored"], ts_step=fe.peak.ts_step)
    alone = TacanRunConfig(detector="pair").frontend.peak
    assert fe.pair_peak == replace(alone, thr_mult=40) and alone.thr_mult == 46
    rc = run.receiver
    assert rc.peak_bias is BOTH_PEAK_BIAS and not rc.pair_reports
    assert BOTH_PEAK_BIAS.noise_rule(1.0) == (1.15, 1.8) and PAIR_PEAK_BIAS.noise_rule(1.0) is None
    assert TacanRunConfig().frontend.pair_peak == fe.pair_peak          # the default: both
    assert TacanRunConfig().detector == "both"
    assert TacanRunConfig(detector="pulse").frontend.pair_peak is None
    with pytest.raises(ValueError, match=r"option of the single-pulse search alone \(add "
                                         r"--detector pulse\)"):
        TacanRunConfig(amplitude="partner")
    assert TacanRunConfig(detector="pulse", amplitude="partner").frontend.pair_peak is None


@pytest.mark.slow   # 18 s; bench tacan-sensitivity measures it on 16 records
@pytest.mark.xfail(strict=True, reason=(
    "issue 41: with one measurement per pair (pair_centres) this record's RMSE is 0.4436 deg, "
    "2.03x the bound, against < 2x (0.41 deg before); a bearing, no slip, nothing misleading "
    "still hold; the 0 dB accuracy is judged pooled by bench tacan-accuracy (full grid: 1.6x)"))
def test_both_searches_golden_chain_gives_a_bearing_at_0_db_90_deg():
    """Seed 102 at 0 dB, 90 deg (main burst in the envelope's trough): the pair detector
    alone acquires no reference in 3 s; with both searches the references come from the
    single pulses and the bearing from the pairs, without a sector slip, within 2x the
    bound (0.219 deg; RMSE 0.41 deg; the pulse detector alone: 1.0 deg)."""
    from cosim.tacan.frontends import golden_frontend
    from cosim.tacan.run import run_dsp
    sig = TacanSignalConfig(bearing_deg=90.0, snr_db=0.0, duration_s=3.0, seed=102)
    s = generate(sig)
    out = {}
    for det in ("pair", "both"):
        run = TacanRunConfig(signal=sig, detector=det, require_bearing=False)
        tr = run_dsp(golden_frontend(s.samples, run), run)
        out[det] = (tr, bearing_stats(tr, 90.0, 1.0))
    assert out["pair"][1]["n_valid"][0] == 0
    tr, st = out["both"]
    assert tr.first_valid_s()[0] < 1.5 and st["n_valid"][0] > 200
    assert st["misleading"][0] == 0 and st["rmse_deg"][0] < 2 * 0.219


@pytest.mark.slow
def test_pair_reports_that_are_no_pairs_and_the_confirmation_that_drops_them():
    """Issue 41's evidence (6 dB, 1 s, X mode): one pair report in seven or eight is no pair
    (half pairs at ~0.78 of the pulse, noise pairs at ~1.06 thresholds); the confirmation by
    the single pulses keeps ~90 % of the pairs and almost none of the others (measured:
    pairs 84.7 %, confirmed 90.2 %; half pairs 7.2 %, 3.4 %; noise pairs 8.1 %, 0.3 %)."""
    from cosim.tacan.detector import pair_report_kinds
    r = pair_report_kinds(TacanRunConfig(signal=TacanSignalConfig(
        mode="X", snr_db=6.0, bearing_deg=60.0, duration_s=1.0, seed=1), require_bearing=False))
    assert 0.05 < r["half_pair"]["share"] < 0.12 and 0.05 < r["noise_pair"]["share"] < 0.12
    assert 0.7 < r["half_pair"]["report_over_pulse"] < 0.85
    assert r["noise_pair"]["report_over_threshold"] < 1.15
    assert r["pair"]["confirmed"] > 0.85
    assert r["half_pair"]["confirmed"] < 0.06 and r["noise_pair"]["confirmed"] < 0.01
    assert 0.7 < r["paired_fraction"] < 0.85
    with pytest.raises(ValueError, match="need both searches"):
        pair_report_kinds(TacanRunConfig(detector="pulse"))


@pytest.mark.slow
def test_confirmed_pair_reports_carry_their_own_bias():
    """With both searches the DSP measures on the confirmed pair reports from a paired
    fraction of 0.45 up (~3 dB); near the threshold they lie higher over their pulse than
    the average pair report (the single-pulse search reported both pulses only when the
    noise lifted them), and ``BOTH_PEAK_BIAS.confirmed`` is their curve: on a fresh record
    (1 dB, seed 77) the 0.1-wide bins of u from 0.75 to 1.45 within 0.02 thresholds of it on
    average and each within 0.06 (measured -0.056 to +0.002, mean -0.018; the bins of one
    record scatter by ~0.03 from record to record: -3 / -1 dB seeds the curve was not
    fitted on), and each at least 0.09 thresholds above the curve of every pair report."""
    from cosim.tacan.detector import peak_bias_samples
    from dsp.tacan.peakbias import BOTH_PEAK_BIAS
    run = TacanRunConfig(signal=TacanSignalConfig(bearing_deg=123.0, snr_db=1.0,
                                                  duration_s=2.0, seed=77), detector="both")
    u, e = peak_bias_samples(run, confirmed=True)
    edges = np.arange(0.75, 1.46, 0.1)
    got = _bins(u, e, edges)
    mid = (edges[:-1] + edges[1:]) / 2
    dev = got - BOTH_PEAK_BIAS.confirmed.bias(mid)
    assert abs(dev.mean()) < 0.02 and np.all(np.abs(dev) < 0.06), dev
    assert np.all(got - BOTH_PEAK_BIAS.bias(mid) > 0.09), got
    with pytest.raises(ValueError, match="both searches"):
        peak_bias_samples(TacanRunConfig(signal=run.signal, detector="pair"), confirmed=True)
