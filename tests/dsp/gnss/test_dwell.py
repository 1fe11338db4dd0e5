"""The sequential acquisition (dsp.gnss.dwell): it finds a 30 dB-Hz satellite with data bits
within the 500 ms limit at the right Doppler and code phase, noise alone passes at most the
stated false-alarm rate, the dwells and the chunked front end are what they say."""
import numpy as np
import pytest
from scipy import stats

from dsp.gnss.ephemeris import L1_WAVELENGTH_M
from cosim.gnss.dynamics import PolynomialProfile
from cosim.gnss.signal import GnssSignalConfig, GnssSignalGenerator
from dsp.gnss.dwell import (DEFAULT_LIMIT_MS, DEFAULT_SCHEDULE, Baseband, Dwell, fixed_schedule,
                            refine, schedule_within, sequential_search)
from dsp.gnss.search_frontend import to_baseband

FS, IF = 6.138e6, 1.5345e6


def _gen(cn0, doppler_hz, code_phase, seed, present=True, duration_s=0.52, prn=9):
    sig = GnssSignalConfig(prn=prn, if_hz=IF, fs_hz=FS, cn0_dbhz=cn0, duration_s=duration_s,
                           dynamics=PolynomialProfile(range_rate_mps=-doppler_hz * L1_WAVELENGTH_M),
                           code_phase_chips=code_phase, signal_present=present, seed=seed)
    g = GnssSignalGenerator(sig)
    bb = Baseband(lambda a, n: g.samples(a, n)[0].astype(np.float64), sig.n_samples, FS,
                  sig.digital_if_hz, sig.spectrum_inverted)
    return g, bb


@pytest.mark.parametrize("seed, doppler", [(11, 4321.0), (12, -2718.0)])
def test_finds_a_30_dbhz_satellite_with_data_within_the_limit(seed, doppler):
    g, bb = _gen(30.0, doppler, 777.7, seed)
    r = sequential_search(bb.ms, bb.fs_d, 9, max_doppler_hz=5000.0)
    assert r.detected and r.t_detect_ms <= DEFAULT_LIMIT_MS
    assert r.coherent_ms >= 5            # a 1 ms x 10 dwell cannot see 30 dB-Hz
    tr = g.truth_at([r.start_ms * 1e-3])
    assert abs(r.doppler_hz - tr["doppler_hz"][0]) <= r.bin_width_hz
    dc = (r.code_phase_chips - tr["code_phase_chips"][0] + 511.5) % 1023 - 511.5
    assert abs(dc) <= 0.5
    # the refinement on the next 200 ms: a few Hz, a small fraction of a chip
    k = r.t_detect_ms
    cp = r.code_phase_chips + r.doppler_hz / 1540 * (k - r.start_ms) * 1e-3
    f, c = refine(g.samples(int(k * 6138), 200 * 6138)[0], FS, 9, IF, False, r.doppler_hz,
                  cp, r.bin_width_hz, 200)
    tr = g.truth_at([k * 1e-3, k * 1e-3 + 0.1])
    assert abs(f - tr["doppler_hz"][1]) < 3.0
    assert abs((c - tr["code_phase_chips"][0] + 511.5) % 1023 - 511.5) < 0.1


def test_a_strong_satellite_stops_at_the_first_dwell():
    g, bb = _gen(45.0, 1234.0, 100.0, 3, duration_s=0.05)
    r = sequential_search(bb.ms, bb.fs_d, 9, max_doppler_hz=5000.0)
    assert r.detected and r.stage == 0 and r.t_detect_ms == 5 and len(r.looks) == 1


def test_fixed_short_dwell_misses_30_dbhz_and_says_so():
    g, bb = _gen(30.0, 500.0, 10.0, 5, duration_s=0.02)
    r = sequential_search(bb.ms, bb.fs_d, 9, fixed_schedule(1, 5), max_doppler_hz=5000.0)
    assert not r.detected and r.n_tests == 1 and r.metric < 1


def test_noise_alone_passes_at_most_the_stated_false_alarm_rate():
    """40 noise records, one 1 ms x 4 test each: the fraction whose p_min is below pfa
    is a false-alarm rate at pfa; it must not exceed pfa beyond its binomial spread (the
    cells are correlated, so it is below it) and must not be 0 at pfa 0.5 (the threshold
    is not absurdly high)."""
    p_min = []
    for s in range(40):
        _, bb = _gen(40.0, 0.0, 0.0, 100 + s, present=False, duration_s=0.006)
        r = sequential_search(bb.ms, bb.fs_d, 9, fixed_schedule(1, 4), max_doppler_hz=3000.0,
                              stop=False)
        p_min.append(r.p_min)
    p_min = np.array(p_min)
    for pfa in (0.1, 0.5):
        k = int(np.sum(p_min < pfa))
        assert k <= stats.binom.ppf(0.999, 40, pfa), (pfa, k)
    assert np.sum(p_min < 0.5) >= 3


def test_dwells_and_their_bit_edge_offsets():
    d = Dwell(20, (6, 11))
    assert d.alignments() == (0, 5, 10, 15) and d.alignments(data_bits=False) == (0,)
    assert d.span_ms() == 15 + 220 and d.look_end_ms(6) == 15 + 120
    assert d.bin_width_hz <= 2 / (3 * 0.020) and Dwell(1, (5,)).bin_width_hz == 500.0
    used = sum(x.span_ms() for x in schedule_within(DEFAULT_SCHEDULE, DEFAULT_LIMIT_MS))
    assert len(schedule_within(DEFAULT_SCHEDULE, DEFAULT_LIMIT_MS)) == 4 and used <= 500
    assert len(schedule_within(DEFAULT_SCHEDULE, 100)) == 2


@pytest.mark.parametrize("make, msg", [
    (lambda: Dwell(25, (2,)), "--coherent-ms must be a whole number in 1..20, not 25"),
    (lambda: Dwell(2.5, (2,)), "--coherent-ms must be a whole number in 1..20, not 2.5"),
    (lambda: Dwell(5, (0,)), "--noncoherent must be a whole number >= 1, not 0"),
    (lambda: Dwell(5, (4, 4)), "a dwell's looks must be increasing"),
    (lambda: schedule_within(DEFAULT_SCHEDULE, 5),
     "--acq-limit-ms 5 is shorter than the first dwell (1 ms x 5/10: 10 ms of signal)"),
    (lambda: sequential_search(lambda a, b: np.zeros(0), 2.046e6, 1, pfa=0.0),
     "--pfa must be in (0, 1), not 0.0"),
])
def test_bad_dwells_are_refused_naming_the_option(make, msg):
    with pytest.raises(ValueError) as e:
        make()
    assert str(e.value).startswith(msg), str(e.value)


def test_chunked_front_end_equals_the_whole_record_converted():
    x = np.random.default_rng(0).standard_normal(int(FS * 0.06))
    bb = Baseband(lambda a, n: x[a:a + n], x.size, FS, IF * 1.01)
    ref = to_baseband(x, FS, IF * 1.01, False, 3)
    for k0, k1 in ((0, 10), (10, 30), (25, 60)):
        y = bb.ms(k0, k1)
        assert y.size == (k1 - k0) * 2046
        assert np.max(np.abs(y - ref[k0 * 2046:k1 * 2046])) < 1e-5
