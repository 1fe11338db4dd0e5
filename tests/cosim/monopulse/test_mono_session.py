"""Monopulse front-end model session: state carried (1, 7 or 50 steps give the same bits),
and the same words on the same cycles as the Amaranth simulation session."""
import numpy as np
import pytest

from cosim.backends.factory import open_stream_session
from cosim.core.session import write_register
from cosim.monopulse.session import MonopulseModelSession
from hdl.monopulse.frontend import MonopulseFrontEnd
from hdl.monopulse.params import (REG_COEF, REG_U0, MonopulseFrontendParams, coef_word, dc_word,
                                  pack_input)

P = MonopulseFrontendParams(snapshots=12, cic_rate=4, snapshot_decimation=4,
                            cordic_iterations=12, angle_bits=16, fifo_depth=16)


def record(seed=1, blocks=6):
    rng = np.random.default_rng(seed)
    n = blocks * 48 + 7
    x = rng.integers(-2048, 2048, (n, 4))
    chips = rng.integers(0, 2, n)
    ready = rng.random(n + 200) < 0.3
    writes = [(30, REG_COEF + 1, coef_word(0.4 - 0.6j, P)), (95, REG_U0, dc_word(-0.3, P)),
              (143, REG_COEF + 3, coef_word(-0.9j, P)), (200, REG_COEF, coef_word(0.7, P))]
    return pack_input(x, chips, P), ready, writes


def run(fe, words, ready, writes, steps):
    n = len(words) + 120
    cuts = np.linspace(0, n, steps + 1).astype(int)
    out_w, out_c = [], []
    pending = sorted(writes)
    for a, b in zip(cuts[:-1], cuts[1:]):
        # The DSP decides writes as it goes: each is made in the step before its cycle.
        while pending and pending[0][0] < b:
            c, reg, v = pending.pop(0)
            write_register(fe, reg, v, max(c, a))
        r = fe.step(words[a:b] if a < len(words) else None, ready[a:b], n_cycles=b - a)
        out_w.append(np.asarray(r.words, np.int64))
        out_c.append(r.cycles)
    return np.concatenate(out_w), np.concatenate(out_c), fe.read("overflow_count")


def test_model_session_steps_give_the_same_bits():
    words, ready, writes = record()
    got = [run(MonopulseModelSession(P), words, ready, writes, s) for s in (1, 7, 50)]
    assert len(got[0][0]) >= 5 * P.record_words
    for w, c, ovf in got[1:]:
        np.testing.assert_array_equal(w, got[0][0])
        np.testing.assert_array_equal(c, got[0][1])
        assert ovf == got[0][2]


def test_model_session_matches_pysim_session():
    words, ready, writes = record(seed=2)
    want = run(MonopulseModelSession(P), words, ready, writes, 7)
    with open_stream_session("pysim", MonopulseFrontEnd(P)) as fe:
        got = run(fe, words, ready, writes, 7)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    assert got[2] == want[2]


def test_session_refuses_other_ports():
    with pytest.raises(KeyError, match="writable ports are reg_we, reg_addr, reg_data, not "
                                       "'freq'"):
        MonopulseModelSession(P).write("freq", 1)
    with pytest.raises(ValueError, match="keeps no range log"):
        MonopulseModelSession(P, log_ranges=True)
