"""Icarus Verilog driven by cocotb, the third simulator of the exported Verilog, through the
equivalence checks and sessions: every registered top (TACAN, the GNSS channel and its
12-channel array, real and I/Q input, monopulse) gives the bit-exact model's FIFO words on the
same cycles, under seeded random stalls; the check fails when the expectation is wrong; the
session keeps its state across steps.

The check ``make test`` runs on the TACAN and GNSS tops is their stream case in
``tests/cosim/test_cocotb_blocks.py`` (short records with register writes mid-run); on the
monopulse front end it is the session test here (writes mid-run, stalls that drop records)
and ``check-equivalence --backends model,icarus``. The other top checks (the equivalence
checks' own records, the registered tops with their default parameters over longer windows)
are marked slow (Icarus runs a whole top at ~0.2-1.5e3 cycles/s). Skipped, with the reason, when ``iverilog``/``vvp`` or cocotb is missing
(``make setup`` installs both).
"""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cosim.backends.icarus import IcarusStreamSim, icarus_available, icarus_missing_message
from cosim.backends.verilator_harness import verilator_available

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "hdl"))
from _util import gnss_stimulus  # noqa: E402  (the GNSS channel tests' stimulus)

pytestmark = [pytest.mark.icarus,
              pytest.mark.skipif(not icarus_available(), reason=icarus_missing_message())]

def _equivalent(r, backends=("model", "icarus")):
    assert r["backends"] == list(backends), r["skipped"]
    assert r["equivalent"] and r["mismatches"] == 0, r["verdict"]
    assert r["per_backend"]["icarus"]["words"] == r["words"] > 0


# -- every registered top: Icarus == model ---------------------------------------------------

@pytest.mark.slow
def test_tacan_frontend_matches_model_under_stalls():
    """The default TACAN front end (tacan_frontend), a 4-word FIFO, seeded on/off stalls, on
    the TACAN record of ``check-equivalence`` (~50 s; the fast suite runs the top's stream
    case)."""
    from cosim.tacan.equivalence import check_equivalence
    r = check_equivalence(samples=6000, backends=("model", "icarus"), stall=True, seed=6)
    _equivalent(r)
    assert "model == icarus over 6,400 cycles" in r["simulators"]


@pytest.mark.slow
def test_gnss_channel_matches_model_under_stalls():
    """One GNSS channel, the record of ``check-equivalence --top gnss`` (5.115 MS/s) over two
    code periods: the hand-over and seeded writes, stalls, a FIFO of one record and a
    marker (slow: the fast suite runs the GNSS tops' stream cases)."""
    from cosim.gnss.equivalence import check_gnss_equivalence
    r = check_gnss_equivalence(2 * 5115 + 300, backends=("model", "icarus"), stall=True,
                               seed=2)
    _equivalent(r)
    assert r["peaks"] >= 1


def _array_check(p, channels, n, seed, *, name):
    """``channels`` GNSS channels (one: :class:`GnssChannel`, more: the array) on Icarus
    against the model, with register writes (two per channel, every register in turn, random
    channels) and random ``ready``."""
    from hdl.gnss.channel import GnssChannel, GnssChannelArray, array_params
    from hdl.gnss.model import GnssArrayModel
    from hdl.model.bus import bus_writes
    x, writes, ready = gnss_stimulus(p, n, seed, n_writes=2, ch=channels, ready_p=0.5)
    n_cycles = n + 200
    model = GnssArrayModel(array_params(p, channels), channels) if channels > 1 \
        else GnssArrayModel(p)
    want = model.run(x, writes, n_cycles=n_cycles, out_ready=ready)
    assert len(want.records) >= channels
    dut = GnssChannelArray(p, channels) if channels > 1 else GnssChannel(p)
    sim = IcarusStreamSim(dut, name=name)
    got = sim.run(p.pack_samples(x), out_ready=ready, n_cycles=n_cycles,
                  writes=bus_writes(writes, data_width=p.reg_data_width))
    np.testing.assert_array_equal(np.asarray(got.words, np.int64), want.words)
    np.testing.assert_array_equal(got.cycles, want.cycles)
    return want


@pytest.mark.slow
def test_monopulse_frontend_matches_model_under_stalls():
    """The record of ``check-equivalence --top monopulse`` under stalls (the fast suite runs
    the top's stream case and ``check-equivalence`` without stalls)."""
    from cosim.monopulse.equivalence import check_monopulse_equivalence
    r = check_monopulse_equivalence(1500, backends=("model", "icarus"), seed=3, stall=True)
    _equivalent(r)
    assert r["peaks"] >= 30


# -- the check can fail -----------------------------------------------------------------------

