"""The TACAN paper's 5-state envelope Kalman filter (float form of the one source), checked against
independent formulations: batch least squares and a plain numpy matrix Kalman filter."""
import numpy as np
import pytest

from dsp.tacan.kalman import EnvelopeKalman
from dsp.tacan.kalman_config import KalmanConfig
from dsp.tacan.standard import F15, F135

H = np.array([1.0, 0, 1, 0, 1])


def _transition(dt):
    """Eq. 12 for each dt (s), written independently: (N, 5, 5)."""
    dt = np.atleast_1d(np.asarray(dt, dtype=np.float64))
    a, b = 2 * np.pi * F15 * dt, 2 * np.pi * F135 * dt
    A = np.zeros(dt.shape + (5, 5))
    A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1] = np.cos(a), np.sin(a), -np.sin(a), np.cos(a)
    A[..., 2, 2], A[..., 2, 3], A[..., 3, 2], A[..., 3, 3] = np.cos(b), np.sin(b), -np.sin(b), np.cos(b)
    A[..., 4, 4] = 1.0
    return A


def _matrix_kalman(cfg, dts, y):
    """Textbook matrix form (no gate): x, P after the run."""
    q_rot, q_dc = cfg.q_rates()
    x, P = np.zeros(5), np.eye(5) * cfg.p0
    for dt, yk in zip(dts, y):
        A = _transition(dt)[0]
        x = A @ x
        P = A @ P @ A.T + np.diag([q_rot * dt] * 4 + [q_dc * dt])
        PH = P @ H
        K = PH / (H @ PH + 1.0)
        x = x + K * (yk - H @ x)
        P = P - np.outer(K, PH)
        P = 0.5 * (P + P.T)
    return x, P


def _stream(seed, n=600, sigma=0.05):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.exponential(1 / 7200, n))  # non-uniform peak times
    x_true = np.array([0.2, -0.1, 0.05, 0.19, 1.0])
    A = _transition(t - t[-1])  # state at t_j from the state at t_N
    y = np.einsum("nij,j->ni", A, x_true) @ H + rng.standard_normal(n) * sigma
    return t, y, x_true


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_kalman_equals_batch_least_squares(seed):
    """With no process noise the filter is recursive least squares: its final state must
    equal the batch fit of all measurements expressed at the last time, with the prior
    x0 = 0, P0 = p0 I as a ridge term (written independently, solved with numpy.linalg)."""
    t, y, _ = _stream(seed)
    cfg = KalmanConfig(memory_s=1e9, p0=1e4, gate=1e9)
    kf = EnvelopeKalman(cfg)
    kf.run(np.diff(t, prepend=t[0]), y[None, :])
    A = _transition(t - t[-1])
    M = A[:, [0, 2, 4], :].sum(axis=1)  # H A(t_j - t_N)
    info = M.T @ M + np.eye(5) / cfg.p0
    x_ls = np.linalg.solve(info, M.T @ y)
    np.testing.assert_allclose(kf.x[0], x_ls, rtol=0, atol=1e-10)
    # Its covariance is the LS covariance (in units of r).
    np.testing.assert_allclose(kf.P[0], np.linalg.inv(info), rtol=1e-8, atol=1e-14)


def test_equals_matrix_form_with_process_noise_and_chunking():
    """With Q (the real memory) and the run split in uneven chunks, the filter equals the
    textbook matrix recursion."""
    t, y, _ = _stream(4, n=300)
    dts = np.diff(t, prepend=t[0])
    cfg = KalmanConfig(gate=1e9)
    a = EnvelopeKalman(cfg)
    for lo, hi in [(0, 7), (7, 8), (8, 150), (150, 300)]:
        a.run(dts[lo:hi], y[None, lo:hi])
    x, P = _matrix_kalman(cfg, dts, y)
    np.testing.assert_allclose(a.x[0], x, rtol=0, atol=1e-10)
    np.testing.assert_allclose(a.P[0], P, rtol=1e-9, atol=1e-12)
    assert a.arithmetic == "float"


