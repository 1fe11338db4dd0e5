"""GNSS tracking channel: model == Amaranth simulation == Verilator, parameter errors."""
import numpy as np
import pytest

from _util import assert_lints_clean, gnss_stimulus as stimulus, needs_verilator, \
    verilator_sim  # tests/hdl/conftest.py
from cosim.backends.pysim import run_stream
from dsp.gnss.ca_code import ca_code_levels
from hdl.gnss.channel import GnssChannel, GnssChannelArray, array_params
from hdl.gnss.model import GnssArrayModel, GnssChannelModel
from hdl.model.bus import bus_writes
from hdl.gnss.params import (REG_CARR_FREQ, REG_CODE_FREQ, REG_PRN, REG_SLEW, GnssChannelParams,
                             dump_epochs_for)

#: Reduced rate for the Amaranth simulation: 2 samples per chip, 2046 samples per epoch.
SMALL = GnssChannelParams(fs_hz=2.046e6, if_hz=0.3e6, el_spacing_samples=2, slew_bits=6,
                          carr_table_bits=6, lo_bits=3, fifo_depth=64)


def run_pysim(dut, x, writes, ready, n_cycles, data_width):
    return run_stream(dut, x, out_ready=ready, n_cycles=n_cycles,
                      writes=bus_writes(writes, data_width=data_width))


def test_pysim_matches_model_with_writes_and_backpressure():
    p = SMALL
    n = 3 * 2046 + 300
    x, writes, ready = stimulus(p, n, seed=1, n_writes=2)
    # A write right at the start, one in every register, so every boundary sees one.
    writes += [(5, REG_PRN, 7), (7, REG_SLEW, 9)]
    n_cycles = n + 60
    want = GnssArrayModel(p).run(x, writes, n_cycles=n_cycles, out_ready=ready)
    assert len(want.records) >= 3
    got = run_pysim(GnssChannel(p), x, writes, ready, n_cycles, p.reg_data_width)
    np.testing.assert_array_equal(got.words, want.words)
    np.testing.assert_array_equal(got.cycles, want.cycles)


def test_model_chunks_give_the_same_records():
    p = SMALL
    n = 4 * 2046
    x, writes, _ = stimulus(p, n, seed=2, n_writes=3)
    whole = GnssChannelModel(p).step(x, writes)
    m = GnssChannelModel(p)
    parts = []
    cuts = [0, 1, 700, 2500, 2501, 6000, n]
    for a, b in zip(cuts[:-1], cuts[1:]):
        # Writes handed over in the chunk where they happen.
        w = [wr for wr in writes if a <= wr[0] < b]
        parts.append(m.step(x[a:b], w))
    np.testing.assert_array_equal(np.concatenate([r.cycles for r in parts]), whole.cycles)
    np.testing.assert_array_equal(np.concatenate([r.fields for r in parts]), whole.fields)