def _monopulse_runs(model_params, icarus_params, n=1000, seed=4):
    """``run(backend)`` of :func:`cosim.tools.equivalence.compare_backends`: the reduced
    monopulse front end's record with writes and stalls, the model built from
    ``model_params``, Icarus from ``icarus_params``."""
    from cosim.backends.factory import open_frontend
    from cosim.core.session import write_register
    from cosim.monopulse.equivalence import stimulus
    from cosim.tools.equivalence import stall_pattern
    words, writes = stimulus(icarus_params, n, seed)
    n_cycles = n + icarus_params.latency + 400
    ready = stall_pattern(n_cycles, seed, burst=300)

    def run(backend):
        with open_frontend(backend, model_params if backend == "model" else icarus_params) as fe:
            for c, reg, v in writes:
                write_register(fe, reg, v, c)
            r = fe.step(words, ready, n_cycles=n_cycles)
            ovf = fe.read("overflow_count")
        return np.asarray(r.words, np.int64), np.asarray(r.cycles), ovf, 0.0
    return run, n_cycles


def test_a_corrupted_expected_word_is_reported():
    from cosim.monopulse.equivalence import EQUIV_PARAMS
    from cosim.tools.equivalence import compare_backends
    run, n_cycles = _monopulse_runs(EQUIV_PARAMS, EQUIV_PARAMS)
    cache = {b: run(b) for b in ("model", "icarus")}
    w, c, ovf, s = cache["model"]
    assert len(w) > 10
    bad = w.copy()
    bad[7] ^= 1 << 5                    # one bit of one expected word

    def corrupted(backend):
        return (bad, c, ovf, s) if backend == "model" else cache[backend]
    ok = compare_backends("monopulse", 1000, ("model", "icarus"), lambda b: cache[b], seed=4,
                          stall=True, empty_hint="", n_cycles=n_cycles)
    assert ok["equivalent"] and ok["mismatches"] == 0, ok["verdict"]
    r = compare_backends("monopulse", 1000, ("model", "icarus"), corrupted, seed=4,
                         stall=True, empty_hint="", n_cycles=n_cycles)
    assert not r["equivalent"] and r["mismatches"] == 1
    assert r["verdict"].startswith("1 mismatches")
    assert r["simulators"].startswith("model != icarus over")


def test_a_model_with_a_changed_parameter_is_reported():
    """The model of one CORDIC iteration less than the design Icarus runs: its angle words
    differ, and the check says so."""
    from cosim.monopulse.equivalence import EQUIV_PARAMS
    from cosim.tools.equivalence import compare_backends
    other = replace(EQUIV_PARAMS, cordic_iterations=EQUIV_PARAMS.cordic_iterations - 1)
    run, n_cycles = _monopulse_runs(other, EQUIV_PARAMS)
    r = compare_backends("monopulse", 1000, ("model", "icarus"), run, seed=4, stall=True,
                         empty_hint="", n_cycles=n_cycles)
    assert not r["equivalent"] and r["mismatches"] > 0, r["verdict"]


# -- the session --------------------------------------------------------------------------------

def test_session_in_blocks_equals_one_step_and_reads_ports():
    """Stepping the Icarus session in blocks with writes in between gives the model's words
    and cycles (vvp stays alive between steps); read() gives the overflow counter after the
    last edge; the stream ports cannot be written."""
    from cosim.backends.factory import open_frontend
    from cosim.core.session import write_register
    from cosim.monopulse.equivalence import EQUIV_PARAMS, stimulus
    p = replace(EQUIV_PARAMS, fifo_depth=EQUIV_PARAMS.record_words + 2)
    words, writes = stimulus(p, 900, 5)
    ready = np.random.default_rng(5).random(1200) < 0.5
    ready[300:800] = False              # a long stall: records dropped
    out = {}
    for backend in ("model", "icarus"):
        with open_frontend(backend, p) as fe:
            assert fe.backend == backend
            got_w, got_c = [], []
            for a, b in ((0, 250), (250, 251), (251, 700), (700, 1200)):
                for c, reg, v in writes:
                    if a <= c < b:
                        write_register(fe, reg, v, c)
                r = fe.step(words[a:b], ready[a:b], n_cycles=b - a)
                got_w.append(r.words)
                got_c.append(r.cycles)
            out[backend] = (np.concatenate(got_w), np.concatenate(got_c),
                            fe.read("overflow_count"))
            if backend == "icarus":
                with pytest.raises(ValueError, match="driven by the stream runner"):
                    fe.write("o__ready", 1)
                with pytest.raises(KeyError, match="no port named"):
                    fe.write("nonexistent", 1)
    np.testing.assert_array_equal(out["icarus"][0], out["model"][0])
    np.testing.assert_array_equal(out["icarus"][1], out["model"][1])
    assert out["icarus"][2] == out["model"][2] > 0     # records dropped, counted alike


