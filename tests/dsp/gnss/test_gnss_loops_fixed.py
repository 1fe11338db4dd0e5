"""The one-source channel core: float form == the float golden channel; fixed form bit
exact against a Python-int reference on random dumps; fixed within a stated bound of float
in closed loop."""
import numpy as np
import pytest

from cosim.gnss.dynamics import aukf_patent_dynamics
from cosim.gnss.loopsim import cycle_slips, track_fast, truth_for
from dsp.gnss.discriminators import costas_atan, dll_nelp, pll_atan2
from dsp.gnss.loops import TrackingChannel, hz_to_word
from dsp.gnss.loops_fixed import (COEF_FRAC, DISC_CODE, DISC_PHASE, F16_FRAC, FLOAT, T_FRAC, V1,
                                  V2, ChannelCore, FixedArith, check_products, word_coef_frac)

FS = 16.368e6
T = 1e-3
#: Stated bound, fixed vs float in closed loop (same noise): carrier phase error within
#: 0.025 deg (~2 LSB of DISC_PHASE, 2^-15 cycle = 0.011 deg), code error within 2e-4 chip.
PHASE_BOUND_DEG, CODE_BOUND_CHIPS = 0.025, 2e-4


def _dumps(rng, n, batch):
    e = rng.normal(0, 0.05, (n, batch))
    a = rng.uniform(20, 200, (n, batch))
    p = a * np.exp(2j * np.pi * e) + rng.normal(0, 3, (n, batch)) + 1j * rng.normal(0, 3, (n, batch))
    tau = rng.normal(0, 0.1, (n, batch))
    E = a * (1 - np.abs(tau - 0.25)) + rng.normal(0, 3, (n, batch))
    L = a * (1 - np.abs(tau + 0.25)) + rng.normal(0, 3, (n, batch))
    return E, rng.normal(0, 3, (n, batch)), p.real, p.imag, L, rng.normal(0, 3, (n, batch))


def _q(x, fmt):
    v = int(np.floor(x * 2.0 ** fmt.frac + 0.5))
    hi = (1 << (fmt.bits - 1)) - 1
    return max(-hi - 1, min(hi, v))


def _rs(v, s):
    return (v + (1 << (s - 1))) >> s if s > 0 else v << -s


def _sat(v, fmt):
    hi = (1 << (fmt.bits - 1)) - 1
    return max(-hi - 1, min(hi, v))


def test_float_form_is_the_golden_channel():
    rng = np.random.default_rng(3)
    d = _dumps(rng, 300, 16)
    gold = TrackingChannel(T, 3, 15.0, 1.0, 0.5, 4.092e6, False, 5255.0 * np.ones(16), 51.5)
    core = ChannelCore(FLOAT, FS, T, 3, 15.0, 1.0, 0.5, 4.092e6, False, 5255.0 * np.ones(16), 51.5)
    for k in range(300):
        g = gold.update(*(x[k] for x in d))
        c = core.step(*(x[k] for x in d))
        assert np.allclose(g[0], c[0], rtol=0, atol=1e-9) and np.allclose(g[1], c[1], rtol=0, atol=1e-9)


