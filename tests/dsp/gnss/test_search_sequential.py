"""Every PRN of a recording by the sequential search (dsp.gnss.search_sequential): synthetic
recordings with known truth, the dwells split between the passes make the tests of one
search, the real PocketSDR window (slow)."""
from pathlib import Path

import numpy as np
import pytest

from cosim.gnss.files import SampleFile
from cosim.gnss.synthetic_file import SatelliteSpec, SyntheticRecording, write_synthetic
from dsp.gnss.dwell import Baseband, Dwell, sequential_search
from dsp.gnss.search_sequential import sequential_search_all

from test_search import _check_found, _sats

DATA = Path(__file__).resolve().parents[2] / "data" / "gnss"


@pytest.mark.slow
def test_eight_satellites_found_by_the_sequential_search(tmp_path):
    """The 8 satellites (35-50 dB-Hz) of an inverted int8 I/Q file are found with Doppler
    within 10 Hz, code phase within one sample, C/N0 within 3 dB; 4 absent PRNs are not
    reported; the strong ones decide at the first dwell, the 35 dB-Hz one at a later
    one, on the signal with the others cancelled."""
    sats = _sats()
    path = tmp_path / "sats.bin"
    write_synthetic(path, "int8-iq", 4.092e6, 0.0, 0.07, sats, inverted=True, seed=7)
    f = SampleFile(path, "int8-iq", 4.092e6, 0.0, inverted=True)
    prns = sorted([s.prn for s in sats] + [1, 10, 20, 30])
    rep = sequential_search_all(f.read, f.n_samples, f.fs_hz, f.if_hz,
                                f.doppler_sign_inverted, prns)
    _check_found(rep, sats, 4.092e6)
    stage = {d.prn: d.stage for d in rep.detections}
    assert stage[31] == 0 and stage[2] >= 1
    assert rep.stages_run == ["1 ms x 5/10", "5 ms x 4/8"]     # what 70 ms hold
    assert rep.stages_skipped == ["10 ms x 5/10/20", "20 ms x 6/11"]
    assert rep.pfa == pytest.approx(1e-3 / len(prns))
    assert all(d.verify_metric is None for d in rep.detections)


def test_a_split_schedule_makes_the_tests_of_one_search():
    """first / last: the dwells run in two calls are the dwells of one call, at the same
    places in the stream and against the same thresholds (every look's metric equal)."""
    sat = [SatelliteSpec(11, 1750.0, 333.3, 30.0, 0.2)]
    r = SyntheticRecording("int8-iq", 2.048e6, 0.0, 0.06, sat, seed=3)
    bb = Baseband(r.samples, r.n_samples, 2.048e6, 0.0)
    sched = (Dwell(1, (2, 4)), Dwell(2, (3,)), Dwell(5, (2, 4)))
    whole = sequential_search(bb.ms, bb.fs_d, 11, sched, 60, stop=False)
    a = sequential_search(bb.ms, bb.fs_d, 11, sched, 60, stop=False, last=1)
    b = sequential_search(bb.ms, bb.fs_d, 11, sched, 60, stop=False, first=1)
    assert [x["t_end_ms"] for x in whole.looks] == [x["t_end_ms"] for x in a.looks + b.looks]
    assert np.allclose([x["metric"] for x in whole.looks],
                       [x["metric"] for x in a.looks + b.looks], rtol=1e-12, atol=0)
    with pytest.raises(ValueError, match="first, last must pick dwells"):
        sequential_search(bb.ms, bb.fs_d, 11, sched, 60, first=2, last=2)


def test_a_recording_shorter_than_the_first_dwell_is_refused():
    r = SyntheticRecording("int8-iq", 2.048e6, 0.0, 0.008, [], seed=1)
    with pytest.raises(ValueError, match=r"the recording \(8 ms\) is too short for the "
                                         r"search's first dwell \(1 ms x 5/10: 10 ms"):
        sequential_search_all(r.samples, r.n_samples, 2.048e6, 0.0, prns=[3])


@pytest.mark.slow
def test_the_real_window_gives_the_verified_searchs_satellites():
    """The 70 ms PocketSDR window, all 32 PRNs: the 11 satellites the verified search finds
    (tests/cosim/gnss/test_track_cli.py REAL_PRNS), no other; the strong satellites'
    cross-correlations refused."""
    f = SampleFile(DATA / "L1_20211125_004000_12MHz_I_70ms.bin", "int8", 12e6, 3e6)
    rep = sequential_search_all(f.read, f.n_samples, f.fs_hz, f.if_hz, False)
    assert {d.prn for d in rep.detections} == {2, 5, 11, 13, 15, 18, 20, 24, 28, 29, 30}
    assert all("cross_correlation_of" in r for r in rep.rejected)
