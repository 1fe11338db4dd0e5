"""``python -m cosim check-equivalence --top gnss``: the GNSS channel's model, Amaranth
simulation and Verilator on one record with register writes (cosim/gnss/equivalence.py)."""
from __future__ import annotations

import json

import numpy as np
import pytest

import cosim.gnss.session as gnss_session
from cosim.cli import main
from cosim.gnss.equivalence import (EQUIV_PARAMS, EQUIV_PARAMS_IQ, EQUIV_PRN,
                                    check_gnss_equivalence, gnss_equivalence_stimulus)
from hdl.model.fifo import unpack_word
from cosim.core.executables import find_executable


def _records(words, p):
    payload, tag = unpack_word(np.asarray(words), p.fifo)
    rw = p.fifo.record_words
    assert list(tag[::rw]) == [1] * (len(tag) // rw)      # whole records, first word tagged
    out = []
    for row in payload.reshape(-1, rw):
        v = sum(int(a) << (p.fifo_width * i) for i, a in enumerate(row))
        out.append(p.record.unpack(v))
    return out


def test_stimulus_correlates_and_writes_every_register():
    """The record is a real signal the channel locks onto after the hand-over: the records
    after it carry the satellite's correlation (prompt power far above the reset epoch's
    noise); every register is written; the PRN is changed away and back."""
    p = EQUIV_PARAMS
    x, writes = gnss_equivalence_stimulus(p, 40_000, seed=1)
    assert x.min() >= -2 and x.max() <= 1 and len(x) == 40_000
    assert {r for _, r, _ in writes} == {"carr_freq", "code_freq", "slew", "prn"}
    prns = [v for _, r, v in writes if r == "prn"]
    assert prns[0] == EQUIV_PRN and any(v != EQUIV_PRN for v in prns)
    with gnss_session.open_gnss("model", p) as fe:
        for c, reg, v in writes:
            fe.write(reg, v, cycle=c)
        r = fe.step(x, None, n_cycles=len(x) + 500)
    recs = _records(r.words, p)
    assert len(recs) == 7
    power = [rec["ip"] ** 2 + rec["qp"] ** 2 for rec in recs]
    assert power[2] > 16 * power[0], power      # on the peak after the slew vs reset epoch
    assert min(power[1:4]) > 10 * max(power[0], power[4]), power


@pytest.mark.verilator
@pytest.mark.skipif(find_executable("verilator") is None, reason="verilator not on PATH")
def test_cli_three_backends_agree(capsys):
    rc = main(["check-equivalence", "--top", "gnss", "--samples", "20000", "--backends",
               "model,pysim,verilator", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0, out["verdict"]
    assert out["top"] == "gnss" and out["backends"] == ["model", "pysim", "verilator"]
    assert out["mismatches"] == 0 and out["equivalent"] and out["peaks"] == 3
    assert out["words"] == 3 * EQUIV_PARAMS.fifo.record_words


@pytest.mark.verilator
@pytest.mark.skipif(find_executable("verilator") is None, reason="verilator not on PATH")
def test_stall_drops_records_identically():
    r = check_gnss_equivalence(40_000, backends=("model", "verilator"), stall=True)
    assert r["equivalent"] and r["mismatches"] == 0, r["verdict"]
    assert r["dropped"] >= 1 and r["backends"] == ["model", "verilator"]


def test_a_different_backend_gives_mismatches_and_exit_1(monkeypatch, capsys):
    """A backend that differs (pysim given one extra carrier write) is caught: mismatches
    counted, the command exits 1."""
    real = gnss_session.open_gnss

    def tampered(backend, params, **kw):
        fe = real(backend, params, **kw)
        if backend == "pysim":
            fe.write("carr_freq", params.carr_word(params.if_hz + 1000.0), cycle=100)
        return fe
    monkeypatch.setattr(gnss_session, "open_gnss", tampered)
    rc = main(["check-equivalence", "--top", "gnss", "--samples", "16000",
               "--backends", "model,pysim"])
    cap = capsys.readouterr()
    assert rc == 1
    assert "error:" in cap.err and "mismatches" in cap.err
    assert "gnss: 16000 samples" in cap.out


def test_nothing_compared_and_bad_arguments(capsys):
    r = check_gnss_equivalence(3000, backends=("model", "pysim"))
    assert not r["equivalent"] and r["words"] == 0
    assert r["verdict"] == ("nothing was compared: the 3000 samples gave no FIFO word (a record "
                            "every 5115 samples, one code period)")
    assert main(["check-equivalence", "--top", "gnss", "--samples", "3000",
                 "--backends", "model,pysim"]) == 1
    capsys.readouterr()
    with pytest.raises(ValueError, match=r"samples must be an integer >= 1, not 0"):
        check_gnss_equivalence(0)
    with pytest.raises(ValueError, match=r"backends must be among .* not \['fpga'\]"):
        check_gnss_equivalence(100, backends=("model", "fpga"))
    assert main(["check-equivalence", "--top", "gnss", "--samples", "0"]) == 2
    assert "error: --samples must be an integer >= 1, not 0" in capsys.readouterr().err


def test_iq_stimulus_correlates_on_the_complex_channel():
    """The zero-IF I/Q record: the complex-input channel locks onto it after the hand-over
    (the same carrier-word sign as the real record's), and not with the Doppler mirrored."""
    p = EQUIV_PARAMS_IQ
    x, writes = gnss_equivalence_stimulus(p, 40_000, seed=1)
    assert x.shape == (40_000, 2) and x.min() >= -2 and x.max() <= 1
    assert {r for _, r, _ in writes} == {"carr_freq", "code_freq", "slew", "prn"}

    def powers(ws):
        with gnss_session.open_gnss("model", p) as fe:
            for c, reg, v in ws:
                fe.write(reg, v, cycle=c)
            r = fe.step(p.pack_samples(x), None, n_cycles=len(x) + 500)
        return [rec["ip"] ** 2 + rec["qp"] ** 2 for rec in _records(r.words, p)]

    power = powers(writes)
    assert len(power) == 7
    # on the peak after the hand-over (records 1, 2) vs the reset epoch and the record of
    # another PRN (the seeded PRN write lands before record 4)
    assert min(power[1:3]) > 16 * max(power[0], power[4]), power
    # The hand-over alone (no seeded writes after it): the Doppler's word against the
    # mirrored one.
    hand = writes[:4]
    assert [r for _, r, _ in hand] == ["prn", "carr_freq", "code_freq", "slew"]
    mirrored = [(c, r, (-v) % (1 << p.carr_phase_bits) if r == "carr_freq" else v)
                for c, r, v in hand]
    assert np.mean(powers(hand)[1:]) > 5 * np.mean(powers(mirrored)[1:])


@pytest.mark.verilator
@pytest.mark.skipif(find_executable("verilator") is None, reason="verilator not on PATH")
def test_iq_three_backends_agree():
    r = check_gnss_equivalence(20_000, params=EQUIV_PARAMS_IQ,
                               backends=("model", "pysim", "verilator"))
    assert r["equivalent"] and r["mismatches"] == 0, r["verdict"]
    assert r["backends"] == ["model", "pysim", "verilator"] and r["peaks"] == 3
