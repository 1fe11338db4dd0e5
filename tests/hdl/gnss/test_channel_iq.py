"""GNSS tracking channel with complex (I/Q) input: model == Amaranth simulation ==
Verilator, the sign convention on a synthetic signal, the width bound at full scale, errors."""
from dataclasses import replace

import numpy as np
import pytest

from _util import assert_lints_clean, gnss_stimulus as stimulus, needs_verilator, \
    verilator_sim  # tests/hdl/conftest.py
from cosim.backends.pysim import run_stream
from dsp.gnss.ca_code import ca_code_levels, ca_code_table
from hdl.gnss.channel import GnssChannel, GnssChannelArray, array_params
from hdl.gnss.model import GnssArrayModel, GnssChannelModel
from hdl.gnss.params import (REG_CARR_FREQ, REG_CODE_FREQ, REG_PRN, REG_SLEW, GnssChannelParams)
from hdl.model.bus import bus_writes
from hdl.model.nco import nco_full_tables

#: Reduced rate for the Amaranth simulation (2 samples per chip), complex input at a
#: negative complex IF (the wipe-off turns the other way than at a positive one).
SMALL_IQ = GnssChannelParams(fs_hz=2.046e6, if_hz=-0.3e6, el_spacing_samples=2, slew_bits=6,
                             carr_table_bits=6, lo_bits=3, fifo_depth=64, input="complex")
#: PocketSDR-like zero-IF front end: 4 MS/s, 2-bit I and Q.
ZIF = GnssChannelParams(fs_hz=4e6, if_hz=0.0, el_spacing_samples=2, input="complex")


def _model_run(p, channels, x, writes, ready, n_cycles, valid=None):
    cyc = None if valid is None else np.flatnonzero(valid)[:len(x)]
    m = GnssArrayModel(array_params(p, channels), channels) if channels > 1 \
        else GnssArrayModel(p)
    return m.run(x, writes, n_cycles=n_cycles, out_ready=ready, cycles=cyc)


def _sim_run(sim_or_dut, p, x, writes, ready, n_cycles, valid=None):
    """The HDL run: the I/Q pairs packed into the ``i`` payload (one stream, as for the
    real input)."""
    kw = dict(in_valid=valid, out_ready=ready, n_cycles=n_cycles,
              writes=bus_writes(writes, data_width=p.reg_data_width))
    words = p.pack_samples(x)
    if hasattr(sim_or_dut, "run"):
        return sim_or_dut.run(words, **kw)
    return run_stream(sim_or_dut, words, **kw)


def _assert_same(got, want):
    assert len(got.words) == len(want.words)
    np.testing.assert_array_equal(np.asarray(got.words, np.int64), want.words)
    np.testing.assert_array_equal(got.cycles, want.cycles)


# -- parameters, packing ---------------------------------------------------------------------

def test_widths_grow_one_bit_for_the_sum_of_two_products():
    real = GnssChannelParams()
    cplx = replace(real, input="complex")
    assert (real.iq_width, cplx.iq_width) == (5, 6)
    assert cplx.acc_width == real.acc_width + 1
    assert cplx.mixer.complex_input and cplx.mixer.drop_bits == 0
    assert cplx.latency == real.latency + 1          # the complex mixer's sum stage
    assert cplx.input_width == 2 * real.input_width == 4
    assert cplx.record_bits == real.record_bits + 6


@pytest.mark.parametrize("p", [SMALL_IQ, ZIF, replace(ZIF, adc_bits=1),
                               replace(ZIF, adc_bits=8, lo_bits=9),
                               replace(ZIF, adc_levels="odd")])
def test_per_sample_bound_over_the_whole_carrier_table(p):
    """``|xi cos + xq sin| <= 2**(a-1) (|cos| + |sin|) < 2**(iq_width-1)`` for every table
    entry, and the real path's width (one bit less) would not hold it: the extra bit is
    needed, not just safe."""
    cos_t, sin_t = nco_full_tables(p.nco)
    a = p.mixer_in_width
    worst = (1 << (a - 1)) * int(np.max(np.abs(cos_t) + np.abs(sin_t)))
    assert worst < 1 << (p.iq_width - 1)
    assert worst >= 1 << (p.iq_width - 2)


