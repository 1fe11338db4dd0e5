"""Generic DSP-side record receiver (dsp.records): reassembly, markers, parity, tags, batch
boundaries, and agreement with the single-word decoder TACAN uses."""
from __future__ import annotations

import numpy as np
import pytest

from dsp.records import receive_records
from hdl.model.fifo import (TAG_DATA, TAG_MARKER, TAG_START, FifoParams, ReadySchedule,
                            decode_stream, fifo_model, pack_word)


def _run(p, seed, n=20_000):
    rng = np.random.default_rng(seed)
    in_valid = rng.random(n) < 0.06
    in_valid[int(0.9 * n):] = False
    ready = ReadySchedule(period=30, count=6).mask(n)
    ready[n // 4:n // 2] = False
    recs = rng.integers(0, 1 << p.width, (int(in_valid.sum()), p.record_words))
    return recs, fifo_model(recs, in_valid, ready, p)


@pytest.mark.parametrize("n_words", [1, 3, 6])
def test_records_and_counts_from_the_fifo_model(n_words):
    p = FifoParams(width=20, depth=24, record_words=n_words, parity=True)
    recs, ref = _run(p, 500 + n_words)
    rx = receive_records(ref.words, width=p.width, record_words=n_words, parity=True)
    np.testing.assert_array_equal(rx.records, recs[~ref.dropped])
    st = rx.state.stats
    assert st["dropped_reported"] == ref.state.overflow == ref.dropped.sum() > 50
    assert st["records"] == (~ref.dropped).sum()
    assert st["words"] == ref.words.size
    assert sum(st[k] for k in ("parity_errors", "bad_tags", "broken_records",
                               "orphan_words", "bad_markers")) == 0
    np.testing.assert_array_equal(ref.words[rx.first_word] >> p.width & 3,
                                  TAG_START if n_words > 1 else TAG_DATA)


def test_single_words_agree_with_decode_stream():
    p = FifoParams(width=30, depth=8)
    recs, ref = _run(p, 510)
    data, dropped = decode_stream(ref.words, p)
    rx = receive_records(ref.words, width=30)
    np.testing.assert_array_equal(rx.records[:, 0], data)
    assert rx.state.stats["dropped_reported"] == dropped


def test_batches_equal_one_batch():
    """Split anywhere (inside a record too): same records, same stats."""
    p = FifoParams(width=16, depth=16, record_words=3)
    _, ref = _run(p, 511, n=6000)
    whole = receive_records(ref.words, width=16, record_words=3)
    rng = np.random.default_rng(512)
    cuts = np.sort(rng.choice(np.arange(1, ref.words.size), 40, replace=False))
    st, recs, gaps = None, [], []
    for chunk in np.split(ref.words, cuts):
        r = receive_records(chunk, width=16, record_words=3, state=st)
        st = r.state
        recs.append(r.records)
        gaps.append(r.gap_before)
    np.testing.assert_array_equal(np.concatenate(recs), whole.records)
    np.testing.assert_array_equal(np.concatenate(gaps), whole.gap_before)
    assert st.stats == whole.state.stats


def test_corrupted_words_never_give_a_partial_record():
    p = FifoParams(width=12, depth=8, record_words=3, parity=True)

    def w(pay, tag):
        return int(pack_word(pay, tag, p))
    good = [w(1, TAG_START), w(2, TAG_DATA), w(3, TAG_DATA)]
    words = np.array(
        good
        + [w(4, TAG_START), w(5, TAG_DATA) ^ 1, w(6, TAG_DATA)]   # parity error mid-record
        + [w(7, TAG_START), w(8, TAG_DATA)]                       # cut short by a start
        + [w(9, TAG_START), w(10, TAG_DATA), w(11, TAG_DATA)]
        + [w(12, TAG_START), w(2, TAG_MARKER)]                    # cut short by a marker
        + [w(13, TAG_DATA)]                                       # orphan
        + [w(0, 3)]                                               # reserved tag
        + good, dtype=np.int64)
    rx = receive_records(words, width=12, record_words=3, parity=True)
    assert rx.records.tolist() == [[1, 2, 3], [9, 10, 11], [1, 2, 3]]
    st = rx.state.stats
    assert (st["parity_errors"], st["broken_records"], st["orphan_words"], st["bad_tags"],
            st["markers"], st["dropped_reported"]) == (1, 3, 2, 1, 1, 2)
    assert rx.gap_before.tolist() == [0, 0, 2]
    assert rx.first_word.tolist() == [0, 8, words.size - 3]


def test_bad_marker_and_arguments():
    p = FifoParams(width=12, depth=8)
    words = np.array([int(pack_word(4000, TAG_MARKER, p))])
    st = receive_records(words, width=12, max_marker=1000).state.stats
    assert st["bad_markers"] == 1 and st["dropped_reported"] == 0
    with pytest.raises(ValueError, match=r"record_words must be an integer in \[1, 64\]"):
        receive_records(words, width=12, record_words=0)
    with pytest.raises(ValueError, match=r"record width must be an integer in \[1, 60\]"):
        receive_records(words, width=61, parity=True)
