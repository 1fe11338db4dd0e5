"""The TACAN FIFO record on :class:`dsp.record_layout.RecordLayout`
(:func:`dsp.tacan.fifo_rx.peak_record`): the model packs its words with it and the DSP
decodes them with it, bit for bit the documented payload ``amplitude | timestamp <<
amp_width [| source << (amp_width + ts_bits)]``, one FIFO word wide."""
from __future__ import annotations

import numpy as np
import pytest

from dsp.tacan.fifo_rx import peak_record, receive_words
from hdl.tacan.model import FrontendPeaks, TacanFrontendModel
from hdl.tacan.params import TacanFrontendParams

from _tacan_fe_util import BOTH  # on sys.path: conftest.py


@pytest.mark.parametrize("params", [TacanFrontendParams(), BOTH], ids=["one", "both"])
def test_model_words_and_unpack_are_the_documented_payload(params):
    p, rec = params, params.record
    aw, tb, sb = p.peak.amp_width, p.ts_bits, p.source_bits
    assert rec.names == ("amplitude", "timestamp") + (("source",) if sb else ())
    assert rec.bits == p.fifo.width == aw + tb + sb
    rng = np.random.default_rng(3)
    n = 200
    amp = rng.integers(0, 1 << aw, n)
    ts = np.sort(rng.integers(0, 1 << (tb + 3), n))         # unwrapped: past the wrap
    src = rng.integers(0, 2, n).astype(np.int8) if sb else None
    peaks = FrontendPeaks(amp, ts, np.arange(n), np.arange(n), src)
    words = TacanFrontendModel(p).words(peaks)
    want = amp | ((ts % (1 << tb)) << aw)
    if sb:
        want = want | (src.astype(np.int64) << (aw + tb))
    np.testing.assert_array_equal(words, want)
    tag = rng.integers(0, 4, n)
    got = TacanFrontendModel(p).unpack(words | (tag << p.fifo.width))
    assert list(got) == ["amplitude", "timestamp", "tag"] + (["source"] if sb else [])
    np.testing.assert_array_equal(got["amplitude"], amp)
    np.testing.assert_array_equal(got["timestamp"], ts % (1 << tb))
    np.testing.assert_array_equal(got["tag"], tag)
    if sb:
        np.testing.assert_array_equal(got["source"], src)


def test_the_dsp_decodes_the_model_words_with_the_same_record():
    p = BOTH
    rng = np.random.default_rng(5)
    n = 50
    ts = np.cumsum(rng.integers(100, 1000, n))
    amp = rng.integers(1, 1 << p.peak.amp_width, n)
    src = np.zeros(n, np.int8)
    peaks = FrontendPeaks(amp, ts, np.arange(n), np.arange(n), src)
    words = TacanFrontendModel(p).words(peaks)          # tag 0: data words
    t, a, s, _ = receive_words(words, width=p.fifo.width, amp_width=p.peak.amp_width,
                               ts_bits=p.ts_bits, source_bits=p.source_bits)
    np.testing.assert_array_equal(a, amp)
    np.testing.assert_array_equal(t - t[0], ts - ts[0])
    np.testing.assert_array_equal(s, src)
    assert peak_record(p.peak.amp_width, p.ts_bits, 1) == p.record
