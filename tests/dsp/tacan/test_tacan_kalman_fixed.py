"""Fixed-point envelope Kalman filter: bit-exact against an unbounded-integer reference,
close to the float golden filter, stable over long runs, robust to garbage input."""
import numba
import numpy as np
import pytest

from cosim.tacan.signal import TacanSignalConfig, pulse_observations
from dsp.fixed import FixedFormat
from dsp import qops
from dsp.tacan import kalman_config as kfx
from dsp.tacan import phase_ops
from dsp.tacan.bearing import PHASE_BITS
from dsp.tacan.kalman import EnvelopeKalman
from dsp.tacan.kalman_config import KalmanConfig, KalmanFixedConfig
from dsp.tacan.kalman_kernel import EVENT_NAMES
from dsp.tacan.standard import F15, F135


def EnvelopeKalmanFixed(cfg=None, batch=1):
    return EnvelopeKalman(cfg or KalmanFixedConfig(), batch)


@numba.njit
def _sincos_phase(lut, phase, cs_frac, half):
    return phase_ops.sincos_dt(lut, phase, np.int64(1), cs_frac, half)


# ---------------------------------------------------------------------------------------
# Reference: the same integer arithmetic written directly with Python's unbounded ints
# (no split multiplies, no two-step divisions): round(v / 2^s) = (v + half) >> s exactly.
# ---------------------------------------------------------------------------------------
def _rs(v, s, half):
    if s <= 0:
        return v << -s
    return (v + (1 << (s - 1) if half else 0)) >> s


def _div(num, den, half):
    """floor(num / den) or floor(num / den + 1/2), den > 0."""
    return (2 * num + den) // (2 * den) if half else num // den


