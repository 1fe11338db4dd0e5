"""The GNSS channel model as a session: blocks, register writes, model == pysim."""
import numpy as np
import pytest

from cosim.gnss.session import GnssModelSession, GnssRegisterSession
from cosim.core.link import DspServiceConfig
from cosim.backends.factory import open_stream_session
from hdl.gnss.model import GnssArrayModel
from hdl.gnss.params import GnssChannelParams

#: Reduced rate (as tests/hdl/gnss/test_channel.py): 2 samples per chip, 2046 per epoch.
SMALL = GnssChannelParams(fs_hz=2.046e6, if_hz=0.3e6, el_spacing_samples=2, slew_bits=6,
                          carr_table_bits=6, lo_bits=3, fifo_depth=64)
SVC = DspServiceConfig(period_cycles=400, latency_cycles=10, batch_words=8, cycles_per_word=3)


def _stimulus(p, n, seed):
    rng = np.random.default_rng(seed)
    x = rng.integers(-2, 2, n)
    regs = [("carr_freq", p.carr_word(p.if_hz + 1234.5)), ("code_freq", p.code_word(1.02301e6)),
            ("prn", 5), ("slew", 3), ("carr_freq", p.carr_word(p.if_hz - 700.0))]
    cyc = sorted(int(c) for c in rng.choice(np.arange(5, n - 5), len(regs), replace=False))
    # two registers for the same cycle: they go out on consecutive bus cycles
    cyc[2] = cyc[1]
    return x, [(c, r, v) for c, (r, v) in zip(cyc, regs)]


def _run_blocks(session, x, writes, n_blocks, n_extra=80):
    edges = np.linspace(0, len(x), n_blocks + 1).astype(int)
    words, cycles = [], []
    pending = list(writes)
    for a, b in zip(edges[:-1], edges[1:]):
        while pending and pending[0][0] < b:
            c, r, v = pending.pop(0)
            session.write(r, v, cycle=c)
        res = session.step(x[a:b], SVC)
        words.append(res.words)
        cycles.append(res.cycles)
    res = session.step(None, SVC, n_cycles=n_extra)
    words.append(res.words)
    cycles.append(res.cycles)
    return np.concatenate(words), np.concatenate(cycles)


def test_model_session_blocks_give_the_same_words():
    p = SMALL
    n = 5 * 2046
    x, writes = _stimulus(p, n, seed=1)
    got = {}
    for nb in (1, 7, 50):
        s = GnssRegisterSession(GnssModelSession(p), p)
        got[nb] = _run_blocks(s, x, writes, nb)
        assert len(s.bus_writes) == len(writes)
        assert s.bus_writes[2][0] == s.bus_writes[1][0] + 1   # the bus takes one per cycle
    assert got[1][0].size >= 4 * p.fifo.record_words
    for nb in (7, 50):
        np.testing.assert_array_equal(got[nb][0], got[1][0])
        np.testing.assert_array_equal(got[nb][1], got[1][1])
    # the same as the one-shot model given the bus writes the session made
    want = GnssArrayModel(p).run(x, [(c, a, v) for c, a, v in s.bus_writes],
                                 n_cycles=n + 80, out_ready=SVC.ready_mask(n + 80))
    np.testing.assert_array_equal(got[1][0], want.words)
    np.testing.assert_array_equal(got[1][1], want.cycles)


def test_model_session_matches_pysim_with_register_writes():
    from hdl.gnss.channel import GnssChannel
    p = SMALL
    n = 2 * 2046 + 300
    x, writes = _stimulus(p, n, seed=2)
    m = _run_blocks(GnssRegisterSession(GnssModelSession(p), p), x, writes, 3)
    ps = GnssRegisterSession(open_stream_session("pysim", GnssChannel(p)), p)
    s = _run_blocks(ps, x, writes, 3)
    assert m[0].size >= 2 * p.fifo.record_words
    np.testing.assert_array_equal(s[0], m[0])
    np.testing.assert_array_equal(s[1], m[1])
    assert ps.read("overflow_count") == 0


def test_complex_input_session_blocks_match_pysim():
    """The complex-input channel: the sessions take the packed I/Q payload words; the model
    session in 1 or 7 blocks == the pysim session in 3."""
    from dataclasses import replace
    from hdl.gnss.channel import GnssChannel
    p = replace(SMALL, input="complex", if_hz=-0.3e6)
    n = 2 * 2046 + 300
    _, writes = _stimulus(p, n, seed=3)
    iq = np.random.default_rng(4).integers(-2, 2, (n, 2))
    x = p.pack_samples(iq)
    np.testing.assert_array_equal(p.unpack_samples(x), iq)
    m1 = _run_blocks(GnssRegisterSession(GnssModelSession(p), p), x, writes, 1)
    m7 = _run_blocks(GnssRegisterSession(GnssModelSession(p), p), x, writes, 7)
    ps = GnssRegisterSession(open_stream_session("pysim", GnssChannel(p)), p)
    s = _run_blocks(ps, x, writes, 3)
    assert m1[0].size >= 2 * p.fifo.record_words
    for got in (m7, s):
        np.testing.assert_array_equal(got[0], m1[0])
        np.testing.assert_array_equal(got[1], m1[1])
    with pytest.raises(ValueError, match=r"I/Q input words are unsigned 4-bit"):
        GnssModelSession(p).step(np.array([16]))
    # The register session takes the (n, 2) pairs as well and packs them.
    pairs = _run_blocks(GnssRegisterSession(GnssModelSession(p), p), iq, writes, 1)
    np.testing.assert_array_equal(pairs[0], m1[0])
    with pytest.raises(ValueError, match=r"\(n, 2\) array of \(I, Q\) pairs, not shape "
                                         r"\(4, 3\)"):
        GnssRegisterSession(GnssModelSession(p), p).step(np.zeros((4, 3), np.int64))


def test_bad_writes_and_ports():
    p = SMALL
    s = GnssRegisterSession(GnssModelSession(p), p)
    with pytest.raises(KeyError, match="GNSS registers are carr_freq, code_freq, prn, slew"):
        s.write("freq", 1)
    with pytest.raises(ValueError, match=r"GNSS register prn \(address 2\) takes unsigned "
                                         r"6-bit words in \[1, 32\], not 33"):
        s.write("prn", 33)
    with pytest.raises(ValueError, match=r"GNSS register slew \(address 3\) takes unsigned "
                                         r"6-bit words in \[0, 63\], not 64"):
        s.write("slew", 64)
    with pytest.raises(ValueError, match=r"GNSS register carr_freq \(address 0\) takes "
                                         r"unsigned 32-bit words in \[0, 4294967295\], not 0.5"):
        s.write("carr_freq", 0.5)
    m = GnssModelSession(p)
    with pytest.raises(KeyError, match="writable ports are reg_we, reg_addr, reg_data"):
        m.write("carr_freq", 1)
    m.write("reg_addr", 4)
    with pytest.raises(ValueError, match="reg_addr takes unsigned 2-bit values, not 4"):
        m.step(np.zeros(10, np.int64))
    with pytest.raises(ValueError, match="one channel"):
        GnssModelSession(GnssChannelParams(channel_bits=2))
