"""The receiver registry drives the command line: a receiver registered here (a toy, in this
file) gets its subcommand, its options derived from its configuration dataclass, its tops
in ``verilog``/``synth``/``check-equivalence`` and its ``sweep``/``faults`` studies."""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import pytest

from cosim import receivers as reg
from cosim.cli import build_parser, hdl_blocks, main
from cosim.receivers import Arg, Figure, Option, Receiver, Study, config_kwargs


@dataclass(frozen=True)
class ToneConfig:
    """A toy receiver's scenario.

    Parameters
    ----------
    freq_hz : float
        Tone frequency (Hz).
    """

    freq_hz: float = 1e3
    gain_db: float | None = field(default=3.0, metadata={"help": "gain (dB), or 'off'",
                                                          "none": ("off",)})
    n_samples: int = field(default=1000, metadata={"help": "record length (samples)"})
    mode: str = field(default="a", metadata={"help": "mode", "choices": ("a", "b"),
                                             "case": "lower"})
    loud: bool = field(default=False, metadata={"help": "louder"})


OPTIONS = tuple(Option(ToneConfig, n) for n in ("freq_hz", "gain_db", "n_samples", "mode",
                                                 "loud")) + (
    Arg("--json", action="store_true", help="print one JSON object"),)


def _run(a) -> int:
    cfg = ToneConfig(**config_kwargs(a, OPTIONS, ToneConfig))
    err = 0.0 if cfg.gain_db is None else cfg.gain_db / cfg.n_samples
    print(json.dumps({"freq_hz": cfg.freq_hz, "gain_db": cfg.gain_db, "n": cfg.n_samples,
                      "mode": cfg.mode, "loud": cfg.loud, "err_hz": err}))
    return 0


def _equivalence(*, samples, backends, seed, stall, progress):
    return {"top": "tone", "samples": samples, "backends": list(backends), "mismatches": 0,
            "equivalent": True, "verdict": "equivalent"}


class _Top:     # stands for an Amaranth top; not elaborated here
    pass


@dataclass(frozen=True)
class ToneSweep:
    trials: int = field(default=2, metadata={"help": "trials"})


SWEEP = (Option(ToneSweep, "trials"),)


def _sweep(a) -> int:
    print(json.dumps({"sweep": "tone", **config_kwargs(a, SWEEP, ToneSweep)}))
    return 0


@pytest.fixture
def tone():
    r = reg.register(Receiver(
        name="tone", help="a toy tone receiver", config=ToneConfig, options=OPTIONS, run=_run,
        metrics=("err_hz",), primary=Figure("err_hz", "frequency error", "Hz"),
        tops={"tone_top": _Top}, equivalence=_equivalence,
        sweep=Study("toy sweep", SWEEP, _sweep)))
    yield r
    reg.unregister("tone")


def _sub(parser, name):
    return next(a for a in parser._actions if a.dest == name)


def test_a_registered_receiver_gets_its_subcommand_and_options(tone, capsys):
    p = build_parser()
    sub = _sub(p, "command").choices["tone"]
    flags = {o for a in sub._actions for o in a.option_strings}
    assert {"--freq-hz", "--gain-db", "--n-samples", "--mode", "--loud", "--json"} <= flags
    text = sub.format_help()
    assert "Tone frequency (Hz). (default: 1000.0)" in text       # help from the docstring
    assert "record length (samples) (default: 1000)" in text    # help from the metadata
    assert main(["tone", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == {
        "freq_hz": 1e3, "gain_db": 3.0, "n": 1000, "mode": "a", "loud": False, "err_hz": 0.003}
    assert main(["tone", "--freq-hz", "2e3", "--gain-db", "off", "--n-samples", "1e4",
                 "--mode", "B", "--loud"]) == 0
    assert json.loads(capsys.readouterr().out) == {
        "freq_hz": 2e3, "gain_db": None, "n": 10000, "mode": "b", "loud": True, "err_hz": 0.0}


def test_derived_options_check_their_type(tone, capsys):
    for argv, msg in ((["--n-samples", "4.5"], "must be a whole number, not 4.5"),
                      (["--freq-hz", "nan"], "must be a finite number, not nan"),
                      (["--mode", "c"], "invalid choice: 'c'")):
        with pytest.raises(SystemExit) as e:
            main(["tone", *argv])
        assert e.value.code == 2 and msg in capsys.readouterr().err


def test_a_registered_receiver_reaches_the_hdl_commands_and_studies(tone, capsys):
    p = build_parser()
    cmds = _sub(p, "command").choices
    assert "tone" in _sub(cmds["check-equivalence"], "top").choices
    assert "tone" in _sub(cmds["synth"], "top").choices
    assert hdl_blocks()["tone_top"] is _Top and "tacan_frontend" in hdl_blocks()
    assert "tone" in _sub(cmds["sweep"], "receiver").choices
    assert "tone" not in _sub(cmds["faults"], "receiver").choices     # it declares none
    assert main(["check-equivalence", "--top", "tone", "--backends", "model,pysim",
                 "--samples", "100", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["top"] == "tone"
    assert main(["sweep", "tone", "--trials", "5"]) == 0
    assert json.loads(capsys.readouterr().out) == {"sweep": "tone", "trials": 5}


def test_registry_refuses_a_second_receiver_of_one_name(tone):
    with pytest.raises(ValueError, match="already registered"):
        reg.register(Receiver(name="tone", help="x", config=ToneConfig, options=(), run=_run,
                              metrics=("err_hz",), primary=Figure("err_hz", "e", "Hz")))
    with pytest.raises(ValueError, match="no receiver named 'gnss-l9'"):
        reg.get("gnss-l9")
    with pytest.raises(ValueError, match="primary figure 'rmse' must be one of the metrics"):
        Receiver(name="t2", help="x", config=ToneConfig, options=(), run=_run,
                 metrics=("err_hz",), primary=Figure("rmse", "e", "Hz"))


def test_tacan_options_are_its_dataclass_fields_with_their_defaults():
    """The TACAN subcommand keeps its options; every default is the dataclass's."""
    from dsp.tacan.kalman import KalmanConfig
    from cosim.tacan.run import TacanRunConfig
    from cosim.tacan.signal import TacanSignalConfig
    sub = _sub(build_parser(), "command").choices["tacan"]
    acts = {a.option_strings[0]: a for a in sub._actions if a.option_strings}
    assert list(acts) == [
        "-h", "--debug", "--bearing-deg", "--snr-db", "--duration-s", "--seed", "--mode",
        "--mod-15", "--mod-135", "--fs-hz", "--if-hz", "--adc-bits", "--memory-s",
        "--settle-s", "--backend", "--dsp", "--compare", "--dsp-service", "--dsp-stall",
        "--dsp-period-cycles", "--dsp-latency-cycles", "--dsp-batch-words",
        "--dsp-cycles-per-word", "--trace", "--trace-window", "--recheck",
        "--recheck-samples", "--json"]
    sig, run = TacanSignalConfig(), TacanRunConfig()
    for f in ("bearing_deg", "snr_db", "duration_s", "seed", "mode", "mod_15", "mod_135",
              "fs_hz", "if_hz", "adc_bits"):
        assert acts["--" + f.replace("_", "-")].default == getattr(sig, f), f
    for f in ("settle_s", "backend", "dsp", "compare", "trace", "recheck", "recheck_samples"):
        assert acts["--" + f.replace("_", "-")].default == getattr(run, f), f
    assert acts["--memory-s"].default == KalmanConfig().memory_s