def test_pack_unpack_round_trip_and_shape_errors():
    p = SMALL_IQ
    x = np.array([[-2, 1], [1, -2], [0, -1], [-1, 0]])
    w = p.pack_samples(x)
    np.testing.assert_array_equal(w, [0b0110, 0b1001, 0b1100, 0b0011])
    np.testing.assert_array_equal(p.unpack_samples(w), x)
    with pytest.raises(ValueError, match=r"complex-input channel must be an \(n, 2\) array of "
                                         r"\(I, Q\) pairs, not shape \(4,\)"):
        GnssChannelModel(p).step(np.zeros(4, np.int64))
    with pytest.raises(ValueError, match=r"complex-input channel must be an \(n, 2\) array"
                                         r".*not shape \(4, 3\)"):
        GnssChannelModel(p).step(np.zeros((4, 3), np.int64))
    with pytest.raises(ValueError, match=r"real-input channel must be a 1-D array, not shape "
                                         r"\(4, 2\)"):
        GnssChannelModel(replace(p, input="real", if_hz=0.3e6)).step(np.zeros((4, 2), np.int64))
    with pytest.raises(ValueError, match=r"samples must be signed 2-bit in \[-2, 1\]"):
        GnssChannelModel(p).step(np.array([[0, 2]]))
    with pytest.raises(ValueError, match=r"I/Q input words are unsigned 4-bit"):
        p.unpack_samples([16])


@pytest.mark.parametrize("kw, msg", [
    (dict(input="iq"), r"GNSS channel input must be one of real, complex \(one real ADC "
                       r"stream, or I and Q\), not 'iq'"),
    (dict(input=None), r"GNSS channel input must be one of real, complex .*not None"),
    (dict(input="complex", if_hz=9e6), r"IF of a complex input must lie in \(-fs_hz/2, "
                                       r"fs_hz/2\) = \(-8.192e\+06, 8.192e\+06\) Hz, not 9000000.0"),
    (dict(if_hz=-1e6), r"IF must lie in the first Nyquist zone"),
])
def test_parameter_errors(kw, msg):
    with pytest.raises(ValueError, match=msg):
        GnssChannelParams(**kw)


# -- the sign convention on a synthetic signal (model) ----------------------------------------

def _prompt_power(p, x, carr_hz, prn):
    """Mean prompt power of records 2.. with the carrier word of ``carr_hz``."""
    m = GnssChannelModel(replace(p, prn=prn))
    recs = [p.record.unpack(v) for v in
            m.step(x, [(0, REG_CARR_FREQ, p.carr_word(carr_hz))]).values(p)][1:]
    return np.mean([r["ip"] ** 2 + r["qp"] ** 2 for r in recs]), recs


