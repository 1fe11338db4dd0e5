"""DSP-side FIFO receiver: decoding, unwrapping, and robustness to corrupted words."""
import numpy as np
import pytest

from dsp.tacan.fifo_rx import RxState, receive_words

W, AW, TB = 51, 19, 32


def _pack(ts, amp, tag=0):
    ts = np.asarray(ts, np.int64) & ((1 << TB) - 1)
    return (np.asarray(amp, np.int64) | (ts << AW)) | (np.int64(tag) << W)


def _stream(n=3000, seed=0, start=(1 << 32) - 50_000):
    rng = np.random.default_rng(seed)
    t = start + np.cumsum(rng.integers(200, 8000, n))
    a = rng.integers(1, 1 << AW, n)
    return t, a


def test_clean_stream_unwraps_across_the_32_bit_wrap_and_batches():
    t, a = _stream()
    words = _pack(t, a)
    ticks, amps, st = receive_words(words, width=W, amp_width=AW, ts_bits=TB)
    np.testing.assert_array_equal(ticks, t)           # starts below the wrap: stays exact
    np.testing.assert_array_equal(amps, a)
    assert st.stats["data"] == 3000 and st.stats["ts_rejected"] == 0
    s2 = RxState()
    parts = [receive_words(words[i:i + 700], width=W, amp_width=AW, ts_bits=TB, state=s2)[0]
             for i in range(0, 3000, 700)]
    np.testing.assert_array_equal(np.concatenate(parts), t)


def test_markers_and_reserved_tags_are_counted():
    t, a = _stream(10)
    words = list(_pack(t, a))
    words.insert(3, int(_pack(0, 5, tag=2)))     # marker: 5 dropped (payload 5)
    words.insert(6, int(_pack(0, 1, tag=1)))
    words.insert(8, int(_pack(0, 1, tag=3)))
    ticks, amps, st = receive_words(words, width=W, amp_width=AW, ts_bits=TB)
    np.testing.assert_array_equal(ticks, t)
    assert st.stats["dropped_reported"] == 5 and st.stats["markers"] == 1
    assert st.stats["bad_tags"] == 2


def test_corrupted_timestamps_are_rejected_and_resynchronised():
    t, a = _stream(2000, seed=3)
    words = _pack(t, a)
    rng = np.random.default_rng(9)
    bad = np.sort(rng.choice(np.arange(10, 1990), 20, replace=False))
    w2 = words.copy()
    w2[bad] ^= np.int64(1) << (AW + rng.integers(23, TB, bad.size))   # high timestamp bits
    ticks, amps, st = receive_words(w2, width=W, amp_width=AW, ts_bits=TB)
    assert np.all(np.diff(ticks) > 0)                  # strictly increasing, always
    good = np.isin(ticks, t)
    assert good.mean() > 0.9                           # most peaks kept ...
    assert st.stats["ts_rejected"] >= 10               # ... the implausible ones rejected
    assert ticks[-1] == t[-1]                          # and back in sync at the end


def test_outage_longer_than_max_gap_resyncs_after_n_words():
    t, a = _stream(100)
    t[50:] += 1 << 24                                  # 0.8 s silence
    ticks, _, st = receive_words(_pack(t, a), width=W, amp_width=AW, ts_bits=TB,
                                 resync_after=4)
    assert st.stats["ts_resyncs"] == 1 and st.stats["ts_rejected"] == 4
    np.testing.assert_array_equal(ticks[-46:], t[-46:])


def test_bad_arguments():
    with pytest.raises(ValueError, match="amp_width \\+ ts_bits"):
        receive_words([], width=40, amp_width=19, ts_bits=32)
    with pytest.raises(ValueError, match="max_gap_ticks"):
        receive_words([], width=W, amp_width=AW, ts_bits=TB, max_gap_ticks=0)