@pytest.mark.parametrize("order,inverted", [(3, False), (2, True)])
def test_fixed_is_bit_exact_against_python_ints(order, inverted):
    rng = np.random.default_rng(order)
    n, batch = 200, 8
    d = _dumps(rng, n, batch)
    f0, r0 = rng.uniform(-5000, 5000, batch), rng.uniform(-60, 60, batch)
    core = ChannelCore(FixedArith(), FS, T, order, 15.0, 1.0, 0.5, 4.092e6, inverted, f0, r0)
    K1, K2, K3, KT = core.K1, core.K2, core.K3, core.KT
    assert K3 == (round(T * (15 / 0.7845) ** 3 * 2 ** COEF_FRAC) if order == 3 else 0)
    # the word coefficients' fractions at 16.368 MS/s: the largest under 2^31
    KWC, KWK, KWD = (round(2 ** 32 / FS * 2 ** 22), round(2 ** 32 / FS / 1540 * 2 ** 33),
                     round(2 ** 32 / FS * 4 * 2 ** 20))
    assert (core.KWC, core.KWK, core.KWD) == (KWC, KWK, KWD)
    assert 2 ** 30 <= KWC < 2 ** 31 and 2 ** 30 <= KWK < 2 ** 31 and 2 ** 30 <= KWD < 2 ** 31
    s = -1 if inverted else 1
    v1 = [_q(f, V1) for f in f0]
    v2 = [_q(r, V2) for r in r0]
    ef = DISC_PHASE.frac + COEF_FRAC
    for k in range(n):
        cw, kw = core.step(*(x[k] for x in d))
        for b in range(batch):
            ie, qe, ip, qp, il, ql = (float(x[k, b]) for x in d)
            e = _q(float(costas_atan(ip, s * qp)), DISC_PHASE)
            tau = _q(float(dll_nelp(ie, qe, il, ql, 0.5)), DISC_CODE)
            if order == 3:
                v2[b] = _sat(v2[b] + _rs(e * K3, ef - V2.frac), V2)
                v1[b] = _sat(v1[b] + _rs(e * K2, ef - V1.frac) + _rs(v2[b] * KT, V2.frac + T_FRAC - V1.frac), V1)
            else:
                v1[b] = _sat(v1[b] + _rs(e * K2, ef - V1.frac), V1)
            f = _sat(v1[b] + _rs(e * K1, ef - V1.frac), V1)
            f16 = _rs(f, V1.frac - F16_FRAC)
            w_c = core.W_IF + s * _rs(f16 * KWC, F16_FRAC + 22)
            w_k = core.W_CHIP + _rs(f16 * KWK, F16_FRAC + 33) + _rs(tau * KWD, DISC_CODE.frac + 20)
            assert (int(cw[b]), int(kw[b])) == (w_c, w_k), (k, b)
            assert int(core.v1[b]) == v1[b] and int(core.v2[b]) == v2[b]
    # and the words are the float frequencies' words to within the quantisation
    fl = ChannelCore(FLOAT, FS, T, order, 15.0, 1.0, 0.5, 4.092e6, inverted, f0, r0)
    fx = ChannelCore(FixedArith(), FS, T, order, 15.0, 1.0, 0.5, 4.092e6, inverted, f0, r0)
    for k in range(n):
        c_f = fl.step(*(x[k] for x in d))
        c_x = fx.step(*(x[k] for x in d))
    wf = hz_to_word(c_f[0], FS)[0]
    assert np.max(np.abs(c_x[0] - wf)) <= 2     # open loop: integrated e quantisation


@pytest.mark.parametrize("fs", [5e6, 16.384e6])
@pytest.mark.parametrize("inverted", [False, True])
def test_carrier_word_within_bound_over_v1_range(fs, inverted):
    """At any Doppler V1 holds (+-60 kHz, its saturation at +-2^16 Hz) the fixed carrier and
    code words are the float frequencies' words to within the documented bound: carrier
    within 1/2 + 2^16 / fs + 2^(15 - c) LSB of f 2^32 / fs (so within 1 of the float word),
    code within 3/2 + 1/8 LSB. An int64 wrap of the word product misses by ~2^32 / 2^c."""
    f = np.array([-2.0 ** 16, -60000.0, -41_000.0, -10_700.0, -1.0, 0.0, 3.3, 10_700.0,
                  41_000.0, 60000.0, 2.0 ** 16 - 2.0 ** -31])
    if_hz = 4.092e6 if fs > 1e7 else 1.25e6
    fx = ChannelCore(FixedArith(), fs, T, 3, 15.0, 1.0, 0.5, if_hz, inverted, f, 0.0)
    fl = ChannelCore(FLOAT, fs, T, 3, 15.0, 1.0, 0.5, if_hz, inverted, f, 0.0)
    z, a = np.zeros(f.size), np.full(f.size, 100.0)
    cw, kw = fx.step(a, z, a, z, a, z)            # e = 0, tau = 0: the state's words
    assert fx.o.sat == {} and np.array_equal(fx.v1, [_q(x, V1) for x in f])
    fc, fk = fl.step(a, z, a, z, a, z)
    c = fx.CWC
    assert c == int(np.floor(np.log2(fs / 2)))
    exact_c = (if_hz + (-1 if inverted else 1) * f) * 2.0 ** 32 / fs
    bound = 0.5 + 2.0 ** 16 / fs + 2.0 ** (15 - c)
    assert bound < 0.53
    assert np.max(np.abs(cw - exact_c)) <= bound + 0.5      # and W_IF's own rounding
    assert np.max(np.abs((cw - fx.W_IF) - (-1 if inverted else 1) * f * 2.0 ** 32 / fs)) <= bound
    assert np.max(np.abs(cw - hz_to_word(fc, fs)[0])) <= 1
    assert np.max(np.abs(kw - fk * 2.0 ** 32 / fs)) <= 1.5 + 1 / 8
    assert np.max(np.abs(kw - hz_to_word(fk, fs)[0])) <= 2


