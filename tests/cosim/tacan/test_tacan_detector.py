"""The detector's operating point measured on the golden chain (cosim.tacan.detector), against
the Rician model the bounds of dsp.tacan.bounds use."""
import pytest

from cosim.tacan.detector import detector_bounds, operating_point
from cosim.tacan.run import TacanRunConfig
from cosim.tacan.signal import TacanSignalConfig


def _op(snr_db, floor="censored"):
    sig = TacanSignalConfig(bearing_deg=90.0, duration_s=1.0, seed=100, snr_db=snr_db)
    return operating_point(TacanRunConfig(signal=sig, noise_floor=floor, settle_s=0.5))


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