def test_positive_doppler_is_tracked_with_the_real_paths_word_sign():
    """``exp(+j 2 pi f t)`` (complex, zero IF) and ``cos 2 pi (IF + f) t`` (real) are both
    wiped off by the word of ``IF + f`` (strong correlation over the dumps), and not
    by the mirrored word; the spectrum-inverted ``I - jQ`` (PocketSDR) correlates on the
    mirrored word, which turning Q's sign (the file reader's ``--invert-spectrum``)
    undoes."""
    f_d, prn, n = 1500.0, 5, 6 * 4000
    t = np.arange(n)
    code = ca_code_levels(prn)[np.floor(t * 1.023e6 / 4e6).astype(np.int64) % 1023]
    ph = 2 * np.pi * f_d * t / 4e6 + 0.4
    rng = np.random.default_rng(21)
    z = code * np.exp(1j * ph) + rng.normal(0, 0.3, n) + 1j * rng.normal(0, 0.3, n)

    def q2(v):                       # 2-bit midrise ADC words
        return np.clip(np.floor(v * 1.5), -2, 1).astype(np.int64)

    iq = np.stack([q2(z.real), q2(z.imag)], axis=-1)
    good, recs = _prompt_power(ZIF, iq, +f_d, prn)
    bad, _ = _prompt_power(ZIF, iq, -f_d, prn)
    assert good > 50 * bad
    # The signal's code is aligned with the early replica (code phase 0 at sample 0):
    # E > P > L.
    pw = {a: recs[-1]["i" + a] ** 2 + recs[-1]["q" + a] ** 2 for a in "epl"}
    assert pw["e"] > 1.5 * pw["p"] > 1.5 * 1.5 * pw["l"]
    inv = np.stack([iq[:, 0], ~iq[:, 1]], axis=-1)   # I - jQ: value 2q+1 -> -(2q+1), q -> ~q
    assert _prompt_power(ZIF, inv, -f_d, prn)[0] > 50 * _prompt_power(ZIF, inv, +f_d, prn)[0]
    # The real path, IF 1 MHz, the same Doppler: the same word sign.
    pr = GnssChannelParams(fs_hz=4e6, if_hz=1e6, el_spacing_samples=2)
    xr = q2(code * np.cos(2 * np.pi * (1e6 + f_d) * t / 4e6 + 0.4) * 1.4
            + rng.normal(0, 0.3, n))
    assert _prompt_power(pr, xr, 1e6 + f_d, prn)[0] > 50 * _prompt_power(pr, xr, 1e6 - f_d,
                                                                          prn)[0]


# -- full scale: nothing overflows -------------------------------------------------------------

def _early_chips(p, n, slew):
    """The early replica's chip at each sample: the reset code word, and a hold of
    ``slew`` samples from the first dump boundary on (a slew written before it)."""
    acc, chip, hold, first = 0, 0, 0, True
    out = np.empty(n, np.int64)
    kw, mask = p.code_word(), (1 << p.code_phase_bits) - 1
    for k in range(n):
        out[k] = chip
        if hold:
            hold -= 1
            continue
        s = acc + kw
        acc = s & mask
        if s >> p.code_phase_bits:
            chip = 0 if chip == 1022 else chip + 1
            if chip == 0 and first:
                hold, first = slew, False
    return out


def _full_scale_input(p, n, word, slew):
    """I/Q words at full scale chosen per sample to drive the early arm's ``I`` as far
    negative as it goes: ``xi cos r``, ``xq sin r`` both ``-2**(a-1) |.|`` where the sign
    allows the ADC's negative end (``r`` the early replica at the reset code word and PRN,
    ``cos, sin`` the table entries the carrier word ``word`` reaches)."""
    cos_t, sin_t = nco_full_tables(p.nco)
    k = np.arange(n, dtype=np.int64)
    addr = ((k * word) & ((1 << p.carr_phase_bits) - 1)) >> p.nco.trunc_bits
    r = 1 - 2 * ca_code_table()[p.prn][_early_chips(p, n, slew)].astype(np.int64)
    lo, hi = -(1 << (p.adc_bits - 1)), (1 << (p.adc_bits - 1)) - 1
    xi = np.where(cos_t[addr] * r > 0, lo, hi)
    xq = np.where(sin_t[addr] * r > 0, lo, hi)
    return np.stack([xi, xq], axis=-1)