def test_ticks_and_seconds_agree_in_float():
    ticks = np.random.default_rng(3).integers(100, 6000, 300)
    y = np.random.default_rng(4).uniform(0.5, 1.5, (1, 300))
    a, b = EnvelopeKalman(), EnvelopeKalman(KalmanConfig(tick_hz=20e6))
    a.run(ticks / 20e6, y)
    b.run(ticks, y)
    np.testing.assert_array_equal(a.x, b.x)


def test_batched_trials_are_independent():
    t, y, _ = _stream(5, n=200)
    dts = np.diff(t, prepend=t[0])
    ys = np.stack([y, 2 * y, -y])
    kb = EnvelopeKalman(batch=3)
    kb.run(dts, ys)
    for i in range(3):
        k1 = EnvelopeKalman()
        k1.run(dts, ys[i:i + 1])
        np.testing.assert_allclose(kb.x[i], k1.x[0], atol=1e-12)


def test_covariance_stays_symmetric_psd_over_a_long_run():
    rng = np.random.default_rng(0)
    n = 20000
    dts = rng.exponential(1 / 7200, n)
    kf = EnvelopeKalman()
    kf.run(dts, rng.standard_normal((1, n)) * 0.1 + 1.0)
    P = kf.P[0]
    np.testing.assert_allclose(P, P.T, atol=0)
    assert np.linalg.eigvalsh(P).min() > 0


def test_outliers_are_gated_and_divergence_reinitialises():
    rng = np.random.default_rng(1)
    cfg = KalmanConfig(warmup=100, max_rejects=20, input_limit=2.0)
    kf = EnvelopeKalman(cfg)
    dts = rng.exponential(1 / 7200, 3000)
    y = 1.0 + 0.05 * rng.standard_normal(3000)
    y[1000] = 1.95                      # one wild pulse: gated
    y[2000:2100] = 1.8                  # the level jumps: divergence -> re-initialise
    y[500] = y[2500] = 50.0             # beyond input_limit: not a measurement at all
    kf.run(dts, y[None, :])
    assert kf.events["gated"][0] >= 21
    assert kf.events["reinit"][0] == 1
    assert kf.events["implausible"][0] == 2
    assert np.all(np.isfinite(kf.x))
    with pytest.raises(ValueError, match="input_limit must be a finite number > 0 or None"):
        KalmanConfig(input_limit=0.0)


def test_nan_measurement_is_refused():
    kf = EnvelopeKalman()
    with pytest.raises(ValueError, match="measurement is NaN or infinite"):
        kf.run(np.ones(3) * 1e-4, np.array([[1.0, np.inf, 1.0]]))


@pytest.mark.parametrize("kw, message", [
    (dict(memory_s=0.0), r"memory_s must be a finite number > 0, not 0.0"),
    (dict(memory_s=float("nan")), r"memory_s must be a finite number > 0, not nan"),
    (dict(gate=-1.0), r"gate must be a finite number > 0, not -1.0"),
    (dict(warmup=0), r"warmup must be an integer >= 1, not 0"),
    (dict(memory_s=1e-4), r"memory_s=0.0001 is shorter than a few pulses"),
])
def test_bad_config(kw, message):
    with pytest.raises(ValueError, match=message):
        KalmanConfig(**kw)


