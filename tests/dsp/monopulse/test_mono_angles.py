"""Angle equations (C1), the two phase formulations, and the angle Cramer-Rao bound."""
import itertools

import numpy as np
import pytest

from cosim.monopulse import fastpath
from cosim.monopulse.array import ArrayConfig
from cosim.monopulse.signal import MonopulseSignalConfig, generate
from cosim.monopulse.trajectory import ConstantRate
from dsp.monopulse import angles, golden

STEERINGS = [(0.3, 0.2), (0.5, -0.4), (0.2, 0.6), (0.6, 0.0)]
OFFSETS = [0.0] + [s * x for x in (1e-6, 0.01, 0.05, 0.1, 0.12, 0.124, 0.1249) for s in (1, -1)]


def _fast_noise_free(u0, v0, du, dv, array=ArrayConfig(phase_bits=6), snapshots=1):
    cfg = MonopulseSignalConfig(array=array, snapshots=snapshots, snr_db=None, adc_bits=None,
                                trajectory=ConstantRate(u0 + du, v0 + dv))
    return fastpath.matched_filter_outputs(cfg, (u0, v0), trials=1)[0, 0], cfg


def test_c1_noise_free_fast_path_recovers_az_el_to_1e_9_rad():
    worst = 0.0
    for (u0, v0), du, dv in itertools.product(STEERINGS, OFFSETS, OFFSETS):
        s, cfg = _fast_noise_free(u0, v0, du, dv)
        u, v, az, el = angles.measure(s, u0, v0, 4.0, 4.0)
        az_t = np.arctan2(v0 + dv, u0 + du)
        el_t = np.arcsin(np.hypot(u0 + du, v0 + dv))
        worst = max(worst, abs(az - az_t), abs(el - el_t))
        assert abs(az - az_t) < 1e-9 and abs(el - el_t) < 1e-9, (u0, v0, du, dv)
    print(f"C1 fast path: worst |error| over {len(STEERINGS) * len(OFFSETS) ** 2} cases: "
          f"{worst:.2e} rad")


def test_c1_fails_outside_the_unambiguous_region():
    s, _ = _fast_noise_free(0.3, 0.2, 0.13, 0.0)
    u, v, az, el = angles.measure(s, 0.3, 0.2, 4.0, 4.0)
    assert u == pytest.approx(0.3 + 0.13 - 0.25, abs=1e-9)  # wrapped by 1 / D


def test_c1_noise_free_if_record():
    """A short IF record (16 snapshots of 10 samples, no noise, no ADC): the integrate-and-dump
    DDC nulls the 2 IF image exactly, so only rounding remains; tolerance 1e-9 rad."""
    worst = 0.0
    offs = [0.0, 0.05, -0.05, 0.124, -0.124]
    for (u0, v0), du, dv in itertools.product(STEERINGS[:2], offs, offs):
        cfg = MonopulseSignalConfig(array=ArrayConfig(phase_bits=6), snapshots=16, snr_db=None,
                                    adc_bits=None, trajectory=ConstantRate(u0 + du, v0 + dv))
        rec = generate(cfg, (u0, v0), 0, 1)
        s = golden.golden_chain(rec.samples, rec.scale, rec.replica,
                                cfg.array.steering_correction(u0, v0), cfg.if_hz, cfg.fs_hz,
                                cfg.decimation)[0]
        _, _, az, el = angles.measure(s, u0, v0, 4.0, 4.0)
        err = max(abs(az - rec.az[0]), abs(el - rec.el[0]))
        worst = max(worst, err)
        assert err < 1e-9, (u0, v0, du, dv)
    print(f"C1 IF path: worst |error| {worst:.2e} rad")


def test_ratios_are_minus_j_tan_and_both_phase_forms_agree():
    u0, v0, du, dv = 0.3, 0.2, 0.07, -0.11
    s, _ = _fast_noise_free(u0, v0, du, dv,
                            array=ArrayConfig(phase_bits=3))
    ss, da, de = golden.beams(s)
    d2, d3 = 2 * np.pi * 4 * (-dv), 2 * np.pi * 4 * (-du)
    assert de / ss == pytest.approx(-1j * np.tan(d2 / 2), abs=1e-12)
    assert da / ss == pytest.approx(-1j * np.tan(d3 / 2), abs=1e-12)
    assert angles.phase_im(ss, de) == pytest.approx(d2, abs=1e-12)
    assert angles.phase_arg(ss, de) == pytest.approx(d2, abs=1e-12)
    assert angles.phase_arg(ss, da) == pytest.approx(angles.phase_im(ss, da), abs=1e-12)
    with pytest.raises(ValueError, match="method must be 'im' or 'arg', not 'x'"):
        angles.direction_cosines(s, u0, v0, 4.0, 4.0, method="x")