def test_word_formats_raise_where_they_cannot_hold():
    assert word_coef_frac(2 ** 32 / 5e6, 2.0 ** 16, "carrier") == 21
    with pytest.raises(ValueError, match="sample rate too low"):
        word_coef_frac(2 ** 32 / 4e5, 2.0 ** 16, "carrier")
    with pytest.raises(ValueError, match="F16"):
        ChannelCore(FixedArith(), 4e5, T, 3, 15.0, 1.0, 0.5, 1e5)
    ChannelCore(FLOAT, 4e5, T, 3, 15.0, 1.0, 0.5, 1e5)          # the float form has no words
    with pytest.raises(ValueError, match="2\\^62"):
        check_products([("x", V2, 2 ** 23)])
    check_products([("x", V2, 2 ** 23 - 1)])
    with pytest.raises(ValueError, match="KT"):                # V2 at full range times 10 ms
        ChannelCore(FixedArith(), 5e6, 10e-3, 3, 15.0, 1.0, 0.5, 1.25e6)


def _closed(duration_s, n_trials, seed):
    tr = truth_for(aukf_patent_dynamics(q=0, jerk_g_per_s=5.0, jerk_start_s=0.5, jerk_duration_s=duration_s),
                   duration_s + 1.01)
    n = int(round((duration_s + 1.0) / T))
    fx = FixedArith()
    a = track_fast(tr, 45.0, n, shape=(n_trials,), seed=seed, arith=FLOAT)
    b = track_fast(tr, 45.0, n, shape=(n_trials,), seed=seed, arith=fx)
    return a, b, fx


def _check_closed(a, b, fx):
    assert fx.sat == {}
    assert np.all(cycle_slips(b.phase_err_cycles) == 0)
    dp = np.abs(a.phase_err_cycles - b.phase_err_cycles).max() * 360
    dc = np.abs(a.code_err_chips - b.code_err_chips).max()
    assert dp < PHASE_BOUND_DEG and dc < CODE_BOUND_CHIPS, (dp, dc)
    assert dp > 0          # the fixed form really quantises


def test_fixed_within_bound_of_float_closed_loop_short():
    _check_closed(*_closed(1.0, 8, 1))


@pytest.mark.slow
def test_fixed_within_bound_of_float_aukf_patent_jerk_10_s():
    _check_closed(*_closed(10.0, 8, 2))


@pytest.mark.parametrize("fs,doppler,order,inverted", [
    (12e6, 1234.5, 3, False), (2.046e6, 4900.0, 3, True),
    (5e6, 2e5, 2, False)])                                      # V1 saturates
def test_scalar_step_is_the_batch_step(fs, doppler, order, inverted):
    """One channel's step on Python ints (the closed loop's per-channel tracker) gives the
    bits, states and saturation counts of the numpy batch path, also where the formats
    saturate."""
    rng = np.random.default_rng(7)
    a, b = FixedArith(), FixedArith()
    one = ChannelCore(a, fs, T, order, 15.0, 1.0, 0.5, fs / 4, inverted, np.asarray(doppler),
                      np.asarray(50.0))
    bat = ChannelCore(b, fs, T, order, 15.0, 1.0, 0.5, fs / 4, inverted, np.asarray([doppler]),
                      np.asarray([50.0]))
    assert type(one.v1) is int
    for k in range(600):
        x = rng.integers(-2 ** 21, 2 ** 21, 6)
        if k % 37 == 0:
            x[2] = 0                 # I = 0: the Costas discriminator's edge
        if k % 41 == 0:
            x[:] = 0                 # no energy: the DLL's edge
        o1 = one.step(*(int(v) for v in x))
        o2 = bat.step(*(np.array([v]) for v in x))
        assert (o1[0], o1[1]) == (int(o2[0][0]), int(o2[1][0])), k
        assert (one.v1, one.v2) == (int(bat.v1[0]), int(bat.v2[0])), k
    assert a.sat == b.sat
    if fs == 5e6:
        assert a.sat                 # the case did saturate


def test_scalar_discriminators_are_the_array_ones():
    rng = np.random.default_rng(8)
    v = rng.integers(-3000, 3000, (500, 4)).astype(float)
    v[::13, 0] = 0.0
    v[::17] = 0.0
    e = costas_atan(v[:, 0], v[:, 1])
    p = pll_atan2(v[:, 0], v[:, 1])
    t = dll_nelp(v[:, 0], v[:, 1], v[:, 2], v[:, 3], 0.4)
    for k in range(v.shape[0]):
        i, q, il, ql = (int(x) for x in v[k])
        assert costas_atan(i, q) == e[k] and pll_atan2(i, q) == p[k]
        assert dll_nelp(i, q, il, ql, 0.4) == t[k]