@pytest.mark.parametrize("arith", ["float", "fixed"])
def test_state_jump_sees_a_state_word_changed_between_updates(arith):
    """The state-continuity monitor: between checkpoints ~50 updates apart the state,
    turned back by the model, moves by about what the measurements' information allows
    (a few standard deviations of it at most); a state word changed from outside (an upset
    of the DSP's memory) moves it by many; so does a covariance word raised beyond the
    process noise. The answer: the checkpoint's state predicted to now (the core's own
    prediction); twice in a row, a re-initialisation, after which nothing is judged until
    the next checkpoint."""
    from dsp.tacan.kalman_config import KalmanFixedConfig
    t, y, _ = _stream(5, n=3000)
    cfg = KalmanConfig()
    kf = EnvelopeKalman(KalmanFixedConfig(kalman=cfg) if arith == "fixed" else cfg)
    dts = np.diff(t, prepend=t[0])
    assert kf.state_jump()[0] == 0.0                     # no checkpoint yet
    kf.run(dts[:1000], y[None, :1000])
    kf.checkpoint()
    z = []
    for a in range(1000, 2500, 50):
        kf.run(dts[a:a + 50], y[None, a:a + 50])
        z.append(kf.state_jump()[0])
        kf.checkpoint()
    assert 0.5 < np.median(z) < 3 and max(z) < 6 and not kf.covariance_fault()[0]
    # the 135 Hz sine term moved by 0.02 (10 % of its amplitude) between two updates
    x_ck, P_ck = kf.x.copy(), kf.P.copy()
    kf.x[0, 2] += 0.02 if arith == "float" else int(round(0.02 * 2 ** kf.fixed.x.frac))
    kf.run(dts[2500:2550], y[None, 2500:2550])
    assert kf.state_jump()[0] > 12.0 and not kf.covariance_fault()[0]
    # recovered: the checkpoint's state predicted over the interval, by the core itself
    # (a reference filter fed one implausible input over the interval: predict only)
    rcfg = KalmanConfig(input_limit=10.0)
    ref = EnvelopeKalman(KalmanFixedConfig(kalman=rcfg) if arith == "fixed" else rcfg)
    ref.x[:], ref.P[:], ref._r[:] = x_ck, P_ck, kf._r
    ref.run(np.array([kf._elapsed_ticks]) if arith == "fixed" else np.array([kf._elapsed_s]),
            np.array([[100.0]]))
    assert ref.events["implausible"][0] == 1
    kf.recover(kf.state_jump() > 12.0)
    if arith == "fixed":                                 # the same bits
        np.testing.assert_array_equal(kf.x, ref.x)
        np.testing.assert_array_equal(kf.P, ref.P)
    else:
        np.testing.assert_allclose(kf.x, ref.x, rtol=0, atol=1e-15)
        np.testing.assert_allclose(kf.P, ref.P, rtol=1e-15, atol=0)
    assert kf.events["state_faults"][0] == 1 and kf.events["reinit"][0] == 0
    assert kf.state_jump()[0] < 1.0                      # its own checkpoint, unmoved
    # a second failed check in a row: the checkpoint is not trusted -- re-initialised
    kf.recover(np.array([True]))
    assert kf.events["state_faults"][0] == 2 and kf.events["reinit"][0] == 1
    assert (kf.P_float()[0].diagonal() == cfg.p0).all() and (kf.x[0] == 0).all()
    kf.run(dts[2550:3000], y[None, 2550:3000])
    assert kf.state_jump()[0] == 0.0                     # across a re-initialisation: not judged
    assert not kf.covariance_fault()[0]


@pytest.mark.parametrize("arith", ["float", "fixed"])
def test_covariance_fault_sees_a_covariance_word_changed_between_updates(arith):
    """``P`` only rotates, grows by the process noise and shrinks with updates: a diagonal
    word raised by far more than the process noise since the checkpoint, or an off-diagonal
    word beyond the Cauchy-Schwarz bound, is a corrupted word (and a state-jump statistic
    that divides by the covariance does not see it)."""
    from dsp.tacan.kalman_config import KalmanFixedConfig
    t, y, _ = _stream(6, n=2000)
    cfg = KalmanConfig()
    dts = np.diff(t, prepend=t[0])
    for i, j, v in ((1, 1, 0.5), (0, 2, 0.5)):
        kf = EnvelopeKalman(KalmanFixedConfig(kalman=cfg) if arith == "fixed" else cfg)
        kf.run(dts[:1500], y[None, :1500])
        kf.checkpoint()
        kf.run(dts[1500:1550], y[None, 1500:1550])
        assert not kf.covariance_fault()[0]
        kf.checkpoint()
        code = v if arith == "float" else int(round(v * 2 ** kf.fixed.P.frac))
        kf.P[0, i, j] += code
        if i != j:
            kf.P[0, j, i] += code
        assert kf.covariance_fault()[0], (i, j)            # as stored
        assert kf.state_jump()[0] < 12.0