def test_cli_reports_the_simulators(capsys):
    """check-equivalence with Verilator and Icarus: the line naming every simulator, the
    cycles and the wall times."""
    from cosim.cli import main
    rc = main(["check-equivalence", "--top", "monopulse", "--samples", "1000",
               "--backends", "model,icarus"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "simulators: model == icarus over 1,444 cycles: model " in out
    assert "cycles/s), icarus " in out


@pytest.mark.slow
@pytest.mark.verilator
@pytest.mark.skipif(not verilator_available(), reason="Verilator not found on PATH")
def test_cli_four_backends_on_tacan(capsys):
    """The default check-equivalence (model, pysim, Verilator, Icarus) on TACAN."""
    from cosim.cli import main
    rc = main(["check-equivalence", "--top", "tacan", "--samples", "16000"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "simulators: model == pysim == verilator == icarus over 16,400 cycles" in out


# -- the registered tops with default parameters, longer windows --------------------------------

@pytest.mark.slow
def test_tacan_long_window_with_drops_and_markers():
    from cosim.tacan.equivalence import check_equivalence
    r = check_equivalence(samples=30_000, backends=("model", "icarus"), stall=True, seed=1)
    _equivalent(r)
    assert r["markers"] > 0 and r["dropped"] > 0


@pytest.mark.slow
def test_gnss_channel_default_equivalence_record():
    """The record of ``check-equivalence --top gnss`` (EQUIV_PARAMS), stalls and drops."""
    from cosim.gnss.equivalence import check_gnss_equivalence
    r = check_gnss_equivalence(20_000, backends=("model", "icarus"), stall=True, seed=1)
    _equivalent(r)


@pytest.mark.slow
def test_gnss_channel_default_parameters():
    """The registered gnss_channel top (default parameters: 16.384 MS/s, 1 ms dumps)."""
    from hdl.gnss.channel import GnssChannel
    from hdl.gnss.model import GnssArrayModel
    from hdl.gnss.params import GnssChannelParams
    from hdl.model.bus import bus_writes
    p = GnssChannelParams()
    x, writes, ready = gnss_stimulus(p, 2 * 16368 + 100, 7, n_writes=2, ready_p=0.5)
    n_cycles = len(x) + 200
    want = GnssArrayModel(p).run(x, writes, n_cycles=n_cycles, out_ready=ready)
    assert len(want.records) >= 1
    got = IcarusStreamSim(GnssChannel(p), name="gnss_channel").run(
        x, out_ready=ready, n_cycles=n_cycles,
        writes=bus_writes(writes, data_width=p.reg_data_width))
    np.testing.assert_array_equal(np.asarray(got.words, np.int64), want.words)
    np.testing.assert_array_equal(got.cycles, want.cycles)


@pytest.mark.slow
def test_gnss_array12_default_parameters():
    """The registered gnss_channel_array12 top (default parameters), two dumps."""
    from hdl.gnss.params import GnssChannelParams
    want = _array_check(GnssChannelParams(), 12, 2 * 16368 + 100, seed=13,
                        name="gnss_channel_array12")
    assert len(want.records) >= 12


@pytest.mark.slow
def test_monopulse_default_parameters():
    """The registered monopulse_frontend top (default parameters: a record every 81,920
    samples) under stalls, with register writes."""
    from cosim.tools.equivalence import compare_backends
    from hdl.monopulse.params import MonopulseFrontendParams
    p = MonopulseFrontendParams()
    p = replace(p, fifo_depth=p.record_words + 2)
    n = p.snapshots * p.snapshot_decimation + 2000
    run, n_cycles = _monopulse_runs(p, p, n=n, seed=2)
    r = compare_backends("monopulse", n, ("model", "icarus"), run, seed=2, stall=True,
                         empty_hint="", n_cycles=n_cycles, icarus_max_samples=n)
    _equivalent(r)


@pytest.mark.slow
def test_tacan_run_rechecked_on_icarus(capsys):
    """``python -m cosim tacan --backend model --recheck icarus``: the start of a model run
    (its first pulse pairs leave after ~25,000 samples) re-run on Icarus gives the same FIFO
    words on the same cycles."""
    import json
    from cosim.cli import main
    rc = main(["tacan", "--backend", "model", "--duration-s", "0.7", "--memory-s", "0.15",
               "--recheck", "icarus", "--recheck-samples", "30000", "--json"])
    out = capsys.readouterr().out
    assert rc == 0, out
    c = json.loads(out)["recheck"]
    assert c["backend"] == "icarus" and c["samples"] == 30000
    assert c["same_bits"] is True and c["words"] > 0