def test_angles_outside_the_visible_region_are_nan():
    az, el = angles.angles(np.array([0.8, 0.3]), np.array([0.7, 0.0]))
    assert np.isnan(el[0]) and el[1] == pytest.approx(np.arcsin(0.3))


def test_crb_equals_the_numerical_fisher_information():
    """Independent form: the FIM of (u, v, Re alpha, Im alpha) for the 4-channel model,
    J = (2 / sigma^2) N Re(D^H D), inverted; the (u, v) block against the closed form."""
    dx, dy, snr, n = 4.0, 3.0, 10 ** (-0.8), 8192
    P = np.array([[0, 0], [0, dy], [dx, 0], [dx, dy]], float)
    u, v, alpha = 0.31, 0.17, 0.7 * np.exp(0.4j)
    a = np.exp(-2j * np.pi * (P @ [u, v]))
    D = np.stack([-2j * np.pi * P[:, 0] * alpha * a, -2j * np.pi * P[:, 1] * alpha * a,
                  a, 1j * a], axis=1)
    sigma2 = abs(alpha) ** 2 / snr
    crb = np.linalg.inv(2 * n / sigma2 * np.real(D.conj().T @ D))
    vu, vv = angles.crb_uv(snr, n, dx, dy)
    assert crb[0, 0] == pytest.approx(vu, rel=1e-9)
    assert crb[1, 1] == pytest.approx(vv, rel=1e-9)
    assert abs(crb[0, 1]) < 1e-9 * vu


def _paper_scenario_mc(du, dv, trials=20000):
    u0, v0 = 0.3, 0.2
    arr = ArrayConfig(phase_bits=None)
    cfg = MonopulseSignalConfig(array=arr, snapshots=8192, snr_db=-8.0, adc_bits=None,
                                trajectory=ConstantRate(u0 + du, v0 + dv), seed=3)
    s = fastpath.matched_filter_outputs(cfg, (u0, v0), trials=trials)[:, 0]
    u, v, az, el = angles.measure(s, u0, v0, 4.0, 4.0)
    af = abs(arr.subarray_pattern(np.array(u0 + du), np.array(v0 + dv), u0, v0))
    snr = cfg.snr_linear * af ** 2
    return (u0 + du, v0 + dv), (u, v, az, el), snr


@pytest.mark.parametrize("du, dv", [(0.0005, -0.0003), (0.03, -0.02), (-0.06, 0.08)])
def test_monopulse_variance_at_the_paper_scenario(du, dv):
    """-8 dB, N = 8192 (31 dB after the matched filter), ideal shifters, fast path over 20000
    trials (1 sigma of a variance: 1 %): var(u), var(v), var(az), var(el) and the u-v
    correlation as the estimator's first-order covariance (``monopulse_covariance_uv``),
    which is the CRB on boresight and above it off boresight. The CRB takes the SNR the channel sees,
    snr |AF|^2."""
    (u, v), est, snr = _paper_scenario_mc(du, dv)
    vu, vv, cuv = angles.monopulse_covariance_uv(snr, 8192, 4.0, 4.0, du, dv)
    vaz, vel = angles.angle_variances(u, v, vu, vv, cuv)
    cu, cv = angles.crb_uv(snr, 8192, 4.0, 4.0)
    caz, cel = angles.crb_angles(u, v, snr, 8192, 4.0, 4.0)
    pred = np.array([vu, vv, vaz, vel])
    got = np.array([np.var(x) for x in est])
    print(f"offset ({du}, {dv}): var / predicted (u, v, az, el):", np.round(got / pred, 4),
          " var / CRB:", np.round(got / np.array([cu, cv, caz, cel]), 4),
          " CRB az, el (mrad):", np.round(1e3 * np.sqrt([caz, cel]), 4))
    assert np.all(np.abs(got / pred - 1) < 0.05)
    corr = np.corrcoef(est[0], est[1])[0, 1]
    assert corr == pytest.approx(cuv / np.sqrt(vu * vv), abs=0.05)  # 1 sigma 0.007
    assert abs(np.mean(est[0]) - u) < 5 * np.sqrt(vu / 20000)
    assert abs(np.mean(est[1]) - v) < 5 * np.sqrt(vv / 20000)