def test_correlation_peak_and_register_effects():
    """Physical sanity on the default front end: a PRN-3 signal aligned with the early
    replica correlates E > P > L; after a PRN write the dumps decorrelate; a slew of
    d samples moves the peak onto the prompt; the epoch counter counts."""
    p = GnssChannelParams()
    per = round(p.fs_hz * 1e-3)                     # samples per 1 ms code period
    fs, n = p.fs_hz, per * 7
    t = np.arange(n)
    code = ca_code_levels(3)
    sig = code[(t * 1023 // per) % 1023] * np.cos(2 * np.pi * p.if_hz * t / fs + 0.3)
    x = np.clip(np.floor(sig * 1.5 + 0.5), -2, 1).astype(np.int64)
    m = GnssChannelModel(replace_prn(p, 3))
    # Boundary 1 (end of epoch 1): a slew of a period minus d samples advances the replica
    # by d, putting the prompt on the signal (epoch 2 is the long one); the PRN-4 write
    # lands after boundary 3, so epoch 5 is the first with the wrong code.
    writes = [(100, REG_SLEW, per - p.half_spacing), (per * 4 + 100, REG_PRN, 4)]
    recs = [p.record.unpack(v) for v in m.step(x, writes).values(p)]
    mag = [{a: abs(r["i" + a]) + abs(r["q" + a]) for a in "epl"} for r in recs]
    assert [r["epoch"] for r in recs] == list(range(1, len(recs) + 1))
    assert mag[0]["e"] > mag[0]["p"] > mag[0]["l"]
    # Epoch 3 (after the slew): prompt on the peak, early and late equal.
    assert mag[2]["p"] > 1.2 * max(mag[2]["e"], mag[2]["l"])
    assert abs(mag[2]["e"] - mag[2]["l"]) < 0.05 * mag[2]["p"]
    assert mag[4]["p"] < 0.2 * mag[2]["p"]


def replace_prn(p, prn):
    from dataclasses import replace
    return replace(p, prn=prn)


@pytest.mark.parametrize("kw, msg", [
    (dict(prn=0), r"PRN must be an integer in \[1, 32\], not 0"),
    (dict(prn=33), r"PRN must be an integer in \[1, 32\], not 33"),
    (dict(dump_epochs=1.5), r"dump length must be a whole number of code periods .*not 1.5"),
    (dict(dump_epochs=0), r"GNSS dump_epochs must be an integer in \[1, 64\], not 0"),
    (dict(record_words=4), r"GNSS record of 212 bits is wider than the FIFO record "
                           r"\(record_words \* fifo_width = 4 \* 51 = 204 bits\)"),
    (dict(adc_bits=0), r"GNSS adc_bits must be an integer in \[1, 16\], not 0"),
    (dict(adc_bits=17), r"GNSS adc_bits must be an integer in \[1, 16\], not 17"),
    (dict(fs_hz=1e6), r"sample rate fs_hz must be >= the C/A signal bandwidth 2.046e\+06 Hz, "
                      r"not 1000000.0"),
    (dict(if_hz=9e6), r"IF must lie in the first Nyquist zone \[0, fs_hz/2 = 8.192e\+06\) Hz, "
                      r"not 9000000.0"),
    (dict(fs_hz=float("nan")), r"fs_hz must be a finite number, not nan"),
    (dict(el_spacing_samples=3), r"el_spacing_samples .* must be an even integer in "
                                 r"\[2, 128\], not 3"),
    (dict(carr_phase_bits=40), r"carr_phase_bits must be an integer in \[8, 32\], not 40"),
])
def test_parameter_errors(kw, msg):
    with pytest.raises(ValueError, match=msg):
        GnssChannelParams(**kw)


def test_dump_length_and_write_errors():
    assert dump_epochs_for(0.02) == 20
    with pytest.raises(ValueError, match=r"dump length must be a whole number \(>= 1\) of "
                                         r"1 ms code periods, not 0.0015 s"):
        dump_epochs_for(0.0015)
    p = GnssChannelParams()
    with pytest.raises(ValueError, match=r"GNSS register prn \(address 2\) takes unsigned "
                                         r"6-bit words in \[1, 32\], not 40"):
        GnssChannelModel(p).step(np.zeros(10, np.int64), [(1, REG_PRN, 40)])
    with pytest.raises(ValueError, match=r"GNSS register slew \(address 3\) takes unsigned "
                                         r"16-bit words in \[0, 65535\], not 70000"):
        GnssChannelModel(p).step(np.zeros(10, np.int64), [(1, REG_SLEW, 70000)])
    with pytest.raises(ValueError, match=r"GNSS register address must be one of 0, 1, 2, 3, "
                                         r"not 4"):
        GnssChannelModel(p).step(np.zeros(10, np.int64), [(1, 4, 0)])
    with pytest.raises(ValueError, match=r"GnssChannel needs a GnssChannelParams, not 3"):
        GnssChannel(3)
    with pytest.raises(ValueError, match=r"channel array needs channels in \[1, 64\], not 0"):
        GnssChannelArray(p, 0)


def test_widths_are_derived():
    p = GnssChannelParams()
    assert p.iq_width == 5                       # 2-bit ADC x 4-bit LO, full precision
    assert p.max_dump_samples == 16386 + 65535   # 1 ms at 1.023 Mcps - 100 Hz, max slew
    assert p.acc_width == 5 + 17
    assert p.record_bits == 6 * 22 + 16 + 32 + 32
    assert p.fifo.record_words == 5
    assert GnssChannelParams(dump_epochs=20, slew_bits=8).acc_width == 5 + 19


# -- Verilator, arrays, lint ------------------------------------------------------------------


def _sample_cycles(valid, n):
    c = np.flatnonzero(valid)[:n]
    assert c.size == n
    return c


def _model_run(p, channels, x, writes, ready, n_cycles, valid=None):
    cyc = None if valid is None else _sample_cycles(valid, len(x))
    m = GnssArrayModel(p, channels) if channels > 1 else GnssArrayModel(p)
    return m.run(x, writes, n_cycles=n_cycles, out_ready=ready, cycles=cyc)


def _sim_run(sim_or_dut, x, writes, ready, n_cycles, p, valid=None):
    kw = dict(in_valid=valid, out_ready=ready, n_cycles=n_cycles,
              writes=bus_writes(writes, data_width=p.reg_data_width))
    if hasattr(sim_or_dut, "run"):
        return sim_or_dut.run(x, **kw)
    return run_stream(sim_or_dut, x, **kw)


def _assert_same(got, want):
    np.testing.assert_array_equal(np.asarray(got.words, np.int64), want.words)
    np.testing.assert_array_equal(got.cycles, want.cycles)


@needs_verilator
def test_verilator_small_with_adc_gaps_matches_model():
    p = SMALL
    n = 5 * 2046
    x, writes, ready = stimulus(p, n, seed=3, n_writes=4)
    rng = np.random.default_rng(33)
    valid = rng.random(2 * n) < 0.9
    n_cycles = int(_sample_cycles(valid, n)[-1]) + 60
    writes = [w for w in writes if w[0] < n_cycles]
    want = _model_run(p, 1, x, writes, ready, n_cycles, valid)
    assert len(want.records) >= 4
    got = _sim_run(verilator_sim(GnssChannel(p), "gnss_channel_small"), x, writes, ready,
                   n_cycles, p, valid)
    _assert_same(got, want)


@needs_verilator
def test_verilator_default_front_end_matches_model():
    """Default parameters (16.384 MS/s, 2-bit ADC, 1 ms dumps): 8 epochs, writes of every
    register mid-run, a DSP that stalls."""
    p = GnssChannelParams()
    n = 8 * 16368
    x, writes, ready = stimulus(p, n, seed=4, n_writes=4, ready_p=0.3)
    n_cycles = n + 60
    want = _model_run(p, 1, x, writes, ready, n_cycles)
    assert len(want.records) >= 7
    got = _sim_run(verilator_sim(GnssChannel(p), "gnss_channel"), x, writes, ready,
                   n_cycles, p)
    _assert_same(got, want)


def test_array_pysim_matches_model():
    """3 channels in step (same reset words: their records collide at the arbiter), writes
    to different channels mid-run."""
    p = SMALL
    n = 2 * 2046 + 200
    x, writes, ready = stimulus(p, n, seed=5, n_writes=1, ch=3)
    writes += [(30, 4 * 2 + REG_SLEW, 5), (40, 4 * 1 + REG_CODE_FREQ, p.code_word(1.0231e6))]
    n_cycles = n + 80
    want = _model_run(array_params(p, 3), 3, x, writes, ready, n_cycles)
    assert len(want.records) >= 5 and not want.dropped.any()
    got = _sim_run(GnssChannelArray(p, 3), x, writes, ready, n_cycles, p)
    _assert_same(got, want)
    chans = [array_params(p, 3).record.unpack(v)["channel"] for v in want.records]
    assert chans[:3] == [0, 1, 2]     # the first dumps coincide: granted in channel order


@needs_verilator
def test_array12_default_verilator_matches_model():
    p = GnssChannelParams()
    n = 4 * 16368
    x, writes, ready = stimulus(p, n, seed=6, n_writes=3, ready_p=0.5, ch=12)
    n_cycles = n + 200
    want = _model_run(array_params(p, 12), 12, x, writes, ready, n_cycles)
    assert len(want.records) >= 30 and not want.dropped.any()
    got = _sim_run(verilator_sim(GnssChannelArray(p, 12), "gnss_channel_array12"), x, writes,
                   ready, n_cycles, p)
    _assert_same(got, want)


def test_verilog_lint_clean():
    assert_lints_clean(GnssChannel(GnssChannelParams()), "gnss_channel")
    assert_lints_clean(GnssChannelArray(SMALL, 3), "gnss_channel_array3")


@needs_verilator
@pytest.mark.parametrize("kw", [dict(adc_bits=1, dump_epochs=2), dict(adc_bits=4, lo_bits=5,
                                                                       el_spacing_samples=4)])
def test_verilator_variants_match_model(kw):
    """1-bit ADC with 2-epoch dumps; 4-bit ADC, wider LO, wider spacing (reduced rate)."""
    from dataclasses import replace
    p = replace(SMALL, **kw)
    n = 5 * 2046
    x, writes, ready = stimulus(p, n, seed=7, n_writes=3)
    n_cycles = n + 60
    want = _model_run(p, 1, x, writes, ready, n_cycles)
    assert len(want.records) >= 2
    name = "gnss_channel_" + "_".join(f"{k}{v}" for k, v in kw.items())
    got = _sim_run(verilator_sim(GnssChannel(p), name), x, writes, ready, n_cycles, p)
    _assert_same(got, want)


@needs_verilator
def test_closed_loop_model_writes_replayed_on_verilator():
    """A toy DSP closes a code loop on the model, chunk by chunk (each record's E-L nudges
    the code word, written 200 cycles after the record leaves the FIFO); the same writes
    replayed on Verilator give the same FIFO words on the same cycles."""
    p = SMALL
    spe = 2046
    n = 6 * spe
    t = np.arange(n)
    sig = ca_code_levels(1)[((t + 1) // 2) % 1023] * np.cos(2 * np.pi * p.if_hz * t / p.fs_hz)
    x = np.clip(np.floor(sig * 1.2 + np.random.default_rng(8).normal(0, 0.5, n)), -2, 1
                ).astype(np.int64)
    m = GnssChannelModel(p)
    writes, recs = [], []
    word = p.code_word()
    handed = 0
    for k in range(0, n, 500):          # 500-sample chunks, as a streaming pipeline would
        # Writes decided in the last chunk, handed over once (a write only has to reach the
        # model before the dump boundary that applies it).
        r = m.step(x[k:k + 500], writes[handed:])
        handed = len(writes)
        for v, c in zip(r.values(p), r.cycles):
            d = p.record.unpack(v)
            e = abs(d["ie"]) + abs(d["qe"]) - abs(d["il"]) - abs(d["ql"])
            word += int(np.sign(e)) * 1000
            writes.append((int(c) + 200, REG_CODE_FREQ, word))
            recs.append(v)
    writes = [w for w in writes if w[0] < n]
    assert len(writes) >= 4
    want = _model_run(p, 1, x, writes, None, n + 60)
    assert want.records == recs
    got = _sim_run(verilator_sim(GnssChannel(p), "gnss_channel_small"), x, writes, None,
                   n + 60, p)
    _assert_same(got, want)


@pytest.mark.slow
@needs_verilator
def test_verilator_default_front_end_long_run():
    """200 ms of the default front end, 40 register writes, a slow DSP: Verilator == model."""
    p = GnssChannelParams()
    n = 200 * 16368
    x, writes, ready = stimulus(p, n, seed=9, n_writes=10, ready_p=0.2)
    want = _model_run(p, 1, x, writes, ready, n + 60)
    assert len(want.records) >= 150
    got = _sim_run(verilator_sim(GnssChannel(p), "gnss_channel"), x, writes, ready, n + 60, p)
    _assert_same(got, want)


@pytest.mark.synth
@pytest.mark.slow
def test_synth_one_channel_meets_100mhz():
    from cosim.tools.synth import synth, yowasp_available
    if not yowasp_available():
        pytest.skip("YoWASP yosys/nextpnr not installed")
    from hdl.gnss.channel import gnss_top
    r = synth(gnss_top(1), name="gnss_channel_1", target_mhz=100)
    assert r["timing_met"] and r["fmax_mhz"] >= 100, r["fmax_mhz"]


def test_array_model_chunks_give_the_same_records():
    """12 channels in step (every dump collides at the arbiter), chunks cut anywhere, even
    inside a collision: the same FIFO input records on the same cycles as one step."""
    p = array_params(SMALL, 12)
    n = 3 * 2046
    x, writes, _ = stimulus(p, n, seed=10, n_writes=2, ch=12)
    m = GnssArrayModel(p, 12)
    c1, v1 = m.step(x, writes)
    c2, v2 = m.flush()
    whole_c, whole_v = np.concatenate([c1, c2]), v1 + v2
    m = GnssArrayModel(p, 12)
    got_c, got_v = [], []
    cuts = [0, 2040, 2047, 2050, 4100, n]
    for a, b in zip(cuts[:-1], cuts[1:]):
        c, v = m.step(x[a:b], [w for w in writes if a <= w[0] < b])
        got_c.append(c)
        got_v += v
    c, v = m.flush()
    np.testing.assert_array_equal(np.concatenate(got_c + [c]), whole_c)
    assert got_v + v == whole_v
    assert len(whole_v) >= 24


def test_check_stream_without_writes():
    """The public check (cosim.testing.check_stream) on the channel at its reset registers,
    with a stalling reader: pysim and Verilator against the model, words and cycles."""
    from cosim.testing import check_stream
    p = SMALL
    n = 2 * 2046 + 100
    x, _, ready = stimulus(p, n, seed=11, ready_p=0.4)
    n_cycles = n + 60

    def model(s):
        r = GnssArrayModel(p).run(s, (), n_cycles=n_cycles, out_ready=ready)
        return r.words, r.cycles

    check_stream(GnssChannel(p), model, x, ready=ready[:n_cycles], n_cycles=n_cycles,
                 name="gnss_channel_small")


def test_write_in_the_boundary_cycle_waits_for_the_next_boundary():
    """Reduced rate, exact 2 samples/chip: the generator's first epoch ends at sample 2045
    (cycle 2045). A slew written in cycle 2044 delays the 2nd dump; written in 2045 (the
    boundary cycle itself) it delays the 3rd. pysim agrees on the corner case."""
    p = SMALL
    n = 3 * 2046 + 40
    x = np.random.default_rng(12).integers(-2, 2, n)

    def dumps(c):
        return GnssChannelModel(p).step(x, [(c, REG_SLEW, 5)]).cycles

    base = GnssChannelModel(p).step(x).cycles
    np.testing.assert_array_equal(np.diff(base), [2046, 2046])
    np.testing.assert_array_equal(dumps(2044) - base, [0, 5, 5])
    np.testing.assert_array_equal(dumps(2045) - base, [0, 0, 5][:len(dumps(2045))])
    writes = [(2045, REG_SLEW, 5), (2044, REG_PRN, 9)]
    want = GnssArrayModel(p).run(x, writes, n_cycles=n + 60)
    got = run_pysim(GnssChannel(p), x, writes, None, n + 60, p.reg_data_width)
    np.testing.assert_array_equal(got.words, want.words)
    np.testing.assert_array_equal(got.cycles, want.cycles)


@pytest.mark.parametrize("parallel", [False, True])
def test_array_bank_is_its_channels_one_by_one(parallel):
    """The one compiled call over all channels (hdl.gnss.kernel.array_kernel, and its
    threaded form) gives every channel the records and final state of that channel run
    alone with its own writes, chunk by chunk."""
    from hdl.gnss.model import ChannelBank
    p = array_params(SMALL, 12)
    n = 4 * 2046 + 77
    x, writes, _ = stimulus(p, n, seed=12, n_writes=3, ch=12)
    bank = ChannelBank(p, 12, parallel=parallel)
    alone = [GnssChannelModel(p) for _ in range(12)]
    cuts = [0, 1000, 2046, 2047, 5000, n]
    for a, b in zip(cuts[:-1], cuts[1:]):
        w = [(c, addr, v) for c, addr, v in writes if a <= c < b]
        bank.add_writes((addr // 4, c, addr % 4, v) for c, addr, v in w)
        cyc, fields, chans = bank.advance(*bank.prepare(x[a:b], None))
        for ch, m in enumerate(alone):
            r = m.step(x[a:b], [(c, addr % 4, v) for c, addr, v in w if addr // 4 == ch])
            np.testing.assert_array_equal(cyc[chans == ch], r.cycles)
            np.testing.assert_array_equal(fields[chans == ch], r.fields)
    assert len({addr // 4 for _, addr, _ in writes}) >= 8     # most channels were written
    for ch, m in enumerate(alone):
        np.testing.assert_array_equal(bank.state[ch], m.state)
        np.testing.assert_array_equal(bank.ring[ch], m.ring)
