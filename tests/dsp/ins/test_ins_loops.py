import math

import numpy as np
import pytest

from cosim.ins.ins_error import InsAiding, InsErrors
from cosim.ins.study import InsStudyConfig, run_loop, scenario_for
from cosim.ins.trajectory import Scenario, PaperTrajectory
from dsp.estimation.kalman import KalmanFilter
from dsp.gnss.loops_fixed import FLOAT
from dsp.gnss.trackers import TrackerContext, make_tracker, tracker_names
from dsp.ins.loops import (KF_FORMATS, KalmanCarrierLoop, kf_model_matrices, r_from_cn0,
                           steady_state_gain)

T = 1e-3


def test_registered():
    assert {"aided-kf", "aided-pll", "unaided-kf"} <= set(tracker_names())


def test_fixed_formats_fit_the_int64_datapath():
    KF_FORMATS.check(3, 1, 2)


def test_b4_iterated_gain_equals_riccati():
    ctx = TrackerContext(fs_hz=16.368e6, T_s=T, doppler0_hz=np.zeros(1), cn0_dbhz=40.0)
    lp = KalmanCarrierLoop(ctx, FLOAT, aided=False, oscillator="tcxo")
    kf = KalmanFilter(lp.model, np.zeros(3), np.eye(3) * 1e-3, "float64")
    kf.run(np.zeros((20000, 1)), np.zeros((20000, 2)))
    Ps = kf.P_float()[0]
    Ks = Ps @ lp.model.H[0].T / lp.model.R[0, 0, 0]          # posterior: K = P H^T R^-1
    K = (lp.D @ Ks).ravel()
    np.testing.assert_allclose(K, lp.steady_gain(), rtol=1e-9)


@pytest.mark.parametrize("bn_hz", [5.0, 15.0])
def test_b4_kalman_gain_is_the_equivalent_third_order_pll(bn_hz):
    # white-jerk triple integrator, measurement PSD r = R T: the steady-state loop is the
    # 3rd-order PLL with k = (2 w, 2 w^2, w^3), w = (q / r)^(1/6)  (a3 = b3 = 2)
    R = r_from_cn0(40.0, T)
    w = bn_hz / 0.7845
    q = w ** 6 * R * T
    A, B, H, Q, Rm = kf_model_matrices(T, 0.0, 0.0, q, R, aided=True)
    K = steady_state_gain(A, H, Q, Rm) / T
    np.testing.assert_allclose(K, [2 * w, 2 * w ** 2, w ** 3], rtol=0.04 * bn_hz / 5)
    # and not Kaplan's coefficients: the check can tell the two loops apart
    assert abs(K[0] - 2.4 * w) / (2.4 * w) > 0.1


def _ctx(**kw):
    base = dict(fs_hz=16.368e6, T_s=T, doppler0_hz=np.zeros(2), cn0_dbhz=40.0,
                aiding=lambda k: 0.0)
    base.update(kw)
    return TrackerContext(**base)


def test_bad_input_messages():
    with pytest.raises(ValueError, match=r"T_s must be a finite number > 0.0, not 0.0"):
        make_tracker("aided-kf", _ctx(T_s=0.0), FLOAT)
    with pytest.raises(ValueError, match=r"T_s must be a finite number > 0.0, not -0.001"):
        make_tracker("aided-pll", _ctx(T_s=-1e-3), FLOAT)
    with pytest.raises(ValueError, match=r"h0 must be a finite number >= 0.0, not -1e-19"):
        kf_model_matrices(T, -1e-19, 0.0, 1.0, 1e-3, True)
    with pytest.raises(ValueError, match=r"h_2 must be a finite number >= 0.0"):
        kf_model_matrices(T, 0.0, -1.0, 1.0, 1e-3, True)
    with pytest.raises(ValueError, match="oscillator h0 must be a finite number >= 0"):
        from dsp.gnss.oscillator import Oscillator
        make_tracker("aided-kf", _ctx(), FLOAT, oscillator=Oscillator(-1e-19, 0.0, 0.0))
    with pytest.raises(ValueError, match="aided Kalman loop needs ctx.aiding"):
        make_tracker("aided-kf", _ctx(aiding=None), FLOAT)
    nan = make_tracker("aided-kf", _ctx(aiding=lambda k: math.nan if k == 3 else 0.0), FLOAT)
    one = np.ones(2)
    for _ in range(2):
        nan.step(one, 0 * one, one, 0 * one, one, 0 * one)
    with pytest.raises(ValueError, match=r"aiding must give a finite Doppler rate \(Hz/s\); epoch 3"):
        nan.step(one, 0 * one, one, 0 * one, one, 0 * one)
    pll = make_tracker("aided-pll", _ctx(aiding=lambda k: math.nan), FLOAT)
    with pytest.raises(ValueError, match="aiding must give a finite Doppler rate"):
        pll.step(one, 0 * one, one, 0 * one, one, 0 * one)


def test_aiding_removes_the_dynamic_stress_noise_free():
    # ideal clock, perfect INS, no noise: the aided loops follow the 5 g/s ramp with a
    # phase error far below the unaided loop's
    sc = Scenario(PaperTrajectory(duration_s=4.0, start_s=0.5, accel_g=5.0, v_max_mps=100.0), osc=None)
    ins = InsAiding(sc, InsErrors(0, 0, 0, 0), T, 4002)
    res = {lp: _noise_free(lp, sc, ins) for lp in ("aided-kf", "unaided-kf", "aided-pll")}
    assert res["unaided-kf"] > 5e-4, res
    assert res["aided-kf"] < res["unaided-kf"] / 20, res
    assert res["aided-pll"] < res["unaided-kf"] / 20, res


