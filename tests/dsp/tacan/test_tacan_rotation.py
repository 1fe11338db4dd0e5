"""Rotation-rate tracking (issue 18): a beacon whose antenna turns off 15 Hz.

The rate is the 135 Hz reference grid's period (:func:`dsp.tacan.rotation.estimate_rotation`),
tracked causally (:func:`dsp.tacan.rotation.rotation_track`) and used by the Kalman model and
the bearing's phase advances; rounded to 1e-5 so that a nominal beacon runs the nominal
bits."""
import math

import numpy as np
import pytest

from cosim.tacan.signal import TacanSignalConfig, pulse_observations
from dsp.tacan.bearing import wrap_deg
from dsp.tacan.rotation import (RATE_QUANTUM, estimate_rotation, quantize_rotation,
                              rotation_track)
from dsp.tacan.kalman import EnvelopeKalman
from dsp.tacan.kalman_config import KalmanConfig, KalmanFixedConfig
from dsp.tacan.receiver import ReceiverConfig, bearing_stats, process_peaks
from dsp.tacan.standard import F15


def _grid(rate_hz, n, jitter_s=0.0, seed=0, t0=5e-3):
    rng = np.random.default_rng(seed)
    return t0 + np.arange(n) / (9 * rate_hz) + rng.normal(0, jitter_s, n)


def test_quantize_rotation_is_exact_at_nominal_and_clipped():
    assert quantize_rotation(15.0) == F15 and quantize_rotation(15.0 * (1 + 4e-6)) == F15
    assert quantize_rotation(15.0 * (1 - 4e-6)) == F15
    assert quantize_rotation(15.15) == pytest.approx(15.15, abs=0.5 * RATE_QUANTUM * F15)
    assert quantize_rotation(20.0) == pytest.approx(15.75)
    assert quantize_rotation(10.0) == pytest.approx(14.25)


@pytest.mark.parametrize("rate", [15.0, 15.075, 14.925, 15.15, 14.85, 15.6])
def test_estimate_rotation_from_the_reference_grid(rate):
    """Gap-by-gap grid indices: 5 % off and 3 s of references (400 periods) still fit;
    100 ns timing jitter and lost references (every third) leave the estimate within one
    quantum, exactly 15 Hz on a nominal beacon."""
    t = _grid(rate, 405, jitter_s=100e-9, seed=int(rate * 1000))
    t = np.delete(t, np.arange(0, t.size, 3))
    f = estimate_rotation(t, 1e-6, 8)
    assert f == pytest.approx(rate, abs=RATE_QUANTUM * F15)
    if rate == 15.0:
        assert f == F15
    # a misaligned burst (one code step, 12 us) and a false one do not pull it
    t2 = np.sort(np.concatenate([t[:50], [t[50] + 12e-6], t[51:], [t[10] + 2.1e-3]]))
    assert estimate_rotation(t2, 1e-6, 8) == f


def test_estimate_rotation_needs_enough_references():
    t = _grid(15.15, 7)
    assert estimate_rotation(t, 1e-6, 8) is None                      # 7 < min_refs
    assert estimate_rotation(_grid(15.15, 9), 1e-6, 8, min_span_s=0.1) is None  # 0.053 s
    rng = np.random.default_rng(3)
    assert estimate_rotation(np.sort(rng.uniform(0, 2, 60)), 1e-6, 8) is None  # no grid


def test_rotation_track_is_causal_and_confirms_after_min_refs():
    t = _grid(15.15, 60, jitter_s=50e-9)
    f, conf = rotation_track(t, 1e-6, 8, 0.05)
    assert not conf[:7].any() and np.all(f[:7] == F15)              # nothing known yet
    first = int(np.argmax(conf))
    assert t[first] - t[0] >= 0.05 and conf[first:].all()
    assert np.all(np.abs(f[first:] - 15.15) <= RATE_QUANTUM * F15)
    # later references do not change earlier estimates
    t_alt = t.copy()
    t_alt[40:] += 3e-6
    f_alt, conf_alt = rotation_track(t_alt, 1e-6, 8, 0.05)
    assert np.array_equal(f_alt[:40], f[:40]) and np.array_equal(conf_alt[:40], conf[:40])
    # a prior estimate (an earlier block) is held until the first estimate of this one
    f_p, conf_p = rotation_track(t[:5], 1e-6, 8, 0.05, prior_rate=15.1)
    assert conf_p.all() and np.all(f_p == 15.1)


def test_set_rotation_nominal_is_the_nominal_core_and_bad_rates_are_refused():
    for cfg in (KalmanConfig(), KalmanFixedConfig()):
        kf = EnvelopeKalman(cfg)
        cv = kf._cv.copy()
        kf.set_rotation(15.15)
        assert kf.rotation_hz == 15.15 and not np.array_equal(kf._cv[:2], cv[:2])
        kf.set_rotation(F15)
        assert np.array_equal(kf._cv, cv, equal_nan=True) and kf.rotation_hz == F15
        with pytest.raises(ValueError, match="rotation rate must be within 10 % of 15 Hz"):
            kf.set_rotation(17.0)
        with pytest.raises(ValueError, match="rotation rate must be within 10 % of 15 Hz"):
            kf.set_rotation(math.nan)