def test_full_scale_input_pysim_matches_model():
    """Adversarial full-scale I/Q (every sample at the mixer's worst case for the early arm,
    the carrier word visiting every table address), a whole dump lengthened by the longest
    slew: the hardware's mixer and accumulators give the model's exact (unwrapped) sums."""
    p = SMALL_IQ
    word = (1 << p.carr_phase_bits) // 8 + 12345
    p = replace(p, if_hz=float(word) * p.fs_hz / (1 << p.carr_phase_bits))
    assert p.carr_word(p.if_hz) == word
    n = 2 * 2046 + (1 << p.slew_bits) + 100
    slew = (1 << p.slew_bits) - 1
    x = _full_scale_input(p, n, word, slew)
    writes = [(5, REG_SLEW, slew)]
    r = GnssChannelModel(p).step(x, writes)
    ie = r.fields[:, 0]
    cos_t, sin_t = nco_full_tables(p.nco)
    a = p.mixer_in_width
    # The first record is the dump from reset to the first boundary (all samples worst
    # case); the second the long one (slewed).
    assert len(ie) >= 2
    peak = 1 << (a - 1)
    assert ie[1] <= -(peak - 1) * np.mean(np.abs(cos_t) + np.abs(sin_t)) * (2046 + slew)
    assert np.abs(r.fields[:, :6]).max() < 1 << (p.acc_width - 1)
    n_cycles = n + 60
    want = _model_run(p, 1, x, writes, None, n_cycles)
    got = _sim_run(GnssChannel(p), p, x, writes, None, n_cycles)
    _assert_same(got, want)
    assert p.record.unpack(want.records[1])["ie"] == ie[1]      # not wrapped


# -- model == Amaranth simulation == Verilator -----------------------------------------------

def test_pysim_matches_model_with_writes_and_backpressure():
    p = SMALL_IQ
    n = 3 * 2046 + 300
    x, writes, ready = stimulus(p, n, seed=1, n_writes=2)
    writes += [(5, REG_PRN, 7), (7, REG_SLEW, 9)]
    n_cycles = n + 60
    want = _model_run(p, 1, x, writes, ready, n_cycles)
    assert len(want.records) >= 3
    got = _sim_run(GnssChannel(p), p, x, writes, ready, n_cycles)
    _assert_same(got, want)


@pytest.mark.parametrize("p", [replace(SMALL_IQ, adc_levels="odd"),
                               replace(SMALL_IQ, input="real", if_hz=0.3e6, adc_levels="odd")])
def test_odd_levels_pysim_matches_model(p):
    """Odd ADC levels (a word q enters the mixer as 2q+1, one bit wider), complex and real
    input: the Amaranth simulation gives the model's records, and the model's prompts are
    those of the odd-level samples (the 2-bit words' two's-complement DC is gone)."""
    n = 2 * 2046 + 300
    x, writes, ready = stimulus(p, n, seed=11, n_writes=2, pairs=True)
    if not p.complex_input:
        x = x[:, 0]
    assert p.mixer_in_width == p.adc_bits + 1
    assert replace(p, adc_levels="twos").mixer_in_width == p.adc_bits
    n_cycles = n + 60
    want = _model_run(p, 1, x, writes, ready, n_cycles)
    assert len(want.records) >= 2
    got = _sim_run(GnssChannel(p), p, x, writes, ready, n_cycles)
    _assert_same(got, want)
    # a constant word 0 is the level +1 when odd, nothing when two's complement
    z = np.zeros((4 * 2046,) + ((2,) if p.complex_input else ()), np.int64)
    acc = ("ie", "qe", "ip", "qp", "il", "ql")
    pt = replace(p, adc_levels="twos")
    odd = [p.record.unpack(v) for v in GnssChannelModel(p).step(z).values(p)]
    twos = [pt.record.unpack(v) for v in GnssChannelModel(pt).step(z).values(pt)]
    assert len(odd) >= 3 and len(twos) == len(odd)
    assert any(r[k] != 0 for r in odd for k in acc)
    assert all(r[k] == 0 for r in twos for k in acc)


def test_model_chunks_give_the_same_records():
    p = SMALL_IQ
    n = 4 * 2046
    x, writes, _ = stimulus(p, n, seed=2, n_writes=3)
    whole = GnssChannelModel(p).step(x, writes)
    m = GnssChannelModel(p)
    parts = []
    cuts = [0, 1, 700, 2500, 2501, 6000, n]
    for a, b in zip(cuts[:-1], cuts[1:]):
        parts.append(m.step(x[a:b], [w for w in writes if a <= w[0] < b]))
    np.testing.assert_array_equal(np.concatenate([r.cycles for r in parts]), whole.cycles)
    np.testing.assert_array_equal(np.concatenate([r.fields for r in parts]), whole.fields)
    assert len(whole.cycles) >= 3


