"""The multi-channel closed loop's mechanism: the array session against single channels, the
dump boundaries the DSP derives against the HDL replay, the mid-run hand-over."""
from pathlib import Path

import numpy as np
import pytest

from cosim.backends.verilator_harness import verilator_available
from cosim.gnss.config import GnssRunConfig
from cosim.gnss.files import SampleFile
from cosim.gnss.multichannel import Candidate, TrackConfig, channel_params_for, track_file
from cosim.gnss.multichannel_session import array_channel_params, open_gnss_array
from cosim.gnss.synthetic_file import SatelliteSpec, write_synthetic
from cosim.gnss.tracking import SKIP_RECORDS, record_boundaries
from dsp.records import receive_records
from hdl.gnss.model import GnssChannelModel
from hdl.gnss.params import GnssChannelParams

DATA = Path(__file__).resolve().parents[2] / "data" / "gnss"
REAL = DATA / "L1_20211125_004000_12MHz_I_70ms.bin"


def _stimulus(p, n, channels, seed=3):
    rng = np.random.default_rng(seed)
    x = rng.integers(-2, 2, n)
    writes = []
    for ch in range(channels):
        name = (lambda r: r) if channels == 1 else (lambda r, c=ch: f"ch{c}.{r}")
        writes += [(0, name("prn"), 3 + 5 * ch),
                   (1, name("carr_freq"), p.carr_word(p.if_hz + 300.0 * ch)),
                   (2, name("slew"), 17 * ch)]
        for k, c in enumerate(range(3000 + 700 * ch, n, 2500)):
            writes.append((c, name("code_freq"), p.code_word(1.023e6 + 5.0 * (k % 3 - 1))))
    return x, sorted(writes, key=lambda w: w[0])


def _run_session(backend, p, channels, x, writes):
    with open_gnss_array(backend, p, channels) as fe:
        for c, r, v in writes:
            fe.write(r, v, cycle=c)
        r1 = fe.step(x, None, n_cycles=x.size)
        if hasattr(fe, "end_input"):
            fe.end_input()
        r2 = fe.step(None, None, n_cycles=p.latency + 64 * p.fifo.record_words * channels)
        return (np.r_[r1.words, r2.words], np.r_[r1.cycles, r2.cycles], list(fe.bus_writes),
                int(fe.read("overflow_count")))


