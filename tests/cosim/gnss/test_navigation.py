"""A channel's navigation and its observables on synthetic channel records with a known
satellite time: bit and frame sync, the TOW of the bit edges, the transmit time at whole-ms
receiver samples against the truth (exact records and carried-forward ones across a slip of
the ms grid), the pseudorange, the carrier phase from the carrier NCO words; a channel of
noise or one that never locked has no navigation and says why."""
from types import SimpleNamespace

import numpy as np
import pytest

from cosim.gnss.multichannel import Assignment, Candidate
from cosim.gnss.navigation import channel_navigation
from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, L1_HZ
from dsp.gnss.nominal_orbits import nominal_constellation
from dsp.gnss.ephemeris import C_LIGHT, KlobucharParameters
from dsp.gnss.lnav import encode_frames
from dsp.gnss.observables import pseudoranges_from_channels, transmit_time
from hdl.gnss.params import GnssChannelParams

WEEK, TOE = 2300, 345_600.0
FS, IF = 5e6, 1.25e6
F = TOE + 30.0                                # the frame the bits start with
EPH = nominal_constellation(WEEK, TOE)[6]
IONO = KlobucharParameters((0.0,) * 4, (0.0,) * 4)
P = GnssChannelParams(fs_hz=FS, if_hz=IF, adc_bits=2, el_spacing_samples=2)


def t_sv(n, t0, r):
    """Satellite time of the signal received at sample ``n``."""
    return t0 + n / FS * (1.0 + r)


def records(doppler_hz, t0, duration_s, *, cn0=45.0, seed=1, data=True, ch=3):
    """An assignment whose records are those of a perfect tracker of a satellite with
    satellite time ``t_sv(n) = t0 + (1 + r) n / fs``, ``r = doppler / L1``, and the carrier
    word of the Doppler written at cycle 0."""
    r = doppler_hz / L1_HZ
    bits = encode_frames(EPH, IONO, WEEK, F, 1)
    n_end = int(duration_s * FS)
    chi = lambda n: CHIP_RATE_HZ * (t_sv(n, t0, r) - F)           # chips since F
    c0 = int(np.ceil(chi(0) / CODE_LENGTH)) + 1
    c1 = int(np.floor(chi(n_end) / CODE_LENGTH))
    c = np.arange(c0, c1)
    # the prompt boundary of code c: the first sample at or after chip 1023 c
    n_p = np.ceil((c * CODE_LENGTH / CHIP_RATE_HZ + F - t0) / (1 + r) * FS).astype(np.int64)
    n_p -= chi(n_p - 1) >= c * CODE_LENGTH           # the same rounding as the phases'
    n_p += chi(n_p) < c * CODE_LENGTH
    g = (n_p // 5000) * 5000
    code_phase = np.mod(chi(g), CODE_LENGTH)        # as the HDL record gives it (mod 1023)
    rng = np.random.default_rng(seed)
    a_ = np.sqrt(2 * 10 ** (cn0 / 10) * 1e-3)
    d = 1.0 - 2.0 * bits[(c - 1) // 20] if data else np.ones(c.size)
    ip = a_ * d + rng.standard_normal(c.size)
    a = Assignment(EPH.prn, ch, Candidate(EPH.prn, doppler_hz, 0.0, cn0), 0,
                   status="tracked", lock_sample=int(n_p[0]), end_sample=n_end)
    a.t, a.code_phase, a.ip = list(n_p / FS), list(code_phase), list(ip)
    a.doppler = [doppler_hz] * c.size
    a.qp = list(rng.standard_normal(c.size))
    a.win_t = list(n_p[19::20] / FS)
    a.win_cn0 = [cn0] * len(a.win_t)
    a.win_phase_lock = a.win_cn0_lock = [True] * len(a.win_t)
    track = SimpleNamespace(fs_hz=FS, n_samples=n_end, channels=12,
                            bus_writes=[(0, ch * 4, P.carr_word(IF + doppler_hz))])
    return a, track, r


# beyond +-1e5 Hz the code period and the ms grid slip every 10 s: a grid ms with two records
# (shorter periods) or none (longer periods, the phase carried forward)
@pytest.mark.parametrize("doppler_hz", [-3100.0, 157_542.0, -157_542.0])
def test_transmit_time_pseudorange_and_carrier_against_the_truth(doppler_hz):
    t0 = F + 5.7                                  # a subframe edge 0.3 s in
    a, track, r = records(doppler_hz, t0, 14.0)
    nav = channel_navigation(a, track, P, reference_week=WEEK, inverted=False, if_hz=IF)
    assert nav.ok, nav.message
    assert nav.decode.subframes[0].tow_start == F + 6.0 and not nav.decode.parity_failures
    # the TOW is known once the first whole subframe and the next TLM + HOW are in
    assert nav.tow_sample / FS == pytest.approx(0.3 + 7.2, abs=2e-3)
    g = (np.round(np.asarray(a.t) * FS).astype(np.int64) // 5000) * 5000
    n = np.arange(g[0], int(13.9 * FS), 5000, dtype=np.int64)      # every ms
    assert (np.setdiff1d(n, g).size > 0) == (doppler_hz < -1e5)
    assert (np.unique(g).size < g.size) == (doppler_hz > 1e5)
    tow_sf, n_bits, n_codes, chips, ok = nav.counts(n)
    assert ok.all()
    m = ok
    t_tx = transmit_time(tow_sf[m], n_bits[m], n_codes[m], chips[m])
    err = t_tx - t_sv(n[m], t0, r)
    assert np.max(np.abs(err)) < 2e-11                # 6 mm
    t_rx = t_sv(n[m], t0, r) + 0.0712
    for j in (0, 1000, int(m.sum()) - 1):
        w = int(np.floor(t_rx[j]))
        pr, okp = pseudoranges_from_channels((w, t_rx[j] - w), tow_sf[m][j], n_bits[m][j],
                                             n_codes[m][j], chips[m][j])
        assert okp and pr == pytest.approx(C_LIGHT * 0.0712, abs=0.01)
    # the carrier NCO's accumulated Doppler phase: the word's frequency, exactly
    f_word = P.carr_word(IF + doppler_hz) * FS / 2 ** P.carr_phase_bits - IF
    cyc = nav.carrier_cycles(n[m])
    assert np.allclose(np.diff(cyc), f_word * np.diff(n[m]) / FS, rtol=0, atol=1e-9)
    assert abs(f_word - doppler_hz) < FS / 2 ** P.carr_phase_bits
    assert nav.cn0_at(n[-1:])[0] == 45.0


def test_inverted_polarity_decodes_too():
    a, track, _ = records(800.0, F + 5.7, 14.0)
    a.ip = list(-np.asarray(a.ip))
    nav = channel_navigation(a, track, P, reference_week=WEEK, inverted=False, if_hz=IF)
    assert nav.ok and nav.decode.inverted


def test_noise_only_and_unlocked_channels_have_no_navigation():
    a, track, _ = records(800.0, F + 5.7, 3.0, cn0=-40.0)
    nav = channel_navigation(a, track, P, reference_week=WEEK, inverted=False, if_hz=IF)
    assert nav.status == "no-bit-sync" and not nav.counts(np.array([10_000]))[4].any()
    a, track, _ = records(800.0, F + 1.7, 3.0)               # no subframe edge, no frame sync
    nav = channel_navigation(a, track, P, reference_week=WEEK, inverted=False, if_hz=IF)
    assert nav.status == "no-frame-sync"
    a.lock_sample = None
    nav = channel_navigation(a, track, P, reference_week=WEEK, inverted=False, if_hz=IF)
    assert nav.status == "not-locked"
