"""The receiver registry drives the command line: a receiver registered here (a toy, in this
file) gets its subcommand, its options derived from its configuration dataclass, its tops
in ``verilog``/``synth``/``check-equivalence`` and its ``sweep``/``faults`` studies."""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import pytest

from cosim.core import receivers as reg
from cosim.cli import build_parser, hdl_blocks, main
from cosim.core.receivers import (Arg, Figure, Frontend, Option, Receiver, Study, SweepModel,
                                  config_kwargs)


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
    with pytest.raises(ValueError, match=r"stream_cases of tops it does not have: \['t2_top'\]"):
        Receiver(name="t2", help="x", config=ToneConfig, options=(), run=_run,
                 metrics=("err_hz",), primary=Figure("err_hz", "e", "Hz"),
                 stream_cases={"t2_top": lambda *a: {}})


def test_tacan_options_are_its_dataclass_fields_with_their_defaults():
    """The TACAN subcommand keeps its options; every default is the dataclass's."""
    from dsp.tacan.kalman_config import KalmanConfig
    from cosim.tacan.config import TacanRunConfig
    from cosim.tacan.signal import TacanSignalConfig
    sub = _sub(build_parser(), "command").choices["tacan"]
    acts = {a.option_strings[0]: a for a in sub._actions if a.option_strings}
    assert list(acts) == [
        "-h", "--debug", "--bearing-deg", "--snr-db", "--duration-s", "--seed", "--mode",
        "--mod-15", "--mod-135", "--fs-hz", "--if-hz", "--adc-bits", "--rotation-hz",
        "--memory-s",
        "--settle-s", "--backend", "--dsp", "--compare", "--noise-floor", "--amplitude",
        "--detector", "--dsp-service",
        "--dsp-stall",
        "--dsp-period-cycles", "--dsp-latency-cycles", "--dsp-batch-words",
        "--dsp-cycles-per-word", "--trace", "--trace-window", "--recheck",
        "--recheck-samples", "--json"]
    sig, run = TacanSignalConfig(), TacanRunConfig()
    for f in ("bearing_deg", "snr_db", "duration_s", "seed", "mode", "mod_15", "mod_135",
              "fs_hz", "if_hz", "adc_bits", "rotation_hz"):
        assert acts["--" + f.replace("_", "-")].default == getattr(sig, f), f
    for f in ("settle_s", "backend", "dsp", "compare", "noise_floor", "amplitude", "detector", "trace", "recheck",
              "recheck_samples"):
        assert acts["--" + f.replace("_", "-")].default == getattr(run, f), f
    assert acts["--memory-s"].default == KalmanConfig().memory_s


# -- a toy receiver with a front end and a sweep model --------------------------------------
# "gain": the front end multiplies each input word by a register ``gain`` (an Amaranth
# stream block, combinational, back-pressure passed through) and has a numpy model session;
# its sweep quantises a noisy tone to ``in_bits`` bits, runs it through the front end's
# model session and scores the RMS error against the float (golden) record.
@dataclass(frozen=True)
class GainParams:
    in_bits: int = 8
    gain: int = 3

    @property
    def out_bits(self) -> int:
        return self.in_bits + 4


def _gain_component(p: GainParams):
    from amaranth.hdl import Module, Signal, unsigned
    from amaranth.lib import stream, wiring
    from amaranth.lib.wiring import In, Out

    class GainBlock(wiring.Component):    # (string annotations here: the signature given)
        def __init__(self):
            super().__init__({"i": In(stream.Signature(unsigned(p.in_bits))),
                              "o": Out(stream.Signature(unsigned(p.out_bits))),
                              "gain": In(unsigned(4), init=p.gain)})

        def elaborate(self, platform):
            m = Module()
            n_out = Signal(16)       # words out (the clock domain the simulators drive)
            with m.If(self.o.valid & self.o.ready):
                m.d.sync += n_out.eq(n_out + 1)
            m.d.comb += [self.o.valid.eq(self.i.valid), self.i.ready.eq(self.o.ready),
                         self.o.payload.eq(self.i.payload * self.gain)]
            return m
    return GainBlock()


