"""``python -m cosim synth --top gnss --channels N``: the array top through the receiver
registry (``Receiver.array_top``); argument errors before any tool runs."""
from __future__ import annotations

import json

import pytest

from cosim.cli import main
from cosim.core.receivers import get
from cosim.tools.synth import yowasp_available
from hdl.gnss.channel import GnssChannel, GnssChannelArray


def test_registry_builds_the_array_top():
    rx = get("gnss")
    assert rx.array_top is not None and rx.equivalence is not None
    top, one = rx.array_top(12), rx.array_top(1)
    # built, not elaborated: silence Amaranth's unused-elaboratable warning
    for c in (top, one, top._fifo, one._fifo):
        c._MustUse__silence = True
    assert isinstance(top, GnssChannelArray) and top.channels == 12
    assert isinstance(one, GnssChannel)
    assert get("tacan").array_top is None


def test_registry_builds_the_complex_input_variant():
    rx = get("gnss")
    top, one = rx.variants["iq"](12), rx.variants["iq"](1)
    for c in (top, one, top._fifo, one._fifo):
        c._MustUse__silence = True
    assert isinstance(top, GnssChannelArray) and top.channels == 12
    assert isinstance(one, GnssChannel)
    assert top.params.input == one.params.input == "complex" and one.params.if_hz == 0.0
    assert {"gnss_channel_iq", "gnss_channel_array12_iq"} <= set(rx.tops)


@pytest.mark.parametrize("argv, msg", [
    (["--top", "gnss", "--variant", "cplx"],
     "error: --variant: the gnss top has variants iq, not 'cplx'"),
    (["--top", "tacan", "--variant", "iq"],
     "error: --variant: the tacan top has variants none, not 'iq'"),
    (["--top", "gnss", "--variant", "iq", "--channels", "65"],
     "error: GNSS channel array needs channels in [1, 64], not 65"),
    (["--top", "tacan", "--channels", "3"],
     "error: --channels: the tacan top has no multi-channel array (only --channels 1), not 3"),
    (["--top", "gnss", "--channels", "0"],
     "error: GNSS channel array needs channels in [1, 64], not 0"),
    (["--top", "gnss", "--channels", "65"],
     "error: GNSS channel array needs channels in [1, 64], not 65"),
    (["--top", "gnss", "--timeout-min", "0"],
     "error: --timeout-min must be in (0, 1440] minutes, not 0"),
])
def test_bad_arguments_refused_before_work(argv, msg, capsys, monkeypatch, tmp_path):
    import cosim.tools.synth as synth_mod

    def never(*a, **k):
        raise AssertionError("synthesis started")
    monkeypatch.setattr(synth_mod, "synth", never)
    assert main(["synth", "--out", str(tmp_path), *argv]) == 2
    assert capsys.readouterr().err.strip() == msg


@pytest.mark.synth
@pytest.mark.slow
@pytest.mark.skipif(not yowasp_available(), reason="YoWASP yosys / nextpnr not installed")
def test_one_channel_through_the_cli_meets_100mhz(tmp_path, capsys):
    rc = main(["synth", "--top", "gnss", "--out", str(tmp_path / "out"), "--results",
               str(tmp_path), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["channels"] == 1 and out["fmax_mhz"] >= 100, out
    rec = json.loads((tmp_path / "synth_gnss.json").read_text())
    assert rec["timing_met"] and rec["tools"]["yosys"].startswith("Yosys")
    assert "nextpnr" in rec["tools"]["nextpnr-ecp5"] and rec["wall_s"] > 0
