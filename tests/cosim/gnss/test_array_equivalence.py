"""``python -m cosim check-equivalence --top gnss --scenario gps``: the channel array closed
loop on a window of the generated 8-satellite scenario, acquired once, tracked by the model
and by Verilator; FIFO words and read cycles, bus writes, the DSP's writes and the trackers'
outputs compared (cosim/gnss/array_equivalence.py). A run with one bus write changed is
caught."""
from __future__ import annotations

import json

import numpy as np
import pytest

import cosim.gnss.multichannel as multichannel
import cosim.tools.equivalence as tools_equivalence
from cosim.backends.verilator_harness import verilator_available
from cosim.cli import main
from cosim.gnss.array_equivalence import (check_array_equivalence, compare_window,
                                          prepare_window)
from cosim.tools.equivalence import count_differences

def needs_verilator(f):
    return pytest.mark.verilator(pytest.mark.skipif(
        not verilator_available(), reason="Verilator, make or a C++ compiler not on PATH")(f))

#: The shortest window (20 ms at 5 MS/s), on all 8 satellites: one Verilator build of the
#: 8-channel array serves this file.
SHORT = 100_000
CHANNELS = 8
OUTPUTS = ("bus writes", "DSP writes", "tracker digest")


@pytest.fixture(scope="module")
def window(tmp_path_factory):
    """20 ms of the scenario, its own PRNs searched (a short acquisition)."""
    return prepare_window(SHORT, tmp_path_factory.mktemp("scenario"), prns=None)


def test_the_window_holds_the_scenarios_satellites(window):
    assert len(window.truth["prns"]) >= 8
    assert sorted(c.prn for c in window.candidates) == sorted(window.truth["prns"])
    assert all(c.cn0_dbhz > 40 for c in window.candidates)


@needs_verilator
def test_closed_loop_window_model_equals_verilator(window):
    r = compare_window(window, channels=CHANNELS, backends=("model", "verilator"))
    assert r["equivalent"] and r["mismatches"] == 0, r["verdict"]
    assert r["backends"] == ["model", "verilator"]
    v = r["per_backend"]["verilator"]
    # every channel's records from the 2nd ms on (about 19 per channel in 20 ms)
    assert r["peaks"] >= CHANNELS * 17 and v["words"] == r["words"]
    outs = v["outputs"]
    assert all(outs[k]["mismatches"] == 0 for k in OUTPUTS)
    # the hand-overs (prn, carrier, code, slew per channel) and a carrier and a code word per
    # record from each tracker
    assert outs["bus writes"]["n"] >= CHANNELS * (4 + 2 * 15)
    assert [a["records"] for a in r["scenario"]["assignments"]] == [17] * CHANNELS


def _tampered_open(nth_carrier_write: int):
    """``open_gnss_array`` whose ``verilator`` session is the model's with the
    ``nth_carrier_write``-th carrier word written 1 LSB higher (no Verilator needed)."""
    real = multichannel.open_gnss_array

    def open_array(backend, params, channels, parallel=False):
        fe = real("model", params, channels, parallel)
        if backend == "verilator":
            write, seen = fe.write, [0]

            def tampered(reg, value, cycle=None):
                if reg.endswith("carr_freq"):
                    seen[0] += 1
                    if seen[0] == nth_carrier_write:
                        value += 1
                return write(reg, value, cycle)
            fe.write = tampered
        return fe
    return open_array


@pytest.mark.parametrize("nth, spreads", [(40, True), (100, False)])
def test_one_changed_bus_write_is_caught(window, monkeypatch, nth, spreads):
    """One carrier word 1 LSB off (of 144 carrier writes: 8 hand-overs, 136 from the
    trackers) is caught: on the bus, and in the FIFO words (each later record of that channel
    carries the carrier NCO's phase, now off by 1 LSB per sample until the next write). The
    40th write's shift also crosses a step of the NCO's output, so the I/Q and with them the
    DSP's later writes and the tracker outputs differ; the 100th's does not: the trackers
    and their writes are the same, only the words and the bus write show it."""
    monkeypatch.setattr(multichannel, "open_gnss_array", _tampered_open(nth))
    monkeypatch.setattr(tools_equivalence, "skip_reason", lambda *a, **k: None)
    r = compare_window(window, channels=CHANNELS, backends=("model", "verilator"))
    assert not r["equivalent"] and "mismatches (verilator vs model:" in r["verdict"]
    v = r["per_backend"]["verilator"]
    outs = {k: o["mismatches"] for k, o in v["outputs"].items()}
    fifo = v["mismatches"] - sum(outs.values())        # FIFO words, read cycles, overflow
    assert outs["bus writes"] >= 1                     # the write itself, on the bus
    assert fifo >= 1                                   # the records' carrier phase
    if spreads:
        assert outs["DSP writes"] >= 1 and outs["tracker digest"] == 1
    else:
        assert outs["DSP writes"] == 0 and outs["tracker digest"] == 0


def test_count_differences():
    a = np.array([[1, 2, 3], [4, 5, 6]])
    assert count_differences(a, a.copy()) == 0
    assert count_differences([(1, 2, 3), (4, 5, 7)], a) == 1       # rows of any kind
    assert count_differences(a[:1], a) == 1                          # a missing row
    assert count_differences(None, a) == 2
    assert count_differences("ab", "ab") == 0 and count_differences("ab", "ac") == 1


@pytest.mark.parametrize("argv, match", [
    (["--channels", "4"], "--channels needs --scenario"),
    (["--top", "tacan", "--scenario", "gps"], "--scenario: the tacan top has scenarios none"),
    (["--scenario", "galileo"], "--scenario: no top has the scenario 'galileo'"),
    (["--top", "gnss", "--scenario", "gps", "--samples", "50000"],
     "--samples 50000 is shorter than the acquisition needs: at least 100000"),
    (["--scenario", "gps", "--channels", "13"], "--channels"),
    (["--scenario", "gps", "--stall"], "--stall does not apply to --scenario"),
])
def test_bad_options_are_refused_before_work(capsys, argv, match):
    assert main(["check-equivalence", "--backends", "model,verilator", *argv]) == 2
    assert match in capsys.readouterr().err


def test_bad_arguments_of_the_api():
    with pytest.raises(ValueError, match="--scenario must be one of gps, not 'x'"):
        prepare_window(SHORT, None, scenario="x")
    with pytest.raises(ValueError, match=r"PRN"):
        prepare_window(SHORT, None, prns=[40])
    with pytest.raises(ValueError, match=r"backends must be among"):
        check_array_equivalence(SHORT, backends=("model", "fpga"))


@pytest.mark.slow
@needs_verilator
def test_cli_100_ms_of_the_scenario_model_equals_verilator(capsys):
    """The command's default window (100 ms), all 32 PRNs searched."""
    rc = main(["check-equivalence", "--top", "gnss", "--scenario", "gps",
               "--backends", "model,verilator", "--json"])
    r = json.loads(capsys.readouterr().out)
    assert rc == 0 and r["equivalent"] and r["mismatches"] == 0, r["verdict"]
    sc = r["scenario"]
    assert sc["window_ms"] == 100 and sc["channels"] == 8
    assert sorted(c["prn"] for c in sc["acquired"]) == sorted(sc["prns"])
    assert r["peaks"] >= 8 * 97
    assert [a["status"] for a in sc["assignments"]] == ["tracked"] * 8
    assert all(o["mismatches"] == 0 for o in r["per_backend"]["verilator"]["outputs"].values())
