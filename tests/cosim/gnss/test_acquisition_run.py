"""A GNSS run's acquisition on the flowing record (cosim.gnss.handover): the search reads
the record from its start, tracking starts where it stopped with the Doppler and code phase
propagated there; the acquisition options of every GNSS command, their bad values pinned."""
import numpy as np
import pytest

from cosim.cli import main
from cosim.gnss.config import GnssRunConfig
from cosim.gnss.handover import RecordFrom, acquired_record, acquisition_span_ms
from cosim.gnss.run import run_gnss
from cosim.gnss.signal import GnssSignalConfig, GnssSignalGenerator


def test_record_from_is_the_record_later():
    sig = GnssSignalConfig(cn0_dbhz=40.0, duration_s=0.05, seed=2, code_phase_chips=12.5)
    full = GnssSignalGenerator(sig.replace(duration_s=0.1))
    v = RecordFrom(full, 16368 * 7 + 3, sig)
    assert np.array_equal(v.samples(100, 5000)[0], full.samples(16368 * 7 + 103, 5000)[0])
    t = np.array([0.0, 0.01])
    a, b = v.truth_at(t), full.truth_at(t + v.t0_s)
    assert np.array_equal(a["t_s"], t) and np.allclose(a["code_phase_chips"], b["code_phase_chips"])
    # the IF phase the mixer has run through by n0 is in the view's carrier truth
    d = (a["carrier_phase_cycles"] - b["carrier_phase_cycles"]) % 1.0
    assert np.allclose(d, (v.n0 * sig.digital_if_hz / sig.fs_hz) % 1.0)
    with pytest.raises(ValueError, match="the record holds"):
        RecordFrom(full, 16368 * 60, sig)


def test_30_dbhz_handover_is_at_the_start_of_tracking():
    """The search needs > 1 dwell at 30 dB-Hz; the hand-over (refined, propagated to the
    first tracked sample) is within 3 Hz and 0.1 chip of the truth there."""
    sig = GnssSignalConfig(prn=5, cn0_dbhz=30.0, duration_s=0.2, seed=4, code_phase_chips=401.3)
    acq, hand, view = acquired_record(sig, GnssRunConfig())
    assert acq["detected"] and acq["t_detect_s"] > 0.01 and acq["search"] == "sequential"
    assert view.t0_s == pytest.approx(acq["t_start_s"]) and hand["n_start"] == view.n0
    tr = view.truth_at([0.0])
    assert abs(hand["doppler_hz"] - tr["doppler_hz"][0]) < 3.0
    dc = (hand["code_phase_chips"] - tr["code_phase_chips"][0] + 511.5) % 1023 - 511.5
    assert abs(dc) < 0.1
    assert acquisition_span_ms(GnssRunConfig()) == 700


def test_a_fixed_dwell_too_short_for_30_dbhz_stops_with_its_message():
    sig = GnssSignalConfig(prn=5, cn0_dbhz=30.0, duration_s=0.2, seed=4)
    with pytest.raises(ValueError, match=r"acquisition did not find PRN 5 within 5 ms of "
                                         r"signal \(last look 1 ms x 5"):
        acquired_record(sig, GnssRunConfig(acq_coherent_ms=1, acq_noncoherent=5))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 5])
def test_gnss_at_30_dbhz_starts_and_tracks(seed):
    r = run_gnss(GnssSignalConfig(cn0_dbhz=30.0, duration_s=1.0, seed=seed), GnssRunConfig())
    assert r["acquired"]["detected"]
    assert r["cycle_slips"] == 0 and r["doppler_rmse_hz"] < 2.0, r


@pytest.mark.parametrize("cmd, args, msg", [
    ("gnss", ["--coherent-ms", "25", "--noncoherent", "2"],
     "error: --coherent-ms must be a whole number in 1..20, not 25"),
    ("gnss", ["--coherent-ms", "10"], "error: --coherent-ms and --noncoherent go together"),
    ("gnss", ["--coherent-ms", "1", "--noncoherent", "0"],
     "error: --noncoherent must be a whole number >= 1, not 0"),
    ("gnss", ["--coherent-ms", "20", "--noncoherent", "30"],
     "error: --coherent-ms 20 x --noncoherent 30 needs 615 ms of signal (bit-edge offsets "
     "included): more than --acq-limit-ms 500"),
    ("gnss", ["--acq-limit-ms", "5"],
     "error: --acq-limit-ms 5 is shorter than the first dwell (1 ms x 5/10: 10 ms of signal)"),
    ("gnss", ["--pfa", "0"], "error: --pfa must be a finite number > 0 and < 1, not 0.0"),
    ("ins", ["--coherent-ms", "21", "--noncoherent", "1"],
     "error: --coherent-ms must be a whole number in 1..20, not 21"),
    ("ins", ["--noncoherent", "3"], "error: --coherent-ms and --noncoherent go together"),
    ("gnss-acquire", ["--file", "x.bin", "--format", "int8", "--fs-hz", "4e6",
                      "--coherent-ms", "0", "--noncoherent", "3"],
     "error: --coherent-ms must be a whole number in 1..20, not 0"),
    ("gnss-acquire", ["--file", "x.bin", "--format", "int8", "--fs-hz", "4e6",
                      "--search", "verified", "--coherent-ms", "5", "--noncoherent", "3",
                      "--stages", "1x10"],
     "error: give --stages or --coherent-ms / --noncoherent, not both"),
    ("gnss-acquire", ["--file", "x.bin", "--format", "int8", "--fs-hz", "4e6",
                      "--stages", "1x10"],
     "error: --stages is the schedule of --search verified"),
    ("gnss-acquire", ["--file", "x.bin", "--format", "int8", "--fs-hz", "4e6",
                      "--search", "verified", "--acq-limit-ms", "100"],
     "error: --acq-limit-ms limits the sequential search"),
    ("gnss-acquire", ["--file", "x.bin", "--format", "int8", "--fs-hz", "4e6",
                      "--acq-limit-ms", "5"],
     "error: --acq-limit-ms 5 is shorter than the first dwell (1 ms x 5/10: 10 ms of signal)"),
    ("gnss-acquire", ["--file", "x.bin", "--format", "int8", "--fs-hz", "4e6",
                      "--coherent-ms", "5"],
     "error: --coherent-ms and --noncoherent go together"),
    ("gnss-acquire", ["--file", "x.bin", "--format", "int8", "--fs-hz", "4e6", "--pfa", "1.5"],
     "error: --pfa must be a finite number > 0 and < 1, not 1.5"),
])
def test_bad_acquisition_options_one_error_line_exit_2(cmd, args, msg, capsys):
    assert main([cmd] + args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(msg), err


@pytest.mark.parametrize("cmd", ["gnss", "ins", "gnss-acquire"])
def test_a_fractional_coherent_time_is_refused_by_the_parser(cmd, capsys):
    with pytest.raises(SystemExit) as e:
        main([cmd, "--coherent-ms", "2.5"])
    assert e.value.code == 2
    assert "argument --coherent-ms: must be a whole number, not 2.5" in capsys.readouterr().err
