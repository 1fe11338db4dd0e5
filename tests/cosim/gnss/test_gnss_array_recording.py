"""The 12-channel GNSS array on the two real PocketSDR recordings (tests/data/gnss): the
real-IF file on the real-input array, the zero-IF I/Q file on the complex-input array.
Every channel is handed over to an acquired satellite through the register bus
(:func:`cosim.gnss.handover.array_handover_writes`); the bit-exact model, Verilator and the
Amaranth simulation give the same FIFO words on the same cycles, and the model's prompt
correlations show the satellites are being correlated (prompt power far above the noise
floor of a PRN that is not in view, prompt above early and late).

The satellites are what ``python -m cosim gnss-acquire`` finds in the windows (PRN, Doppler
Hz, code phase chips, C/N0 dB-Hz as it prints them)::

    python -m cosim gnss-acquire --file tests/data/gnss/L1_20211125_004000_12MHz_I_70ms.bin \\
        --format int8 --fs-hz 12e6 --if-hz 3e6
    python -m cosim gnss-acquire --file tests/data/gnss/L1_20211202_084700_4MHz_IQ_70ms.bin \\
        --format int8-iq --fs-hz 4e6 --if-hz 0 --invert-spectrum
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.backends.pysim import run_stream
from cosim.backends.verilator import VerilatorStreamSim
from cosim.backends.verilator_harness import verilator_available
from cosim.gnss.files import SampleFile
from cosim.gnss.handover import Satellite, array_handover_writes
from hdl.gnss.channel import GnssChannelArray, array_params
from hdl.gnss.model import GnssArrayModel
from hdl.gnss.params import GnssChannelParams
from hdl.model.bus import bus_writes

needs_verilator = pytest.mark.skipif(not verilator_available(),
                                     reason="Verilator, make or a C++ compiler not on PATH")

DATA = Path(__file__).resolve().parents[2] / "data" / "gnss"
CHANNELS = 12
#: A PRN in view in neither recording (the search refuses it in both): the noise floor.
ABSENT_PRN = 1

#: Verilog name of each array (the I/Q one is tests/hdl/gnss/test_channel_iq.py's 4 MS/s
#: zero-IF array: one Verilator build for both).
VERILOG_NAMES = {"real_12M": "gnss_channel_12m_array12", "iq_4M": "gnss_channel_iq_4m_array12"}
#: name -> (file, format, channel parameters, spectrum inverted, acquired satellites
#: (prn, Doppler, code phase, C/N0)).
RECORDINGS = {
    "real_12M": ("L1_20211125_004000_12MHz_I_70ms.bin", "int8",
                 GnssChannelParams(fs_hz=12e6, if_hz=3e6, el_spacing_samples=6), False,
                 ((2, -2749.6, 568.800, 39.8), (5, 146.0, 544.673, 49.2),
                  (11, -3274.1, 84.973, 43.5), (13, -242.4, 511.156, 49.3),
                  (15, 1743.8, 228.728, 49.0), (18, 3229.9, 462.000, 41.1),
                  (20, -1347.8, 326.363, 47.8), (24, 4240.8, 697.729, 35.5),
                  (28, 2332.3, 654.490, 36.2), (29, -2010.3, 249.387, 39.5),
                  (30, -1862.9, 620.676, 46.4))),
    "iq_4M": ("L1_20211202_084700_4MHz_IQ_70ms.bin", "int8-iq",
              GnssChannelParams(fs_hz=4e6, if_hz=0.0, el_spacing_samples=2, input="complex"),
              True,
              ((3, -1431.8, 111.515, 32.4), (4, 3233.0, 64.935, 36.6),
               (16, 2577.7, 10.839, 46.2), (18, 2724.1, 398.924, 39.7),
               (25, -2783.9, 882.724, 36.1), (26, 648.2, 102.525, 46.5),
               (29, -2215.2, 600.293, 48.7), (31, -203.1, 726.613, 47.6),
               (32, -3280.8, 315.629, 43.8))),
}


def _setup(name, ms):
    """(array params, ADC samples of the first ``ms`` ms, bus writes, satellites per
    channel, C/N0 per channel): the satellites in order, then the strongest again until
    every channel has one."""
    fname, fmt, p, inverted, sats = RECORDINGS[name]
    f = SampleFile(DATA / fname, fmt, p.fs_hz, p.if_hz, inverted)
    x = f.words(0, ms * f.samples_per_ms)
    by_cn0 = sorted(sats, key=lambda s: -s[3])
    chans = list(sats) + [by_cn0[k % len(by_cn0)] for k in range(CHANNELS - len(sats))]
    sat = [Satellite(*s[:3]) for s in chans]
    writes = array_handover_writes(p, sat, inverted=f.doppler_sign_inverted)
    return array_params(p, CHANNELS), x, writes, sat, [s[3] for s in chans]


def _model(ap, x, writes, n_cycles):
    return GnssArrayModel(ap, CHANNELS).run(x, writes, n_cycles=n_cycles)


def _hdl_run(sim_or_dut, ap, x, writes, n_cycles):
    kw = dict(n_cycles=n_cycles, writes=bus_writes(writes, data_width=ap.reg_data_width))
    words = ap.pack_samples(x)
    if hasattr(sim_or_dut, "run"):
        return sim_or_dut.run(words, **kw)
    return run_stream(sim_or_dut, words, **kw)


def _assert_same(got, want):
    assert len(got.words) == len(want.words)
    np.testing.assert_array_equal(np.asarray(got.words, np.int64), want.words)
    np.testing.assert_array_equal(got.cycles, want.cycles)


def _powers(ap, run):
    """Per channel: mean ``I^2 + Q^2`` of early, prompt and late over the records from the
    third on (the first two are before the hand-over and its slew)."""
    recs = [ap.record.unpack(v) for v in run.records]
    out = {}
    for ch in range(CHANNELS):
        mine = [r for r in recs if r["channel"] == ch][2:]
        out[ch] = {a: float(np.mean([r["i" + a] ** 2 + r["q" + a] ** 2 for r in mine]))
                   for a in "epl"}
        out[ch]["n"] = len(mine)
    return out


def _check_correlation(name, ap, x, writes, sats, cn0, want):
    """The model's prompts on the satellites against the noise floor: the same writes with
    every PRN replaced by :data:`ABSENT_PRN`."""
    pw = _powers(ap, want)
    absent = [(c, a, ABSENT_PRN if a % 4 == ap.registers.address("prn") else v)
              for c, a, v in writes]
    noise = _powers(ap, _model(ap, x, absent, want.cycles[-1] + 1))
    floor = float(np.mean([noise[ch]["p"] for ch in range(CHANNELS)]))
    for ch in range(CHANNELS):
        p = pw[ch]
        assert p["n"] >= 2, (name, ch)
        snr = p["p"] / floor
        # 1 ms coherent: prompt power / noise ~ 1 + 2 C/N0 T less the losses; weakest
        # acquired (32 dB-Hz) -> ~2.5, strongest (49 dB-Hz) -> ~100.
        need = 1.8 if cn0[ch] < 38 else 5.0
        assert snr > need, (name, ch, sats[ch], cn0[ch], snr)
        if cn0[ch] >= 43:     # the prompt on the code peak: above early and late
            assert p["p"] > max(p["e"], p["l"]), (name, ch, sats[ch], p)


@pytest.mark.parametrize("name", ["iq_4M"])
@needs_verilator
def test_array_on_recording_model_equals_verilator_short(name):
    """5 ms of the I/Q recording on the 12-channel complex-input array."""
    ap, x, writes, sats, cn0 = _setup(name, 5)
    n_cycles = len(x) + 200
    want = _model(ap, x, writes, n_cycles)
    assert len(want.records) >= 4 * CHANNELS and not want.dropped.any()
    got = _hdl_run(VerilatorStreamSim(GnssChannelArray(ap, CHANNELS),
                                      VERILOG_NAMES[name]), ap, x, writes, n_cycles)
    _assert_same(got, want)
    _check_correlation(name, ap, x, writes, sats, cn0, want)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(RECORDINGS))
@needs_verilator
def test_array_on_recording_model_equals_verilator(name):
    """10 ms of each recording: model == Verilator, strong prompts."""
    ap, x, writes, sats, cn0 = _setup(name, 10)
    n_cycles = len(x) + 200
    want = _model(ap, x, writes, n_cycles)
    assert len(want.records) >= 9 * CHANNELS and not want.dropped.any()
    got = _hdl_run(VerilatorStreamSim(GnssChannelArray(ap, CHANNELS),
                                      VERILOG_NAMES[name]), ap, x, writes, n_cycles)
    _assert_same(got, want)
    _check_correlation(name, ap, x, writes, sats, cn0, want)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(RECORDINGS))
def test_array_on_recording_model_equals_pysim(name):
    """The first 1.5 ms of each recording (the hand-over writes and the first dumps of all
    12 channels) on the Amaranth simulation."""
    ap, x, writes, _, _ = _setup(name, 2)
    x = x[:len(x) * 3 // 4]
    n_cycles = len(x) + 200
    want = _model(ap, x, writes, n_cycles)
    assert len(want.records) >= CHANNELS
    _assert_same(_hdl_run(GnssChannelArray(ap, CHANNELS), ap, x, writes, n_cycles), want)


def test_handover_writes_one_per_cycle_and_errors():
    ap, _, writes, sats, _ = _setup("iq_4M", 1)
    p = GnssChannelParams(fs_hz=4e6, if_hz=0.0, el_spacing_samples=2, input="complex")
    assert [c for c, _, _ in writes] == list(range(4 * CHANNELS))
    regs = p.registers
    for ch, s in enumerate(sats):
        mine = {a % 4: v for _, a, v in writes if a // 4 == ch}
        assert mine[regs.address("prn")] == s.prn
        assert mine[regs.address("carr_freq")] == p.carr_word(s.doppler_hz)
    with pytest.raises(ValueError, match=r"PRN must be an integer in \[1, 32\], not 40"):
        array_handover_writes(p, [(40, 0.0, 0.0)])
    with pytest.raises(ValueError, match=r"needs 1 to 64 satellites .*not 0"):
        array_handover_writes(p, [])
    with pytest.raises(ValueError, match=r"start_cycle must be an integer >= 0, not -1"):
        array_handover_writes(p, [(3, 0.0, 0.0)], start_cycle=-1)