def test_receiver_config_and_signal_refuse_bad_rotation_settings():
    with pytest.raises(ValueError, match="track_rotation must be True or False"):
        ReceiverConfig(track_rotation=1)
    with pytest.raises(ValueError, match=r"rotation_span_s must be in \(0, 10\] s"):
        ReceiverConfig(rotation_span_s=0)
    with pytest.raises(ValueError, match=r"rotation_hz must be within 5 % of 15 Hz \(14.25..15.75\)"):
        TacanSignalConfig(rotation_hz=16.0)


BEARINGS = np.arange(0.0, 360.0, 30.0)


def _run(rate_hz, dsp, track=True, seed=1, snr=10.0):
    cfg = TacanSignalConfig(snr_db=snr, duration_s=3.0, seed=seed, rotation_hz=rate_hz)
    t, amps, _ = pulse_observations(cfg, BEARINGS)
    ticks = np.round(t * 20e6).astype(np.int64)
    kc = KalmanConfig() if dsp == "float" else KalmanFixedConfig()
    tr = process_peaks(ticks / 20e6, amps, ReceiverConfig(kalman=kc, track_rotation=track),
                       ticks=ticks)
    return tr, bearing_stats(tr, BEARINGS, 1.0)


@pytest.mark.parametrize("dsp", ["float", "fixed"])
def test_nominal_beacon_gives_the_same_bits_with_and_without_tracking(dsp):
    a, _ = _run(15.0, dsp, track=True)
    b, _ = _run(15.0, dsp, track=False)
    assert np.array_equal(a.bearing_deg, b.bearing_deg) and np.array_equal(a.times_s, b.times_s)
    assert a.state.rotation_hz == F15


@pytest.mark.parametrize("dsp", ["float", "fixed"])
@pytest.mark.parametrize("off", [0.005, -0.01])
def test_off_rate_beacon_is_tracked_without_bias(dsp, off):
    """Pulse level, 10 dB, 12 bearings: 15 Hz assumed gives 5.5-7.8 deg of bias; tracked,
    the bias (mean over the bearings) stays below 0.03 deg and the RMSE within 10 % of the
    nominal beacon's, and no bearing is flagged after the filter settles."""
    rate = F15 * (1 + off)
    tr, st = _run(rate, dsp)
    _, st_nom = _run(15.0, dsp)
    _, st_off = _run(rate, dsp, track=False)
    assert abs(np.mean(st_off["mean_error_deg"])) > 5.0
    assert abs(np.mean(st["mean_error_deg"])) < 0.03
    rmse = np.sqrt(np.mean(st["rmse_deg"] ** 2))
    assert rmse < 1.1 * np.sqrt(np.mean(st_nom["rmse_deg"] ** 2))
    assert abs(tr.state.rotation_hz - rate) <= RATE_QUANTUM * F15
    assert tr.valid[:, tr.times_s > 1.0].all()


def test_first_valid_bearing_waits_for_the_reference_timing():
    tr, _ = _run(15.15, "float")
    assert np.all(tr.produced_s >= tr.times_s)
    first = tr.first_valid_s()
    assert np.all(np.isfinite(first))
    i = int(np.flatnonzero(tr.valid[0])[0])
    assert first[0] == tr.produced_s[i]
    # confirmed after min_grid_refs (8) references spanning rotation_span_s (0.05 s)
    assert first[0] >= 5e-3 + 7 / (9 * 15.15)
    assert first[0] < 0.1
    wrap = np.abs(wrap_deg(tr.bearing_deg[:, tr.times_s > 1.0] - BEARINGS[:, None]))
    assert wrap.max() < 0.5


def test_rotation_track_gives_a_kept_result_as_copies_equal_to_computing_it():
    """``rotation_track`` keeps its last results by their exact inputs (the detector
    variants of one record track the same references): the same arrays as
    ``compute_rotation_track``, copies a caller may change, and another input (one
    reference moved by 1 ns, another parameter) computed afresh."""
    from dsp.tacan.rotation import compute_rotation_track
    t = _grid(15.05, 80, jitter_s=50e-9)
    f, conf = rotation_track(t, 1e-6, 8, 0.05)
    g, cg = compute_rotation_track(t, 1e-6, 8, 0.05)
    assert np.array_equal(f, g) and np.array_equal(conf, cg)
    f[:] = 0.0
    conf[:] = False
    f2, c2 = rotation_track(t, 1e-6, 8, 0.05)
    assert np.array_equal(f2, g) and np.array_equal(c2, cg)
    u = t.copy()
    u[10] += 1e-9
    assert np.array_equal(rotation_track(u, 1e-6, 8, 0.05)[0],
                          compute_rotation_track(u, 1e-6, 8, 0.05)[0])
    assert np.array_equal(rotation_track(t, 1e-6, 8, 0.05, prior_rate=15.1)[0],
                          compute_rotation_track(t, 1e-6, 8, 0.05, prior_rate=15.1)[0])