def _gain_model_session(p: GainParams, log_ranges: bool = False):
    import numpy as np
    from cosim.core.session import FrontendSession, ready_window

    class GainModelSession(FrontendSession):
        backend = "model"

        def __init__(self):
            super().__init__()
            self.gain = p.gain

        def _check_port(self, port):
            if port != "gain":
                raise KeyError(port)

        def _read(self, port):
            self._check_port(port)
            return self.gain

        def _step(self, queue, ready, n, writes):
            g = np.full(n, self.gain, np.int64)
            for c, _port, v in writes:              # in force from cycle c
                g[c - self.cycle:] = v
                self.gain = v
            r = ready_window(ready, self.cycle, n)
            at = np.arange(n) if r is None else np.flatnonzero(r)
            at = at[:queue.size]
            words = np.asarray(queue[:at.size], np.int64) * g[at]
            return words, self.cycle + at, at.size
    return GainModelSession()


GAIN_FRONTEND = Frontend(params=GainParams, component=_gain_component,
                         model=_gain_model_session, verilog_name="gain_block",
                         inputs=lambda p: {"gain": p.gain})


class _GainRecord:
    """One (SNR, trial) record: a tone in noise, the same for every point and the golden."""

    def __init__(self, cfg, snr_db, trial, combos):
        import numpy as np
        rng = np.random.default_rng([cfg.seed, trial, int(round(snr_db * 1000))])
        n = int(cfg.duration_s * 1000)
        self.truth = 0.5 + 0.4 * np.sin(np.arange(n) * 0.05)
        self.x = np.clip(self.truth + 10 ** (-snr_db / 20) * 0.1 * rng.standard_normal(n), 0, 1)
        self.base = {"n_samples": n}
        self.cfg = cfg

    def _shown(self, y):
        """What a user sees: every sample an estimate, valid, misleading beyond 0.25 FS."""
        import numpy as np
        from dsp.shown import shown_figures
        t = np.arange(self.truth.size) / 1000.0
        return shown_figures(t, y - self.truth, np.ones(t.size, bool),
                             settle_s=2 * self.cfg.memory_s, end_s=self.cfg.duration_s,
                             epoch_s=0.01, bound=0.25)

    def golden(self):
        import numpy as np
        return {"err_rms": float(np.sqrt(np.mean((self.x - self.truth) ** 2))),
                "shown": self._shown(self.x)}

    def point(self, combo, recheck=False):
        import numpy as np
        from cosim.backends.factory import open_frontend
        p = GainParams(**dict(combo))
        codes = np.round(self.x * ((1 << p.in_bits) - 1)).astype(np.int64)
        with open_frontend("model", p) as fe:
            w = fe.step(codes).words
        y = w / (p.gain * ((1 << p.in_bits) - 1))
        return {"err_rms": float(np.sqrt(np.mean((y - self.truth) ** 2))), "shown": self._shown(y)}


def _gain_check_param(name):
    if name not in ("in_bits", "gain"):
        raise ValueError(f"unknown parameter {name!r}: use in_bits or gain")


def _gain_check_point(cfg, combo):
    d = dict(combo)
    if not 2 <= d.get("in_bits", 8) <= 16:
        raise ValueError(f"in_bits must be 2..16, not {d['in_bits']}")


GAIN_SWEEP_MODEL = SweepModel(check_param=_gain_check_param, check_point=_gain_check_point,
                              record=_GainRecord, default_params=(("in_bits", (4, 8)),),
                              cpu_s_per_record_s=0.01, title="gain quantisation sweep",
                              description="Path: the gain block's model session.")


@dataclass(frozen=True)
class GainSweep:
    trials: int = field(default=2, metadata={"help": "trials"})
    out: str = field(default="build/studies/gain", metadata={"help": "output directory"})


GAIN_SWEEP = (Option(GainSweep, "trials"), Option(GainSweep, "out"),
              Arg("--param", action="append", default=[], help="NAME=VALUES"))


