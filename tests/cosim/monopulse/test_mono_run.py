"""Monopulse closed loop on the fast path: C2 (tracking RMS < measurement RMS, measurement
RMS within 1.5x the CRB), C5 (pointing inside the unambiguous region), C6 (acquisition of a
target off the guided pointing), calibration, bad input, the fast path's
block-centre outputs against fastpath.mean_outputs."""
from __future__ import annotations

import re

import numpy as np
import pytest

from cosim.monopulse.fastpath import mean_outputs
from cosim.monopulse.run import MonopulseRunConfig, block_outputs, run_monopulse

CRB_FACTOR = 1.5


def _check_c2_c5(r):
    assert r["acquired_trials"] == r["trials"] and r["lost_track_events"] == 0, r
    for ax in ("az", "el"):
        assert r[f"{ax}_track_rms_deg"] < r[f"{ax}_meas_rms_deg"], r
        assert r[f"{ax}_meas_over_crb"] < CRB_FACTOR, r
        assert r[f"{ax}_meas_over_crb"] > 1 / CRB_FACTOR, r     # not too good either
    assert r["pointing_error_max_fraction"] < 1.0 and r["outside_unambiguous_blocks"] == 0, r


@pytest.mark.parametrize("tracker,dsp", [("adaptive", "float"), ("fixed", "fixed")])
def test_c2_c5_short(tracker, dsp):
    r = run_monopulse(MonopulseRunConfig(trials=8, duration_s=0.3, tracker=tracker, dsp=dsp,
                                         seed=3))
    _check_c2_c5(r)


@pytest.mark.slow
@pytest.mark.parametrize("tracker", ["adaptive", "fixed"])
@pytest.mark.parametrize("dsp", ["float", "fixed"])
def test_c2_c5_100_runs_of_2_s(tracker, dsp):
    r = run_monopulse(MonopulseRunConfig(trials=100, duration_s=2.0, tracker=tracker, dsp=dsp,
                                         seed=11))
    _check_c2_c5(r)


def test_c5_manoeuvre_stays_inside_the_unambiguous_region():
    r = run_monopulse(MonopulseRunConfig(trials=4, duration_s=0.6, accel_u=-3.0, accel_v=2.0,
                                         manoeuvre_start_s=0.15, manoeuvre_end_s=0.45, seed=4))
    assert r["acquired_trials"] == 4 and r["lost_track_events"] == 0, r
    assert r["pointing_error_max_fraction"] < 1.0 and r["outside_unambiguous_blocks"] == 0, r


def test_c6_acquires_a_target_off_the_guided_pointing():
    r = run_monopulse(MonopulseRunConfig(trials=3, duration_s=0.3, pointing_u=0.55,
                                         pointing_v=-0.05, seed=5))
    assert r["acquired_trials"] == 3
    assert r["acquisition_block_max"] > 5          # not at the guided pattern: in the centres
    assert r["pointing_error_max_fraction"] < 1.0


def test_calibration_removes_the_mismatch_bias():
    r = run_monopulse(MonopulseRunConfig(duration_s=0.01, settle_s=0.0, gain_spread_db=0.5,
                                         phase_spread_deg=4.0, seed=2))
    b0, b1 = r["calibration"]["bias_before"], r["calibration"]["bias_after"]
    assert max(abs(b0["u"]), abs(b0["v"])) > 5e-4
    assert max(abs(b1["u"]), abs(b1["v"])) < 0.1 * max(abs(b0["u"]), abs(b0["v"]))
    r = run_monopulse(MonopulseRunConfig(duration_s=0.01, settle_s=0.0, gain_spread_db=0.5,
                                         phase_spread_deg=4.0, seed=2, cal_snr_db=None))
    b1 = r["calibration"]["bias_after"]
    assert max(abs(b1["u"]), abs(b1["v"])) < 1e-6      # noise-free: left, the 0.4 ms of motion


def test_block_centre_outputs_match_the_fast_path_mean():
    cfg = MonopulseRunConfig(duration_s=0.01, settle_s=0.0).signal_config()
    st = np.array([[0.31, 0.19]])
    s_ref, _ = mean_outputs(cfg, st[0], first_block=3)
    u, v = cfg.trajectory(cfg.block_centre_s(3))
    s, _, _ = block_outputs(cfg, st, float(u), float(v), np.ones(4), np.array([cfg.carrier_phase]),
                            None, noise=False)
    np.testing.assert_allclose(s[0], s_ref[0], rtol=1e-6)


def test_same_seed_same_digest_other_seed_other():
    a = run_monopulse(MonopulseRunConfig(duration_s=0.05, settle_s=0.0, seed=8))
    b = run_monopulse(MonopulseRunConfig(duration_s=0.05, settle_s=0.0, seed=8))
    c = run_monopulse(MonopulseRunConfig(duration_s=0.05, settle_s=0.0, seed=9))
    assert a["digest"] == b["digest"] != c["digest"]


@pytest.mark.parametrize("kw,msg", [
    (dict(snapshots=0), "snapshots must be an integer >= 1, not 0"),
    (dict(spacing_wl=0.0), "spacing_wl must be a finite number > 0, not 0.0"),
    (dict(u0=0.9, v0=0.9), "initial target direction must lie in the visible region"),
    (dict(phase_bits=0), "phase_bits must be an integer in [1, 24], not 0"),
    (dict(du_dt=1.0), "the target leaves the visible region u^2 + v^2 < 1 at t = 0.682 s "
     "(u = 0.982, v = 0.1898): shorten --duration-s 2 to below that"),
    (dict(trials=0), "trials must be an integer >= 1, not 0"),
    (dict(backend="golden", trials=2), "the golden backend runs one trial, not trials = 2"),
    (dict(backend="model", trials=2), "the model backend runs one trial, not trials = 2"),
    (dict(backend="verilator", latency_blocks=2), "the HDL front end's steering registers take "
     "effect at the next block boundary (latency_blocks 1), not latency_blocks = 2"),
    (dict(backend="model", snapshots=64), "the DSP service cannot turn a record around within "
     "one block on the HDL front end: worst case 20477 cycles (service_period_cycles 20000"),
    (dict(backend="pysim", duration_s=2.0), "200,048,640 cycles on the pysim backend (about "
     "2e+03 cycles/s; --duration-s 2) would take about 27.8 h on this machine (limit 2 h): "
     "reduce --duration-s; long records run on --backend model"),
    (dict(backend="model", service_batch_words=4, snapshots=1 << 14),
     "service_batch_words must hold one record (9 words), not 4"),
    (dict(backend="model", hdl_changes=(("cordic_iterations", 2),)),
     "monopulse cordic_iterations must be"),
])
def test_bad_input_is_refused(kw, msg):
    with pytest.raises(ValueError, match=re.escape(msg)):
        MonopulseRunConfig(**kw)