class _Ref:
    def __init__(self, cfg: KalmanFixedConfig):
        self.cfg = cfg
        c = [int(v) for v in cfg.value_consts()]
        self.c = c
        self.fw15, self.fw135, self.q_rot, self.q_dc, self.p0, self.g2 = c[:6]
        k = cfg.kalman
        self.warmup, self.max_rej, self.r_smooth = k.warmup, k.max_rejects, k.r_smooth
        self.ev = {n: 0 for n in EVENT_NAMES}
        self.r = 1 << cfg.r.frac
        self.bias = None
        self.reset()

    def reset(self):
        self.x = [0] * 5
        self.P = [[self.p0 if i == j else 0 for j in range(5)] for i in range(5)]
        self.n = 0
        self.rej = 0

    def sat(self, v, f: FixedFormat, name):
        if v < f.min_int or v > f.max_int:
            self.ev[name] += 1
            return min(max(v, f.min_int), f.max_int)
        return v

    @staticmethod
    def trig(phase, csf, half):
        lut = [int(v) for v in phase_ops.SIN_LUT]
        sh = PHASE_BITS - phase_ops.LUT_BITS
        idx, d = phase >> sh, phase & ((1 << sh) - 1)
        s0, c0 = lut[idx], lut[(idx + (1 << (phase_ops.LUT_BITS - 2))) % (1 << phase_ops.LUT_BITS)]
        TF = phase_ops.TRIG_FRAC
        dl = _rs((d >> 8) * phase_ops._TWO_PI_30, PHASE_BITS - 8, 1)
        d2 = _rs(dl * dl, TF, 1)
        d3 = _rs(d2 * dl, TF, 1)
        cd, sd = (1 << TF) - (d2 >> 1), dl - d3 // 6
        return (_rs(s0 * cd + c0 * sd, 2 * TF - csf, half),
                _rs(c0 * cd - s0 * sd, 2 * TF - csf, half))

    def step(self, dt, y, rm):
        cfg = self.cfg
        fx, fP, fK, fcs, fi, fr, fy = cfg.x, cfg.P, cfg.K, cfg.cs, cfg.innov, cfg.r, cfg.y
        hx, hP, hK, hcs, hi, hr = (f.rounding == "half_up" for f in (fx, fP, fK, fcs, fi, fr))
        mask = (1 << PHASE_BITS) - 1
        sa, ca = self.trig((dt * self.fw15) & mask, fcs.frac, hcs)
        sb, cb = self.trig((dt * self.fw135) & mask, fcs.frac, hcs)
        qr = _rs(self.q_rot * min(dt, (1 << 61) // self.q_rot), kfx.Q_EXTRA, hP)
        qd = _rs(self.q_dc * min(dt, (1 << 61) // self.q_dc), kfx.Q_EXTRA, hP)
        one = 1 << fcs.frac
        A = [[ca, sa, 0, 0, 0], [-sa, ca, 0, 0, 0], [0, 0, cb, sb, 0], [0, 0, -sb, cb, 0],
             [0, 0, 0, 0, one]]
        cf = fcs.frac
        x, P = self.x, self.P
        xp = [self.sat(_rs(sum(A[i][j] * x[j] for j in range(5)), cf, hx), fx, "sat_x")
              for i in range(4)] + [x[4]]
        M = [[P[4][j] if i == 4 else
              self.sat(_rs(sum(A[i][k] * P[k][j] for k in range(4)), cf, hP), fP, "sat_P")
              for j in range(5)] for i in range(5)]
        Pp = [[0] * 5 for _ in range(5)]
        for i in range(5):
            for j in range(i, 5):
                v = M[i][4] if j == 4 else _rs(sum(M[i][k] * A[j][k] for k in range(4)), cf, hP)
                if i == j:
                    v += qr if i < 4 else qd
                Pp[i][j] = Pp[j][i] = self.sat(v, fP, "sat_P")
        if y is None:                                   # implausible input: predict only
            self.ev["implausible"] += 1
            self.x, self.P = xp, Pp
            return
        yh = xp[0] + xp[2] + xp[4]
        if self.bias and self.bias[3][1] > 0 and self.n >= self.warmup and yh >= self.bias[3][1] \
                and (y << (fx.frac - fy.frac)) < self.bias[3][0]:
            self.ev["noise_reports"] += 1               # a noise report: predict only
            self.x, self.P = xp, Pp
            return
        PH = [Pp[i][0] + Pp[i][2] + Pp[i][4] for i in range(5)]
        if self.bias:   # (table codes, slope codes, shift, noise rule): the peak-bias table
            tab, slope, sh, _ = self.bias
            j = min(max(_rs(yh, sh, False), 0), len(tab) - 1)
            PH = [_rs(v * slope[j], cf, hP) for v in PH]           # the row g H
            S = _rs((PH[0] + PH[2] + PH[4]) * slope[j], cf, hP) + rm
            yh += tab[j]
        else:
            S = PH[0] + PH[2] + PH[4] + rm
        iv = self.sat(_rs((y << (fx.frac - fy.frac)) - yh, fx.frac - fi.frac, hi), fi,
                      "sat_innov")
        if S <= 0:
            raise AssertionError("S <= 0 in the reference run")
        nb = S.bit_length() - qops.S_BITS
        Sn = _rs(S, nb, 1)
        t = fr.frac - 2 * fi.frac + fP.frac - nb
        e2 = _div(iv * iv << t, Sn, hr) if t >= 0 else _div(iv * iv, Sn << -t, hr)
        e2 = self.sat(e2, fr, "sat_r")
        thr = min(_rs(self.g2 * self.r, kfx.GATE_FRAC, 0), fr.max_int)
        warm = self.n >= self.warmup
        gated = warm and e2 > thr
        if gated:
            self.x, self.P = xp, Pp
        else:
            K = [self.sat(_div(_rs(PH[i], nb, 1) << fK.frac, Sn, hK), fK, "sat_K")
                 for i in range(5)]
            self.x = [self.sat(xp[i] + _rs(K[i] * iv, fK.frac + fi.frac - fx.frac, hx), fx,
                               "sat_x") for i in range(5)]
            Pn = [[0] * 5 for _ in range(5)]
            for i in range(5):
                for j in range(i, 5):
                    v = self.sat(Pp[i][j] - _rs(K[i] * PH[j], fK.frac, hP), fP, "sat_P")
                    if i == j:
                        assert v >= 0
                        if v < 1:
                            v = 1
                            self.ev["p_clamps"] += 1
                    Pn[i][j] = Pn[j][i] = v
            self.P = Pn
            if self.n >= self.warmup // 2:
                acc, m = (min(e2, thr), self.r_smooth) if warm else \
                    (e2, max(1, self.n - self.warmup // 2 + 1))
                self.r = self.sat(self.r + _div(acc - self.r, m, hr), fr, "sat_r")
        self.n += 1
        if gated:
            self.ev["gated"] += 1
            self.rej += 1
            if self.rej >= self.max_rej:
                self.ev["reinit"] += 1
                self.reset()
        else:
            self.rej = 0


def _stream(seed, n, batch, outliers=()):
    rng = np.random.default_rng(seed)
    dt = rng.integers(1, 9000, n)                          # ticks at 20 MHz (<= 450 us)
    dt[rng.random(n) < 0.1] = 240                          # burst-like 12 us spacing
    dt[n // 2] = 3_000_000                                 # one long gap (0.15 s)
    t = np.cumsum(dt) / 20e6
    bear = rng.uniform(0, 2 * np.pi, batch)[:, None]
    y = (1 + 0.21 * np.sin(2 * np.pi * F15 * t - bear)
         + 0.21 * np.sin(2 * np.pi * F135 * t - 9 * bear)) * rng.uniform(0.3, 1.3, (batch, 1))
    y = y + rng.standard_normal(y.shape) * 0.02
    for k, v in outliers:
        y[:, k] = v
    rm = np.where(rng.random(n) < 0.1, rng.uniform(0.5, 20, n), 1.0)
    return dt, y, rm


@pytest.mark.parametrize("peak_bias", [False, True])
def test_kernel_equals_unbounded_integer_reference(peak_bias):
    """Bit-exact, also with a peak-bias table (the prediction plus the table's entry at
    the predicted amplitude; :mod:`dsp.tacan.peakbias`)."""
    n, B = 400, 4
    outl = [(k, 1.9) for k in range(250, 256)] + [(300, -1.9)] + \
        [(k, 7.5) for k in range(100, 104)] + [(k, -40.0) for k in range(320, 330)] + \
        [(k, 0.05) for k in range(150, 153)]       # low reports after the warm-up
    dt, y, rm = _stream(7, n, B, outl)
    cfg = KalmanFixedConfig(KalmanConfig(warmup=60, max_rejects=5, r_smooth=64))
    kf = EnvelopeKalmanFixed(cfg, batch=B)
    if peak_bias:
        from dsp.tacan.peakbias import PAIR_PEAK_BIAS
        kf.set_peak_bias(*PAIR_PEAK_BIAS.table(0.6), noise=(0.45, 0.5))
        assert len(set(kf._bt.tolist())) > 50 and kf._bs > 0
        assert len(set(kf._gt.tolist())) > 20 and kf._gt.max() == 1 << cfg.cs.frac
        plain = EnvelopeKalmanFixed(cfg, batch=B)
        plain.run(dt, y, rm)
    kf.run(dt, y, rm)
    if peak_bias:
        assert (np.abs(kf.x - plain.x) > 100).any()              # the table acts
        assert (kf.events["noise_reports"] > 0).any()             # and the noise rule
    yi = cfg.y.quantize(y)[0]
    raw = np.floor(np.ldexp(y, cfg.y.frac) + 0.5)                 # y codes before saturation
    implausible = (raw < cfg.y.min_int) | (raw > cfg.y.max_int)   # beyond the y range
    rmi = np.round(np.ldexp(rm, cfg.P.frac)).astype(np.int64)
    for b in range(B):
        ref = _Ref(cfg)
        ref.bias = ([int(v) for v in kf._bt], [int(v) for v in kf._gt], int(kf._bs),
                    [int(v) for v in kf._nq]) \
            if peak_bias else None
        for k in range(n):
            ref.step(int(dt[k]), None if implausible[b, k] else int(yi[b, k]), int(rmi[k]))
        assert [int(v) for v in kf.x[b]] == ref.x
        assert kf.P[b].tolist() == ref.P
        assert int(kf._r[b]) == ref.r
        ev = kf.events
        for name, v in ref.ev.items():
            if name != "sat_y":
                assert ev[name][b] == v, name
        assert ev["gated"][b] > 0 and ev["reinit"][b] >= 1      # both paths exercised
        assert ev["implausible"][b] == 14


def test_sin_cos_from_phase_accumulator():
    ph = np.random.default_rng(3).integers(0, 1 << PHASE_BITS, 2000)
    got = np.array([_sincos_phase(phase_ops.SIN_LUT, np.int64(p), np.int64(22), np.int64(1))
                    for p in ph]) / 2.0 ** 22
    ang = 2 * np.pi * ph / 2.0 ** PHASE_BITS
    np.testing.assert_allclose(got[:, 0], np.sin(ang), rtol=0, atol=0.51 * 2 ** -22 + 1e-12)
    np.testing.assert_allclose(got[:, 1], np.cos(ang), rtol=0, atol=0.51 * 2 ** -22 + 1e-12)


def test_fixed_tracks_float_on_tacan_pulses():
    """Documented bound: after 2 s at 10 dB every state within 2e-4 FS of the float filter
    (a few 1e-5 in practice), phases within 0.01 deg (15 Hz) / 0.01 deg (135 Hz), bearing
    (fine = 135 Hz phase / 9, the coarse only picks the sector) within 0.02 deg."""
    cfg = TacanSignalConfig(duration_s=2.0, snr_db=10, bearing_deg=90)
    bears = [90.0, 270.0, 33.0, 181.5]
    t, amps, _ = pulse_observations(cfg, bears)
    dts = np.diff(t, prepend=t[0])
    kf = EnvelopeKalman(batch=len(bears))
    kx = EnvelopeKalmanFixed(batch=len(bears))
    # run in chunks as the receiver does (ticks carried across calls)
    for lo in range(0, t.size, 1000):
        kf.run(dts[lo:lo + 1000], amps[:, lo:lo + 1000])
        kx.run(dts[lo:lo + 1000], amps[:, lo:lo + 1000])
    assert np.abs(kx.x_float() - kf.x).max() < 2e-4
    np.testing.assert_allclose(kx.r, kf.r, rtol=1e-3)
    pf, px = kf.phases(), kx.phases()
    d_alpha = np.degrees(np.angle(np.exp(1j * (pf[0] - px[0]))))
    d_beta = np.degrees(np.angle(np.exp(1j * (pf[1] - px[1]))))
    assert np.abs(d_alpha).max() < 0.01 and np.abs(d_beta).max() < 0.1
    assert np.abs(d_beta / 9).max() < 0.02             # bearing (fine) difference, deg
    ev = kx.events
    assert (ev["reinit"] == 0).all() and (ev["p_neg"] == 0).all()
    np.testing.assert_array_equal(ev["gated"], kf.events["gated"])


def test_receiver_bearing_fixed_vs_float():
    """The whole bearing chain (reference decoding, burst r_mult, chunked runs, coarse/fine
    combination) with the fixed filter in place of the float one: bearings within 0.02 deg."""
    from dsp.tacan import receiver
    from dsp.tacan.bearing import wrap_deg

    cfg = TacanSignalConfig(duration_s=2.0, snr_db=10, bearing_deg=90)
    bears = [90.0, 270.0, 7.0, 199.0]
    t, amps, _ = pulse_observations(cfg, bears)
    ref = receiver.process_peaks(t, amps)
    fcfg = receiver.ReceiverConfig(kalman=KalmanFixedConfig())
    assert fcfg.dsp == "fixed" and receiver.ReceiverConfig().dsp == "float"
    fx = receiver.process_peaks(t, amps, fcfg)
    assert fx.bearing_deg.shape == ref.bearing_deg.shape and ref.bearing_deg.shape[1] > 100
    keep = ref.times_s >= 0.5
    d = wrap_deg(fx.bearing_deg[:, keep] - ref.bearing_deg[:, keep])
    assert np.abs(d).max() < 0.02
    np.testing.assert_array_equal(fx.reinit, 0)


def test_long_run_stays_psd_without_reinit():
    n, B = 200_000, 2
    rng = np.random.default_rng(11)
    dts = rng.exponential(1 / 7200, n)
    t = np.cumsum(dts)
    y = 0.8 * (1 + 0.21 * np.sin(2 * np.pi * F15 * t) + 0.21 * np.sin(2 * np.pi * F135 * t + 1))
    y = y[None, :] + rng.standard_normal((B, n)) * 0.03
    kx = EnvelopeKalmanFixed(batch=B)
    kx.run(dts, y)
    P = kx.P_float()
    assert (kx.P == np.swapaxes(kx.P, 1, 2)).all()
    assert (np.linalg.eigvalsh(P) > 0).all()
    ev = kx.events
    assert (ev["reinit"] == 0).all() and (ev["p_neg"] == 0).all()
    assert all((ev[k] == 0).all() for k in ev if k.startswith("sat_"))
    assert np.isfinite(kx.x_float()).all()
    a, b, m1, m2, dc = kx.phases()
    np.testing.assert_allclose(m1, 0.8 * 0.21, rtol=0.02)
    np.testing.assert_allclose(dc, 0.8, rtol=0.005)


@pytest.mark.parametrize("dsp", ["fixed", "float"])
def test_garbage_input_reinitialises_and_recovers(dsp):
    """Garbage within the input range is gated until the filter re-initialises; garbage
    beyond ``input_limit`` is no measurement at all (counted ``implausible``): the filter
    only predicts through it and is not disturbed (the same in both arithmetics)."""
    rng = np.random.default_rng(5)
    n = 12_000
    dts = rng.exponential(1 / 7200, n)
    t = np.cumsum(dts)
    clean = 0.7 * (1 + 0.21 * np.sin(2 * np.pi * F15 * t - 1.0)
                   + 0.21 * np.sin(2 * np.pi * F135 * t - 2.0))
    y = clean + rng.standard_normal(n) * 0.02
    sign = np.sign(rng.standard_normal(200))
    truth = np.array([0.7 * 0.21 * np.sin(2 * np.pi * F15 * t[-1] - 1.0),
                      0.7 * 0.21 * np.cos(2 * np.pi * F15 * t[-1] - 1.0)])
    make = (lambda: EnvelopeKalmanFixed(batch=1)) if dsp == "fixed" else \
        (lambda: EnvelopeKalman(KalmanConfig(input_limit=2.0), batch=1))
    for level, inside in ((1.9, True), (1e9, False)):
        yy = y.copy()
        yy[3000:3200] = level * sign                          # front end gone mad
        kx = make()
        kx.run(dts[:6000], yy[None, :6000])
        ev = kx.events
        if inside:                                            # gated, then re-initialised
            assert ev["reinit"][0] >= 1 and ev["gated"][0] >= 64 and ev["implausible"][0] == 0
        else:                                                 # not measurements at all
            assert ev["implausible"][0] == 200 and ev["reinit"][0] == 0
            assert ev["sat_y"][0] == 0 and ev["gated"][0] <= 2
            if dsp == "fixed":
                assert kx.ranges()["y"]["max"] < 1.5          # the range log ignores them
        kx.run(dts[6000:], yy[None, 6000:])
        a, b, m1, m2, dc = kx.phases()
        np.testing.assert_allclose(kx.x_float()[0, :2], truth, atol=0.01)
        assert dc[0] == pytest.approx(0.7, abs=0.01)
        assert np.isfinite(kx.x_float()).all()


def test_ticks_and_seconds_agree():
    rng = np.random.default_rng(2)
    ticks = rng.integers(100, 6000, 500)
    y = rng.uniform(0.5, 1.5, (1, 500))
    a, b = EnvelopeKalmanFixed(), EnvelopeKalmanFixed()
    a.run(ticks, y)
    b.run(ticks / 20e6, y)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)
    c = EnvelopeKalmanFixed()               # raw integer y codes take the same path
    c.run(ticks, c.cfg.y.quantize(y)[0])
    np.testing.assert_array_equal(a.x, c.x)


def test_bad_input_messages():
    kx = EnvelopeKalmanFixed(batch=2)
    with pytest.raises(ValueError, match="measurement is NaN or infinite"):
        kx.run([1e-4, 1e-4], [[1.0, np.nan], [1.0, 1.0]])
    with pytest.raises(ValueError, match="dts must be finite and >= 0"):
        kx.run([-1e-4, 1e-4], np.ones((2, 2)))
    with pytest.raises(ValueError, match=r"r_mult must hold one finite value > 0 per step"):
        kx.run([1e-4, 1e-4], np.ones((2, 2)), r_mult=[1.0, 0.0])
    with pytest.raises(ValueError, match="3 measurements for 2 time steps"):
        kx.run([1e-4, 1e-4], np.ones((2, 3)))
    with pytest.raises(ValueError, match=r"batch must be an integer >= 1, not 0"):
        EnvelopeKalmanFixed(batch=0)


@pytest.mark.parametrize("changes, message", [
    (dict(P=FixedFormat(46, 30, True, "half_up", "wrap")),
     r"P overflow must be 'saturate', not 'wrap'"),
    (dict(K=FixedFormat(38, 30, True, "half_even", "saturate")),
     r"K rounding must be 'half_up' or 'floor', not 'half_even'"),
    (dict(x=FixedFormat(36, 28, False, "floor", "saturate")), r"x format must be signed"),
    (dict(kalman=KalmanConfig(p0=1e5)), r"p0=100000 does not fit the P format sQ15.30"),
    (dict(P=FixedFormat(52, 30, True, "half_up", "saturate")),
     r"the split P\*K product does not fit int64"),
    (dict(cs=FixedFormat(24, 23, True, "half_up", "saturate")),
     r"cs must hold \+-1 with at most 30 fraction bits"),
    (dict(x=FixedFormat(40, 28, True, "half_up", "saturate")),
     r"x\*cs and K\*innov products must fit 62 bits"),
    (dict(y=FixedFormat(18, 30, True, "half_up", "saturate")),
     r"x needs at least as many fraction bits as y"),
    (dict(r=FixedFormat(44, 36, True, "half_up", "saturate")),
     r"r format sQ7.36\(half_up,saturate\) does not fit e2 = innov\^2/S"),
    (dict(r=FixedFormat(20, 19, True, "half_up", "saturate")), r"must hold the initial r = 1"),
    (dict(innov=FixedFormat(26, 20, True, "half_up", "saturate"),
          K=FixedFormat(30, 26, True, "half_up", "saturate")),
     r"innov must be at most 24 bits wide"),
    (dict(kalman="fast"), r"kalman must be a KalmanConfig, not 'fast'"),
    (dict(innov=(24, 20)), r"innov must be a FixedFormat, not \(24, 20\)"),
])
def test_bad_config_messages(changes, message):
    with pytest.raises(ValueError, match=message):
        KalmanFixedConfig(**changes)


def test_the_core_reads_its_clock_from_the_filter_config():
    assert KalmanFixedConfig(KalmanConfig(tick_hz=24e6)).tick_hz == 24e6
    with pytest.raises(ValueError, match=r"tick_hz must be a finite number >= 135000, not nan"):
        KalmanConfig(tick_hz=float("nan"))