def _gain_sweep(a) -> int:
    from cosim.studies.spec import SweepConfig, parse_param
    from cosim.studies.sweep import check_points, study
    cfg = SweepConfig(receiver="gain", params=tuple(parse_param(t, "gain") for t in a.param),
                      snr_db=(10.0, 30.0), trials=a.trials, duration_s=1.0, memory_s=0.25,
                      recheck=0, target_rel=0.05)
    check_points(cfg)
    s = study(cfg, a.out, jobs=1, progress=False)
    print(json.dumps({"proposal": s["proposal"], "n_points": s["n_points"],
                      "confirmed": s["confirmation"]["confirmed"]}))
    return 0


@pytest.fixture
def gain():
    r = reg.register(Receiver(
        name="gain", help="a toy gain receiver", config=GainParams, options=(), run=_run,
        metrics=("err_rms",), primary=Figure("err_rms", "RMS error", "FS"),
        frontend=GAIN_FRONTEND,
        sweep=Study("toy gain sweep", GAIN_SWEEP, _gain_sweep, model=GAIN_SWEEP_MODEL)))
    yield r
    reg.unregister("gain")


def test_open_frontend_finds_a_registered_front_end(gain):
    """open_frontend looks the front end up in the registry by its parameter class: the
    numpy model session and the Amaranth block on pysim give the same words and cycles,
    a register write included."""
    import numpy as np
    from cosim.backends.factory import open_frontend
    p = GainParams(in_bits=6, gain=5)
    x = np.random.default_rng(1).integers(0, 64, 200)
    ready = np.random.default_rng(2).random(300) < 0.7
    out = {}
    for backend in ("model", "pysim"):
        with open_frontend(backend, p) as fe:
            assert fe.read("gain") == 5
            r1 = fe.step(x[:120], ready[:150], n_cycles=150)
            fe.write("gain", 2, cycle=fe.cycle + 10)
            r2 = fe.step(x[120:], ready[150:], n_cycles=150)
            assert fe.read("gain") == 2
            out[backend] = (np.r_[r1.words, r2.words], np.r_[r1.cycles, r2.cycles])
    np.testing.assert_array_equal(out["model"][0], out["pysim"][0])
    np.testing.assert_array_equal(out["model"][1], out["pysim"][1])
    assert out["model"][0].size == x.size
    with pytest.raises(TypeError, match="no front end registered for parameters of type "
                                        "ToneConfig"):
        open_frontend("model", ToneConfig())


def test_a_registered_sweep_model_runs_through_the_generic_engine(gain, tmp_path, capsys):
    """``sweep gain`` validates its parameters up front through its model, then runs the
    generic engine (grid, cache, paired golden, proposal, confirmation, report)."""
    import csv
    from cosim.studies.spec import SweepConfig
    with pytest.raises(ValueError, match="unknown parameter 'adc_bits': use in_bits or gain"):
        SweepConfig(receiver="gain", params=(("adc_bits", (4,)),))
    with pytest.raises(ValueError, match="no receiver named"):
        SweepConfig(receiver="nope")
    assert SweepConfig(receiver="gain").params == (("in_bits", (4, 8)),)
    out = tmp_path / "g"
    assert main(["sweep", "gain", "--param", "in_bits=3,6,10", "--trials", "2",
                 "--out", str(out)]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["n_points"] == 3 * 2 * 2 and s["confirmed"] is True
    assert s["proposal"]["in_bits"] in (6, 10)
    rows = list(csv.DictReader((out / "summary.csv").read_text().splitlines()))
    assert {"in_bits", "err_rms", "golden_err_rms", "ratio_to_golden"} <= set(rows[0])
    assert len(rows) == 6 and (out / "report.md").read_text().startswith(
        "# gain quantisation sweep")
    assert len(list((out / "points").glob("*.json"))) == 3 * 2 * 2 + 2 * 2
    # resumed from the cache: the same summary
    before = (out / "summary.csv").read_text()
    assert main(["sweep", "gain", "--param", "in_bits=3,6,10", "--trials", "2",
                 "--out", str(out)]) == 0
    assert (out / "summary.csv").read_text() == before
