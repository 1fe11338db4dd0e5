"""``python -m cosim ins``: the INS paper's loops on the GNSS channel run (registry entry, JSON
report, INS aiding at the channel's epoch times, bad input -> exit 2), and the aided
Kalman loop's closed loop bit-identical on the bit-exact model, Amaranth and Verilator."""
from __future__ import annotations

import json

import numpy as np
import pytest

from cosim.core import receivers
from cosim.cli import main
from cosim.gnss.config import GnssRunConfig
from cosim.gnss.tracking import SKIP_RECORDS, closed_loop
from cosim.ins.run import InsRunConfig, run_ins
from cosim.backends.verilator_harness import verilator_available
from dsp.gnss.ca_code import ca_code_levels
from hdl.gnss.params import GnssChannelParams

needs_verilator = pytest.mark.skipif(not verilator_available(),
                                     reason="Verilator, make or a C++ compiler not on PATH")

#: A 1 s trajectory with the paper's shape (1 g peak at 5 g/s, 5 m/s cruise).
SHORT = ["--duration-s", "1.0", "--start-s", "0.2", "--accel-g", "1.0", "--v-max-mps", "5"]
SHORT_KW = dict(duration_s=1.0, start_s=0.2, accel_g=1.0, v_max_mps=5.0)


def test_registered_with_options_from_the_configs(capsys):
    r = receivers.get("ins")
    assert r.config is InsRunConfig
    with pytest.raises(SystemExit):
        main(["ins", "--help"])
    out = capsys.readouterr().out
    for flag in ("--loop", "--cn0-dbhz", "--oscillator", "--backend", "--dsp", "--duration-s",
                 "--trajectory-csv", "--settle-s", "--json"):
        assert flag in out
    for loop in ("aided-kf", "aided-pll", "unaided-kf"):
        assert loop in out


def test_json_report_golden_chain(capsys):
    rc = main(["ins", "--loop", "aided-kf", "--cn0-dbhz", "40", "--oscillator", "ocxo",
               "--backend", "golden", "--dsp", "float", "--json"] + SHORT)
    assert rc == 0
    r = json.loads(capsys.readouterr().out)
    for k in ("vel_err_mean_mps", "vel_err_std_mps", "range_err_mean_m", "range_err_std_m",
              "pli_mean", "pli_min", "lock_fraction", "cycle_slips", "digest", "fifo_dropped",
              "disc_rms_jerk_deg"):
        assert k in r, k
    assert r["backend"] == "golden" and r["loop"] == "aided-kf" and r["oscillator"] == "ocxo"
    # 40 dB-Hz, aided: locked, no slip, LOS velocity error of centimetres per second
    assert r["lock_fraction"] == 1.0 and r["cycle_slips"] == 0, r
    assert r["vel_err_std_mps"] < 0.03 and abs(r["vel_err_mean_mps"]) < 0.01, r
    assert r["range_err_std_m"] < 5.0, r


def test_aiding_epochs_are_the_channels_dumps_and_the_loop_holds_lock_on_the_model():
    # the INS rate is told at the epochs the channel dumps on (received code epochs): the
    # predicted boundaries are the channel's own to well under a microsecond
    r = run_ins(InsRunConfig(loop="aided-kf", **SHORT_KW), GnssRunConfig(backend="model", dsp="fixed"))
    s = r["_series"]
    t, b = s["t_s"], s["aiding_boundaries_s"]
    assert np.abs(b[1:1 + t.size] - t).max() < 1e-6
    assert r["lock_fraction"] == 1.0 and r["cycle_slips"] == 0 and r["fifo_dropped"] == 0, r
    assert not any(r["tracker"]["events"].values()), r["tracker"]
    assert r["vel_err_std_mps"] < 0.03, r


def test_the_aiding_carries_the_dynamics():
    # the same run with the INS rate replaced by 0: the aided loop (its Q sized for the INS
    # error, not the 5 g/s jerk) tracks the jerk far worse
    from cosim.ins import ins_error
    run = GnssRunConfig(backend="golden", dsp="float")
    good = run_ins(InsRunConfig(loop="aided-kf", **SHORT_KW), run)
    orig = ins_error.InsAiding.rate_at
    try:
        ins_error.InsAiding.rate_at = lambda self, t: 0.0 * orig(self, t)
        bad = run_ins(InsRunConfig(loop="aided-kf", **SHORT_KW), run)
    finally:
        ins_error.InsAiding.rate_at = orig
    assert bad["vel_err_std_mps"] > 3 * good["vel_err_std_mps"], (good, bad)
    assert bad["disc_rms_jerk_deg"] > good["disc_rms_jerk_deg"], (good, bad)


