"""The AUKF patent's adaptive UKF tracker: A1 (closed form == generic augmented UKF), bad
configuration, fixed vs float on the patent's scenario, A3 (short form)."""
import numpy as np
import pytest

from cosim.gnss.dynamics import aukf_patent_dynamics
from cosim.gnss.loopsim import cycle_slips, track_fast, truth_for
from dsp.gnss.aukf import AukfTracker
from dsp.gnss.aukf_master import AukfFormats, QFormat, master_update, master_update_generic
from dsp.gnss.trackers import TrackerContext, make_tracker, tracker_names


def _random_prior(rng, B):
    x = rng.normal(size=(B, 4)) * [1.0, 50.0, 10.0, 1.0]
    A = rng.normal(size=(B, 4, 4)) * 0.1
    P = A @ A.transpose(0, 2, 1) + 1e-3 * np.eye(4)
    y = rng.normal(size=(B, 2))
    return x, P, y


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a1_closed_form_equals_generic_augmented_ukf(seed):
    rng = np.random.default_rng(seed)
    x, P, y = _random_prior(rng, 40)
    R = np.array([[0.3155, 0.02], [0.02, 0.25]])
    xc, Pc, evc = master_update(x, P, y, R, amplitude=1.3)
    xg, Pg, evg = master_update_generic(x, P, y, R, amplitude=1.3)
    assert evc.sum() == 0 and evg["chol_fail"] == 0
    np.testing.assert_allclose(xc, xg, rtol=1e-12, atol=1e-12 * np.abs(xg).max(), err_msg=f"seed {seed}")
    np.testing.assert_allclose(Pc, Pg, rtol=1e-12, atol=1e-12 * np.abs(Pg).max(), err_msg=f"seed {seed}")
    # the update moved the state (the check can fail)
    assert np.abs(xc - x).max() > 1e-3


def test_registered():
    assert {"aukf", "ukf", "pll3"} <= set(tracker_names())


CTX = TrackerContext(fs_hz=16.368e6, doppler0_hz=np.zeros(2), cn0_dbhz=32.0)


@pytest.mark.parametrize("kw, msg", [
    (dict(epsilon=0.0), r"epsilon \(UT scaling\) must be > 0, not 0.0"),
    (dict(epsilon=-1.0), r"epsilon \(UT scaling\) must be > 0, not -1.0"),
    (dict(q0=-1.0), r"q0 \(initial process-noise intensity\) must be >= 0, not -1.0"),
    (dict(P0=np.diag([1e-3, 1e-3, -1e-3, 1e-3])), r"P0 must be positive semi-definite"),
    (dict(block_epochs=1), r"block_epochs must be an integer >= 2, not 1"),
    (dict(slave="x"), r"slave must be 'block' or 'seed', not 'x'"),
])
def test_bad_config(kw, msg):
    with pytest.raises(ValueError, match=msg):
        AukfTracker(CTX, "float64", **kw)


def test_formats_too_narrow():
    with pytest.raises(ValueError, match=r"formats too narrow: AukfFormats.w0 QFormat\(bits=24, frac=10\)"):
        AukfTracker(TrackerContext(fs_hz=16.368e6, doppler0_hz=5251.4, cn0_dbhz=32.0),
                    AukfFormats(w0=QFormat(24, 10)))
    with pytest.raises(ValueError, match=r"formats too narrow: AukfFormats.P"):
        AukfTracker(CTX, AukfFormats(P=QFormat(20, 8)))
    with pytest.raises(ValueError, match=r"format bits must be an integer in 2..62, not 70"):
        QFormat(70, 20)
    with pytest.raises(ValueError, match=r"cn0_dbhz must be given"):
        AukfTracker(TrackerContext(fs_hz=16.368e6), "float64")


def _run(name, arith, q_true, n, trials, seed=5, nav=True, **opts):
    tr = truth_for(aukf_patent_dynamics(q=q_true), n * 1e-3 + 0.01, seed=seed, nav_data=nav)
    ctx = TrackerContext(fs_hz=16.368e6, doppler0_hz=np.full(trials, tr(np.array([0.0]))["doppler_hz"][0]),
                         doppler_rate0_hz_s=tr(np.array([0.0]))["doppler_rate_hz_s"][0], cn0_dbhz=32.0)
    trk = make_tracker(name, ctx, arith, **opts)
    r = track_fast(tr, 32.0, n, shape=(trials,), seed=seed + 1, tracker=trk)
    return r, trk


def test_fixed_vs_float_patent_scenario():
    """The AUKF patent's scenario (x0 dynamics, q = q0, 32 dB-Hz): the fixed-format tracker's Doppler
    within 0.01 Hz of float64's on the same noise, P PSD at the end, no saturation, every
    Cholesky failure counted (none expected here)."""
    n, B = 2000, 8
    rf, tf = _run("aukf", "float64", 5.0, n, B)
    rx, tx = _run("aukf", AukfFormats(), 5.0, n, B)
    d = np.abs(rx.doppler_hz - rf.doppler_hz)
    assert d[100:].max() < 0.01, d.max()
    assert d.max() > 0          # the formats do quantise
    for t in (tf, tx):
        assert np.all(np.linalg.eigvalsh(t.P) > 0)
        c = t.counts()
        assert c["chol_fail"] == 0 and c["s_not_pd"] == 0
    assert tx.counts()["saturations"] == 0
    assert cycle_slips(rx.phase_err_cycles).sum() == 0


def test_cholesky_failure_counted_and_recovered():
    x, P, y = _random_prior(np.random.default_rng(4), 3)
    P[1] = np.diag([-1e-3, 1e-3, 1e-3, 1e-3])        # not PD: first pivot fails
    xc, Pc, ev = master_update(x, P, y, np.eye(2) * 0.3)
    assert ev[:, 0].tolist() == [0, 1, 0]
    assert np.all(np.linalg.eigvalsh(Pc[1]) > 0)


def test_a3_short():
    """A3 short form (q_true = q0, 24 runs x 3 s): AUKF Doppler RMSE <= 1.1 x UKF's."""
    n, B = 3000, 24
    ra, ta = _run("aukf", "float64", 5.0, n, B, seed=11)
    ru, _ = _run("ukf", "float64", 5.0, n, B, seed=11)
    rms = lambda r: float(np.sqrt(np.mean(r.freq_err_hz[n // 2:] ** 2)))
    assert rms(ra) <= 1.1 * rms(ru), (rms(ra), rms(ru))
    rep = ta.report()
    assert len(rep["q_hat"]["trajectory_median"]) == n // 500 + 1
    assert rep["diverged_count"] == 0