def test_array_session_records_are_the_single_channels_records():
    channels = 3
    p = array_channel_params(GnssChannelParams(fs_hz=4e6, if_hz=1.25e6, el_spacing_samples=2),
                             channels)
    x, writes = _stimulus(p, 60_000, channels)
    words, _, bus, ovf = _run_session("model", p, channels, x, writes)
    assert ovf == 0
    fp = p.fifo
    b = receive_records(words, width=fp.width, record_words=fp.record_words, parity=fp.parity)
    got = {ch: [] for ch in range(channels)}
    for row in b.records:
        d = p.record.unpack(sum(int(w) << (j * fp.width) for j, w in enumerate(row)))
        got[d.pop("channel")].append(d)
    one = GnssChannelParams(fs_hz=4e6, if_hz=1.25e6, el_spacing_samples=2)
    for ch in range(channels):
        m = GnssChannelModel(one)
        r = m.step(x, [(c, a % 4, v) for c, a, v in bus if a // 4 == ch])
        want = [one.record.unpack(v) for v in r.values(one)]
        assert len(want) >= 13
        assert got[ch] == want


@pytest.mark.slow
@pytest.mark.skipif(not verilator_available(), reason="Verilator not installed")
def test_array_model_and_verilator_give_the_same_words():
    channels = 3
    p = array_channel_params(GnssChannelParams(fs_hz=4e6, if_hz=1.25e6, el_spacing_samples=2),
                             channels)
    x, writes = _stimulus(p, 20_000, channels)
    a = _run_session("model", p, channels, x, writes)
    b = _run_session("verilator", p, channels, x, writes)
    assert a[0].size > 0
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[3] == b[3]


@pytest.mark.parametrize("channels", [1, 3])
def test_dump_boundaries_from_the_records_are_the_hdl_replay(channels):
    """The boundary the DSP derives from every record (CodeEpochs) is the sample the HDL
    channel dumps at, replayed from its bus writes (record_boundaries)."""
    f = SampleFile(REAL, "int8", 12e6, 3e6)
    cands = [Candidate(20, -1347.8, 326.363, 47.8), Candidate(13, -242.4, 511.156, 49.3),
             Candidate(5, 146.0, 544.673, 49.2)][:channels]
    m = track_file(f, cands, GnssRunConfig(), TrackConfig(channels=channels),
                   n_samples=30 * 12_000)
    p1 = channel_params_for(f)
    for a in m.assignments:
        bus = [(c, ad % 4, v) for c, ad, v in m.bus_writes if ad // 4 == a.channel]
        n_b = record_boundaries(p1, bus, len(a.t) + SKIP_RECORDS, m.n_samples)
        got = np.rint(np.asarray(a.t) * f.fs_hz).astype(np.int64)
        assert got.size >= 25
        assert np.array_equal(got, n_b[SKIP_RECORDS:SKIP_RECORDS + got.size])


def test_a_false_candidate_is_dropped_and_the_channel_takes_the_next(tmp_path):
    """A candidate absent from the signal never locks: its channel drops it after the
    pull-in time and takes the next candidate, re-acquired on the samples before it and
    handed over at the channel's next boundary: the prompt is on the code from the first
    window (full C/N0; the carrier phase pulls in during it), lock follows."""
    path = tmp_path / "two.bin"
    sats = [SatelliteSpec(12, 1320.0, 300.7, 45.0, 0.2), SatelliteSpec(21, -2150.0, 811.2,
                                                                        42.0, 0.6)]
    write_synthetic(path, "int8", 4e6, 1.25e6, 0.2, sats, seed=9)
    f = SampleFile(path, "int8", 4e6, 1.25e6)
    cands = [Candidate(9, 700.0, 500.0, 60.0), Candidate(12, 1320.0, 300.7, 45.0),
             Candidate(21, -2150.0, 811.2, 42.0)]
    m = track_file(f, cands, GnssRunConfig(), TrackConfig(channels=2, pull_in_ms=70))
    by = {(a.prn, a.channel): a for a in m.assignments}
    fake = by[(9, 0)]
    assert fake.status == "dropped" and fake.lock_sample is None
    assert "no lock" in fake.end_reason
    assert by[(12, 1)].status == "tracked"
    new = by[(21, 0)]
    assert [r["prn"] for r in m.reacquisitions] == [21] and m.reacquisitions[0]["found"]
    assert new.candidate.source == "re-acquired"
    assert new.status == "tracked"
    assert new.win_cn0[0] > 38.0 and new.win_pli[1] > 0.9      # on the code from the start
    assert new.start_sample > fake.end_sample
    assert abs(np.mean(new.doppler[-20:]) - (-2150.0)) < 5.0
    assert m.pipeline.overflow_count == 0


def test_refusals_name_the_option(tmp_path):
    with pytest.raises(ValueError, match="--channels"):
        TrackConfig(channels=13)
    with pytest.raises(ValueError, match="--parallel"):
        TrackConfig(parallel=1)
    with pytest.raises(ValueError, match="--parallel.*--backend model"):
        open_gnss_array("verilator", array_channel_params(GnssChannelParams(fs_hz=4e6, if_hz=1e6), 2), 2,
                        parallel=True)
    path = tmp_path / "iq.bin"
    write_synthetic(path, "int8-iq", 4e6, 0.0, 0.005, [], seed=1)
    f = SampleFile(path, "int8-iq", 4e6, 0.0)
    assert channel_params_for(f).complex_input        # a complex recording, the I/Q input
    path = tmp_path / "iq.cf32"
    write_synthetic(path, "cf32", 4e6, 0.0, 0.005, [], adc_map="float", seed=1)
    f = SampleFile(path, "cf32", 4e6, 0.0, adc_map="float")
    with pytest.raises(ValueError, match="--adc-map float"):
        channel_params_for(f)


def test_the_closed_loop_with_the_channels_on_threads_is_the_same(tmp_path):
    """--parallel: the same words, cycles, writes and trackers as the serial array."""
    path = tmp_path / "three.bin"
    sats = [SatelliteSpec(12, 1320.0, 300.7, 45.0, 0.2), SatelliteSpec(21, -2150.0, 811.2, 42.0,
                                                                        0.6),
            SatelliteSpec(5, 400.0, 77.5, 44.0, 0.1)]
    write_synthetic(path, "int8", 4e6, 1.25e6, 0.03, sats, seed=9)
    f = SampleFile(path, "int8", 4e6, 1.25e6)
    cands = [Candidate(s.prn, s.doppler_hz, s.code_phase_chips, s.cn0_dbhz) for s in sats]
    runs = [track_file(f, cands, GnssRunConfig(), TrackConfig(channels=3, parallel=par))
            for par in (False, True)]
    assert runs[0].pipeline.digest == runs[1].pipeline.digest
    assert [a.doppler for a in runs[0].assignments] == [a.doppler for a in runs[1].assignments]
    assert min(len(a.t) for a in runs[0].assignments) >= 25


@pytest.mark.slow
@pytest.mark.skipif(not verilator_available(), reason="Verilator not installed")
def test_the_closed_loop_on_verilator_is_the_models_bit_for_bit():
    f = SampleFile(REAL, "int8", 12e6, 3e6)
    cands = [Candidate(20, -1347.8, 326.363, 47.8), Candidate(13, -242.4, 511.156, 49.3)]
    runs = [track_file(f, cands, GnssRunConfig(backend=b), TrackConfig(channels=2),
                       n_samples=12 * 12_000) for b in ("model", "verilator")]
    assert runs[0].pipeline.digest == runs[1].pipeline.digest
    assert [a.doppler for a in runs[0].assignments] == [a.doppler for a in runs[1].assignments]
    assert len(runs[0].assignments[0].t) >= 9
