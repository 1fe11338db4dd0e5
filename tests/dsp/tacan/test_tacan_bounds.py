"""The bearing bounds of dsp.tacan.bounds: the Cramer-Rao bound and the bound of a threshold
detector's output (times and Rician peak amplitudes of the detections, noise peaks)."""
import math

import numpy as np
import pytest
from scipy import stats

from dsp.tacan.bounds import (USES, crb_deg, detected_fraction, detection_bound_deg,
                              information_per_pulse)

REL_0DB = 0.3080543714225879      # TacanSignalConfig(snr_db=0).matched_filter_rel_sigma()


@pytest.mark.parametrize("sigma,th", [(0.3, 4.0), (0.1, 2.0), (0.2, 6.5)])
def test_detection_probability_is_the_rician_tail(sigma, th):
    a = np.array([0.0, 0.3, 0.6, 1.0, 1.4])
    pd = information_per_pulse(a, sigma, th)["pd"]
    np.testing.assert_allclose(pd, stats.rice.sf(th * sigma, a / sigma, scale=sigma), atol=2e-5)


def test_without_threshold_and_noise_peaks_the_detector_keeps_all_the_information():
    """Every pulse detected with its amplitude: the bound is the Cramer-Rao bound (the
    Rician amplitude carries 1/sigma^2 about a when a >> sigma)."""
    for rel in (0.01, 0.03):
        ratio = detection_bound_deg(rel, 0.21, 0.21, 3600, 0.0) / crb_deg(rel, 0.21, 0.21, 3600)
        assert ratio == pytest.approx(1.0, abs=2e-3)


def test_rate_and_marks_add_up_to_the_whole():
    """The information of a marked Poisson process splits exactly into the count's and the
    marks' given the count. The marks' part is computed here on its own, from the density of
    a detection's amplitude (pulses and noise peaks mixed) by finite differences, so the
    analytic derivative of the Rician density in the module is checked too."""
    s, thn, r = 0.2, 3.5, 0.08
    th = thn * s
    y = np.linspace(th, 3.0, 60001)
    dy = y[1] - y[0]
    noise = stats.rayleigh.pdf(y, scale=s) / stats.rayleigh.sf(th, scale=s)

    def cond(a):     # density of a detection's amplitude, and the detection rate per pulse
        lam = stats.rice.pdf(y, a / s, scale=s) + r * noise
        tot = np.sum(lam) * dy
        return lam / tot, tot

    for a in (0.6, 1.0, 1.3):
        h = 1e-4
        (gp, _), (gm, _), (g0, _) = cond(a + h), cond(a - h), cond(a)
        dlog = (np.log(gp) - np.log(gm)) / (2 * h)
        pd = stats.rice.sf(th, a / s, scale=s)
        marks = (pd + r) * np.sum(g0 * dlog ** 2) * dy
        info = information_per_pulse([a], s, thn, r)
        assert info["marks"][0] == pytest.approx(marks, rel=2e-3)
        assert info["both"][0] == pytest.approx(info["rate"][0] + info["marks"][0], rel=1e-12)


def test_the_detector_bound_is_never_below_the_cramer_rao_bound_and_noise_peaks_cost():
    for snr in (-3.0, 0.0, 3.0, 10.0):
        rel = REL_0DB * 10 ** (-snr / 20)
        crb = crb_deg(rel, 0.21, 0.21, 3600)
        prev = 0.0
        for r in (0.0, 0.05, 0.5):
            b = {u: detection_bound_deg(rel, 0.21, 0.21, 3600, 4.0, r, use=u) for u in USES}
            assert b["both"] >= crb * (1 - 1e-3)
            assert b["both"] <= min(b["rate"], b["marks"])
            assert b["both"] > prev
            prev = b["both"]


def test_near_the_noise_floor_the_count_carries_more_than_the_amplitudes():
    """The figures the module docstring and the benchmark quote (0 dB, the censored floor's
    operating point: threshold 4.08 sigma, 0.058 noise peaks per pulse): an amplitude-fitting
    DSP cannot get within 2x of the Cramer-Rao bound; the count of detections can."""
    crb = crb_deg(REL_0DB, 0.21, 0.21, 3600)
    b = {u: detection_bound_deg(REL_0DB, 0.21, 0.21, 3600, 4.08, 0.058, use=u) / crb for u in USES}
    assert b["both"] == pytest.approx(1.66, abs=0.02)
    assert b["rate"] == pytest.approx(1.99, abs=0.03)
    assert b["marks"] == pytest.approx(2.98, abs=0.05)
    rel3 = REL_0DB * 10 ** (-3 / 20)
    crb3 = crb_deg(rel3, 0.21, 0.21, 3600)
    assert detection_bound_deg(rel3, 0.21, 0.21, 3600, 4.08, 0.058, use="marks") / crb3 > 1.5
    assert detected_fraction(REL_0DB, 0.21, 0.21, 4.08) == pytest.approx(0.285, abs=0.005)


@pytest.mark.parametrize("kw,match", [
    (dict(threshold_sigma=-1.0), "threshold_sigma"),
    (dict(rel_sigma=0.0), "rel_sigma must be > 0"),
    (dict(rel_sigma=math.nan), "rel_sigma"),
    (dict(mod_15=0.6, mod_135=0.5), "must be < 1"),
    (dict(false_peaks_per_pulse=-0.1), "false_peaks_per_pulse"),
    (dict(n_pulses=0), "n_pulses"),
    (dict(use="amplitude"), "use must be one of"),
])
def test_bad_arguments_are_refused_with_their_name(kw, match):
    args = dict(rel_sigma=0.3, mod_15=0.21, mod_135=0.21, n_pulses=3600, threshold_sigma=4.0)
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        detection_bound_deg(**args)