def _csv(tmp_path, monotonic):
    t = np.linspace(0.0, 2.0, 40)
    if not monotonic:
        t[9] = t[8]
    p = tmp_path / "traj.csv"
    np.savetxt(p, np.c_[t, 3.0 * t ** 2], delimiter=",")
    return str(p)


@pytest.mark.parametrize("argv,msg", [
    (["--cn0-dbhz", "nan"], None),
    (["--loop", "pll9"], None),
    (["--oscillator", "rubidium"], None),
    (["--duration-s", "0"], "error: duration_s must be a finite number > 0"),
    (["--duration-s", "20"], "error: duration_s must cover the manoeuvre (start_s + 26.93 s), not 20.0"),
    (["--jerk-g-s", "-5"], "error: jerk_g_s must be a finite number > 0, not -5.0"),
    (["--pli-epochs", "0"], "error: pli_epochs must be an integer in [1, 1000], not 0"),
    (["--backend", "pysim", "--duration-s", "150"], "error: 2,469,068,800 cycles on the pysim "
     "backend (about 2e+03 cycles/s; --duration-s 150.7) would take about 343 h on this machine "
     "(limit 2 h): reduce --duration-s"),
    (["--trajectory-csv", "NONMONO"], "error: --trajectory-csv '{csv}' line 10, column 1: time "
                                      "must increase strictly"),
    (["--trajectory-csv", "GOOD", "--duration-s", "5"], "error: trajectory_csv '{good}' ends at 2 s: "
     "it must cover duration_s + 0.05 s"),
])
def test_bad_input_exits_2_with_an_error_line(argv, msg, capsys, tmp_path):
    csv = _csv(tmp_path, monotonic=False)
    (tmp_path / "ok").mkdir()
    good = _csv(tmp_path / "ok", monotonic=True)
    argv = [{"NONMONO": csv, "GOOD": good}.get(a, a) for a in argv]
    if msg is None:         # argparse refuses it (exit 2, usage)
        with pytest.raises(SystemExit) as e:
            main(["ins"] + argv)
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert "invalid choice" in err or "must be a finite number, not nan" in err, err
        return
    assert main(["ins"] + argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(msg.format(csv=csv, good=good)), err


def test_csv_trajectory_runs(tmp_path):
    r = run_ins(InsRunConfig(loop="aided-kf", duration_s=1.0, trajectory_csv=_csv(tmp_path, True)),
                GnssRunConfig(backend="golden", dsp="float"))
    assert r["lock_fraction"] == 1.0 and r["disc_rms_jerk_deg"] is None


# -- the aided Kalman loop closed on the HDL channel: same bits on every backend ----------
SMALL = GnssChannelParams(fs_hz=2.046e6, if_hz=0.3e6, el_spacing_samples=2, slew_bits=12,
                          carr_table_bits=6, lo_bits=3, fifo_depth=64, prn=3)
DOPPLER_HZ, RATE_HZ_S, CODE_PHASE = 1500.0, 200.0, 600.0


def _signal(n, seed=5):
    """PRN 3 at the channel's IF + 1500 Hz + 200 Hz/s, code phase 600 chips at sample 0."""
    t = np.arange(n) / SMALL.fs_hz
    ph = (SMALL.if_hz + DOPPLER_HZ) * t + RATE_HZ_S * t * t / 2
    chips = np.floor(CODE_PHASE + t * 1.023e6 + (DOPPLER_HZ * t + RATE_HZ_S * t * t / 2) / 1540
                     ).astype(np.int64)
    s = ca_code_levels(3)[chips % 1023] * np.cos(2 * np.pi * ph + 0.7)
    x = s * 1.2 + np.random.default_rng(seed).normal(0, 0.6, n)
    return np.clip(np.floor(x), -2, 1).astype(np.int64)


def _run(backend, x, dsp="fixed", block=700):
    run = GnssRunConfig(dsp=dsp, tracker="aided-kf")
    extra = ({"aiding": lambda k: RATE_HZ_S, "doppler0_sigma_hz": 3.0}, {"oscillator": "ocxo"})
    return closed_loop(backend, SMALL, run, (x[k:k + block] for k in range(0, x.size, block)),
                       DOPPLER_HZ + 2.0, CODE_PHASE, keep_words=True, tracker_extra=extra)


def _same(a, b):
    pa, pb = a.pipeline, b.pipeline
    np.testing.assert_array_equal(pa.words, pb.words)
    np.testing.assert_array_equal(pa.cycles, pb.cycles)
    assert pa.writes == pb.writes
    assert a.bus_writes == b.bus_writes
    assert a.track.words == b.track.words
    assert a.track.doppler == b.track.doppler
    assert a.track.digest() == b.track.digest()
    assert pa.digest == pb.digest


def test_aided_kf_closed_loop_on_the_model_tracks_the_rate():
    x = _signal(120 * 2046)
    a = _run("model", x)
    _same(a, _run("model", x, block=4093))
    tr = a.track
    assert len(tr.words) == tr.n_seen - SKIP_RECORDS >= 115
    prompt = np.array([o[3] + 1j * o[4] for o in tr.obs])
    assert np.mean(np.abs(prompt[-30:].real)) > 3 * np.mean(np.abs(prompt[-30:].imag))
    # the Doppler estimate follows 1500 Hz + 200 Hz/s (at the end of each record)
    t_end = (np.arange(len(tr.doppler)) + SKIP_RECORDS + 1) * 1e-3
    err = np.array(tr.doppler) - (DOPPLER_HZ + RATE_HZ_S * t_end)
    assert np.abs(err[-30:]).mean() < 3.0, err[-30:]


def test_aided_kf_closed_loop_model_equals_pysim():
    x = _signal(14 * 2046)
    m = _run("model", x)
    assert len(m.track.words) >= 11
    _same(m, _run("pysim", x))


@needs_verilator
def test_aided_kf_closed_loop_model_equals_verilator():
    x = _signal(40 * 2046)
    for dsp in ("fixed", "float"):
        m = _run("model", x, dsp)
        assert len(m.track.words) >= 37
        _same(m, _run("verilator", x, dsp))


def test_boundary_replay_in_blocks_equals_one_pass():
    # the dump-boundary replay runs in blocks (a 150 s record would not fit in one array)
    from cosim.gnss.handover import handover_writes
    from cosim.gnss.tracking import record_boundaries
    regs = SMALL.registers
    w = [(c, regs.address(r), v) for c, r, v in handover_writes(SMALL, 1500.0, 600.0)]
    w += [(5000 + 2046 * j, regs.address("code_freq"), SMALL.code_word(1.023e6 + 40.0 * j))
          for j in range(8)]
    one = record_boundaries(SMALL, w, 30, 31 * 2046, block=1 << 30)
    assert one.size == 30
    for block in (999, 2046, 7000):
        np.testing.assert_array_equal(record_boundaries(SMALL, w, 30, 31 * 2046, block=block), one)


def test_the_aiding_table_covers_every_received_code_epoch_of_the_paper_record():
    # the paper's 150 s, closing on the satellite at up to 8300 m/s: the received code has
    # more epochs than the record's milliseconds (its Doppler, 27 ppm), and the loop asks
    # for the next epoch's rate; the table holds them all (truth only, no samples)
    from cosim.gnss.signal import GnssSignalGenerator
    from cosim.ins.ins_error import EpochAiding, InsAiding, InsErrors
    from cosim.ins.run import (first_tracked_boundary_s, ins_signal, record_epoch_boundaries)
    from cosim.ins.trajectory import Geometry, Scenario
    cfg = InsRunConfig()
    sc = Scenario(cfg.trajectory(), Geometry(), None, seed=cfg.seed)
    gen = GnssSignalGenerator(ins_signal(cfg, sc))
    tr = gen.truth_at([0.0])
    hand = {"doppler_hz": float(tr["doppler_hz"][0]),
            "code_phase_chips": float(tr["code_phase_chips"][0])}
    t0 = first_tracked_boundary_s("golden", None, hand, False)
    b = record_epoch_boundaries(gen, t0)
    assert np.all(np.diff(b) > 0)
    assert b[-4] < cfg.duration_s <= b[-3]      # the last epoch that starts in the record
    assert b.size - 1 > int(cfg.duration_s / 1e-3) + 2      # more than the record's ms
    ins = InsAiding(sc, InsErrors(), 1e-3, int(round(cfg.duration_s / 1e-3)) + 20, seed=cfg.seed)
    aid = EpochAiding(ins, b[b <= ins.t[-1]])
    assert aid.rate.size == b.size - 1