def test_array_pysim_matches_model():
    p = SMALL_IQ
    n = 2 * 2046 + 200
    x, writes, ready = stimulus(p, n, seed=5, n_writes=1, ch=3)
    writes += [(30, 4 * 2 + REG_SLEW, 5), (40, 4 * 1 + REG_CODE_FREQ, p.code_word(1.0231e6))]
    n_cycles = n + 80
    want = _model_run(p, 3, x, writes, ready, n_cycles)
    assert len(want.records) >= 5 and not want.dropped.any()
    got = _sim_run(GnssChannelArray(p, 3), p, x, writes, ready, n_cycles)
    _assert_same(got, want)


@needs_verilator
def test_verilator_small_with_adc_gaps_matches_model():
    p = SMALL_IQ
    n = 5 * 2046
    x, writes, ready = stimulus(p, n, seed=3, n_writes=4)
    valid = np.random.default_rng(33).random(2 * n) < 0.9
    n_cycles = int(np.flatnonzero(valid)[n - 1]) + 60
    writes = [w for w in writes if w[0] < n_cycles]
    want = _model_run(p, 1, x, writes, ready, n_cycles, valid)
    assert len(want.records) >= 4
    got = _sim_run(verilator_sim(GnssChannel(p), "gnss_channel_iq_small"), p, x, writes,
                   ready, n_cycles, valid)
    _assert_same(got, want)


@needs_verilator
@pytest.mark.parametrize("kw", [dict(adc_bits=1, dump_epochs=2),
                                dict(adc_bits=4, lo_bits=5, el_spacing_samples=4),
                                dict(adc_levels="odd")])
def test_verilator_variants_match_model(kw):
    """1-bit I and Q with 2-epoch dumps; 4-bit I and Q, wider LO, wider spacing; 2-bit
    words as odd levels."""
    p = replace(SMALL_IQ, **kw)
    n = 5 * 2046
    x, writes, ready = stimulus(p, n, seed=7, n_writes=3)
    want = _model_run(p, 1, x, writes, ready, n + 60)
    assert len(want.records) >= 2
    name = "gnss_channel_iq_" + "_".join(f"{k}{v}" for k, v in kw.items())
    got = _sim_run(verilator_sim(GnssChannel(p), name), p, x, writes, ready, n + 60)
    _assert_same(got, want)


@needs_verilator
def test_verilator_zero_if_front_end_matches_model():
    """4 MS/s zero IF (the PocketSDR I/Q front end's rate): 8 epochs, writes of every
    register, a stalling DSP."""
    p = ZIF
    n = 8 * 4000
    x, writes, ready = stimulus(p, n, seed=4, n_writes=4, ready_p=0.3)
    want = _model_run(p, 1, x, writes, ready, n + 60)
    assert len(want.records) >= 7
    got = _sim_run(verilator_sim(GnssChannel(p), "gnss_channel_iq_4m"), p, x, writes, ready,
                   n + 60)
    _assert_same(got, want)


@needs_verilator
def test_array12_verilator_matches_model():
    p = ZIF
    n = 4 * 4000
    x, writes, ready = stimulus(p, n, seed=6, n_writes=3, ready_p=0.5, ch=12)
    want = _model_run(p, 12, x, writes, ready, n + 200)
    assert len(want.records) >= 30 and not want.dropped.any()
    got = _sim_run(verilator_sim(GnssChannelArray(p, 12), "gnss_channel_iq_4m_array12"), p, x,
                   writes, ready, n + 200)
    _assert_same(got, want)


def test_verilog_lint_clean():
    p = replace(GnssChannelParams(), input="complex", if_hz=0.0)
    assert_lints_clean(GnssChannel(p), "gnss_channel_iq")
    assert_lints_clean(GnssChannelArray(p, 12), "gnss_channel_array12_iq")
    assert_lints_clean(GnssChannel(replace(SMALL_IQ, adc_bits=1)), "gnss_channel_iq_1bit")
