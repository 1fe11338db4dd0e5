"""The issue's must-show figures on the full IF chain (signal -> golden front end -> DSP)."""
import numpy as np
import pytest

from cosim.tacan.config import TacanRunConfig
from cosim.tacan.run import run_tacan
from cosim.tacan.signal import TacanSignalConfig, generate
from dsp.tacan.frontend import FrontendConfig, run_golden_frontend


def test_default_scenario_accuracy():
    """SNR 10 dB, bearing 90 deg (references in the trough), X mode, 3 s: after the filter
    settles RMSE <= 0.25 deg, |mean error| <= 0.05 deg, RMSE within 2x the Cramer-Rao bound.
    Three seeds, so the figures are not one lucky draw."""
    rs = [run_tacan(TacanRunConfig(signal=TacanSignalConfig(bearing_deg=90.0, snr_db=10.0,
                                                            duration_s=3.0, seed=s)))
          for s in (1, 2, 3)]
    rmse = float(np.sqrt(np.mean([r["rmse_deg"] ** 2 for r in rs])))
    mean = float(np.mean([r["mean_error_deg"] for r in rs]))
    assert rmse <= 0.25
    assert abs(mean) <= 0.05
    assert rmse <= 2.0 * rs[0]["crb_deg"]
    assert all(r["reinit"] == 0 for r in rs)


def test_y_mode_end_to_end():
    r = run_tacan(TacanRunConfig(signal=TacanSignalConfig(mode="Y", bearing_deg=200.0,
                                                          snr_db=12.0, duration_s=2.0, seed=4)))
    assert r["rmse_deg"] <= 0.25 and r["n_main_refs"] == 30


def test_golden_peaks_match_truth_without_noise():
    cfg = TacanSignalConfig(snr_db=None, duration_s=0.3, bearing_deg=33.0)
    s = generate(cfg)
    fe = FrontendConfig.for_signal(cfg)
    p = run_golden_frontend(s.samples, fe, cfg.adc_bits)
    t = p.times_s - fe.group_delay_samples / cfg.fs_hz
    tr = s.truth
    # Pulses after the first noise-floor block are all found, at the right time and amplitude.
    first = fe.peak.block_len * fe.decimation / cfg.fs_hz
    want = tr.pulse_times_s > first + 20e-6
    j = np.clip(np.searchsorted(t, tr.pulse_times_s[want]), 1, t.size - 1)
    near = np.where(np.abs(t[j] - tr.pulse_times_s[want]) < np.abs(t[j - 1] - tr.pulse_times_s[want]), j, j - 1)
    dt = t[near] - tr.pulse_times_s[want]
    assert np.max(np.abs(dt)) <= 0.5 / fe.env_rate_hz + 1e-9    # within half an envelope sample
    rel = p.amplitudes[near] / tr.pulse_amplitudes[want] - 1
    assert np.max(np.abs(rel)) < 0.01                            # ADC + sampling phase only
    # ... and nothing else: no false or split peaks.
    assert np.count_nonzero(t > first + 20e-6) == want.sum()


def test_frontend_result_does_not_depend_on_chunking():
    cfg = TacanSignalConfig(duration_s=0.12, seed=3)
    s = generate(cfg)
    fe = FrontendConfig.for_signal(cfg)
    from dsp.tacan.frontend import GoldenFrontend
    a = run_golden_frontend(s.samples, fe, cfg.adc_bits)
    g = GoldenFrontend(fe, cfg.adc_bits)
    parts = [g.process(s.samples[i:i + 40000]) for i in range(0, s.samples.size, 40000)]
    np.testing.assert_array_equal(a.timestamps, np.concatenate([q.timestamps for q in parts]))
    np.testing.assert_allclose(a.amplitudes, np.concatenate([q.amplitudes for q in parts]), rtol=1e-12)


def test_frontend_bad_config():
    with pytest.raises(ValueError, match=r"CIC decimation must be an integer >= 2, not 1"):
        FrontendConfig(cic_rate=1)
    with pytest.raises(ValueError, match=r"FIR numtaps must be an odd integer >= 3, not 32"):
        FrontendConfig(fir_numtaps=32)


@pytest.mark.slow
def test_off_rate_beacon_on_the_hdl_model_and_fixed_dsp():
    """Issue 18: a beacon turning 1 % fast, through the bit-exact front-end model and the
    fixed-point DSP (the FPGA side is unchanged): the rate is estimated to its 1e-5 step
    and the bearing stays unbiased (15 Hz assumed: ~7.9 deg); a first valid bearing within
    0.1 s."""
    sig = TacanSignalConfig(bearing_deg=270.0, snr_db=10.0, duration_s=2.0, seed=3,
                            rotation_hz=15.15)
    r = run_tacan(TacanRunConfig(signal=sig, backend="model", dsp="fixed"))
    assert abs(r["rotation_hz"] - 15.15) <= 15.0 * 1e-5
    assert abs(r["mean_error_deg"]) < 0.1 and r["rmse_deg"] < 2 * r["crb_deg"]
    assert r["first_valid_bearing_s"] < 0.1 and r["refs_off_grid"] == 0