def _noise_free(loop, sc, ins, latency=0, told=None, arith=FLOAT):
    from cosim.gnss.loopsim import track_fast
    t0 = sc.truth_at(np.zeros(1))
    ctx = TrackerContext(fs_hz=16.368e6, T_s=T, doppler0_hz=t0["doppler_hz"],
                         doppler_rate0_hz_s=t0["doppler_rate_hz_s"], cn0_dbhz=40.0, aiding=ins,
                         latency_epochs=latency if told is None else told)
    opts = {} if loop == "aided-pll" else {"oscillator": None}
    trk = make_tracker(loop, ctx, arith, **opts)
    r = track_fast(sc.truth_at, None, 4000, T, shape=(1,), tracker=trk, latency=latency)
    return float(np.abs(r.phase_err_cycles[300:]).max())


@pytest.mark.parametrize("latency", [1, 2])
def test_kalman_loop_with_a_loop_latency(latency):
    # the HDL channel's writes take effect one epoch late: the loop that knows it tracks the
    # 5 g/s ramp noise-free as well as with no latency; told no latency, it does far worse
    from dsp.gnss.loops_fixed import FixedArith
    sc = Scenario(PaperTrajectory(duration_s=4.0, start_s=0.5, accel_g=5.0, v_max_mps=100.0), osc=None)
    ins = InsAiding(sc, InsErrors(0, 0, 0, 0), T, 4004)
    base = _noise_free("aided-kf", sc, ins)
    for arith in (FLOAT, FixedArith()):
        late = _noise_free("aided-kf", sc, ins, latency, arith=arith)
        assert late < 2 * base + 2e-4, (latency, base, late)
    blind = _noise_free("aided-kf", sc, ins, latency, told=0)
    assert blind > 5 * (late + 1e-4), (base, late, blind)
    un = _noise_free("unaided-kf", sc, ins, latency)
    assert un < 0.05, un          # unaided, the loop still holds the ramp with the latency


# stated bounds (docs/explanation/ins.md): fixed within 0.005 Hz of Doppler and 0.05 deg of phase
# of the float loop on the same noise (measured: <= 0.0009 Hz, <= 0.011 deg)
@pytest.mark.parametrize("loop", ["aided-kf", "unaided-kf", "aided-pll"])
def test_fixed_within_bound_of_float(loop, dopp_hz=0.005, phase_deg=0.05):
    out = {}
    for dsp in ("float", "fixed"):
        cfg = InsStudyConfig(cn0_dbhz=40.0, oscillator="ocxo", trials=3, duration_s=2.5,
                             skip_s=0.2, dsp=dsp, seed=5, start_s=0.3, accel_g=2.5,
                             v_max_mps=30.0)
        res = run_loop(loop, cfg, keep=True)
        out[dsp] = res["series"]
        counts = res["tracker"].get("events", res["tracker"].get("saturations"))
        assert not any(counts.values()), counts          # no saturation or skipped update
    dd = np.abs(out["float"]["vel_err_mps"] - out["fixed"]["vel_err_mps"]).max() / 0.1903
    dp = np.abs(out["float"]["phase_err_cycles"] - out["fixed"]["phase_err_cycles"]).max() * 360
    print(loop, "fixed - float: Doppler", dd, "Hz, phase", dp, "deg")
    assert dd <= dopp_hz and dp <= phase_deg, (dd, dp)


@pytest.mark.parametrize("latency", [0, 1])
def test_aided_pll_aligns_the_handed_over_phase(latency):
    # a hand-over gives the Doppler, not the carrier phase: from a phase 0.22 cycle off
    # (near the Costas quarter cycle), noise-free and perfectly aided, the aided PLL is
    # within 2 deg of the truth from the epoch its alignment is in force on, and its rate
    # integrator is not kicked (without the alignment: ~70 deg after 20 ms, ~35 Hz/s)
    from dsp.gnss.loops_fixed import FixedArith
    from cosim.gnss.loopsim import track_fast
    sc = Scenario(PaperTrajectory(duration_s=4.0, start_s=0.5, accel_g=5.0, v_max_mps=100.0), osc=None)
    ins = InsAiding(sc, InsErrors(0, 0, 0, 0), T, 204)
    t0 = sc.truth_at(np.zeros(1))
    for arith in (FLOAT, FixedArith()):
        ctx = TrackerContext(fs_hz=16.368e6, T_s=T, doppler0_hz=t0["doppler_hz"],
                             doppler_rate0_hz_s=t0["doppler_rate_hz_s"], cn0_dbhz=40.0,
                             aiding=ins, latency_epochs=latency)
        trk = make_tracker("aided-pll", ctx, arith)
        r = track_fast(sc.truth_at, None, 150, T, shape=(1,), tracker=trk, latency=latency,
                       phase0_err_cycles=0.22)
        ph = np.abs(r.phase_err_cycles[:, 0] - np.rint(r.phase_err_cycles[:, 0] * 2) / 2)
        assert ph[:latency + 1].min() > 0.2, ph[:3]          # the start is 0.22 cycle off
        assert ph[latency + 2:].max() * 360 < 2.0, (latency, ph.max() * 360)
        v2 = trk.core.v2 * 2.0 ** -20 if arith is not FLOAT else trk.core.v2
        assert abs(float(np.ravel(v2)[0])) < 1.0, v2
