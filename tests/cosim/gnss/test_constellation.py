"""The constellation signal: visibility, the light-time truth against gnss-lib-py, the
interpolation error, Doppler as the carrier phase's derivative, the stream against the truth
(correlation at the truth's code phase, Doppler and carrier phase), the LNAV message decoded
from the stream, determinism across block lengths, the file writer and the refused inputs."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from dsp.gnss.ephemeris import L1_WAVELENGTH_M
from cosim.gnss.constellation import ConstellationConfig, \
    ConstellationSignal, write_constellation
from cosim.gnss.constellation_geometry import Cn0Model, ReceiverClock, StaticReceiver, \
    TrajectoryReceiver, along_track_receiver
from cosim.gnss.files import AdcMap, SampleFile
from cosim.gnss.rinex_nav import read_rinex_nav
from cosim.ins.trajectory import PaperTrajectory
from dsp.gnss.ca_code import CHIP_RATE_HZ, L1_HZ, ca_code_levels
from dsp.gnss.nominal_orbits import nominal_constellation
from dsp.gnss.ephemeris import C_LIGHT, OMEGA_E_DOT, WEEK_S
from dsp.gnss.lnav_decode import decode_lnav

DATA = Path(__file__).resolve().parents[2] / "data" / "gnss"
WEEK, TOW = 1865, 259200.0 + 12 * 3600 + 100.0        # brdc2800.15n: 2015-10-07 12:01:40
ZURICH = (47.3769, 8.5417, 500.0)


@pytest.fixture(scope="module")
def nav():
    return read_rinex_nav(DATA / "brdc2800.15n")


def config(nav, **kw):
    base = dict(ephemerides=nav.ephemerides, week=WEEK, tow_s=TOW,
                receiver=StaticReceiver.geodetic(*ZURICH), fs_hz=4.092e6, if_hz=0.0,
                duration_s=0.5, klobuchar=nav.iono)
    base.update(kw)
    return ConstellationConfig(**base)


def test_static_receiver_sees_eight_satellites_above_ten_degrees(nav):
    sig = ConstellationSignal(config(nav))
    tr = sig.truth_at([0.0])
    assert len(sig.prns) >= 8 and np.all(tr.sounding)
    assert np.all(tr.elevation_deg >= 10.0)
    # elevation and azimuth against pymap3d from the satellite positions of the truth's
    # own transmission times, rotated into the reception frame
    from dsp.gnss.ephemeris import sagnac_rotate, satellite_position_velocity
    pos, _ = satellite_position_velocity(list(sig.ephemerides), tr.t_tx[0])
    pos = sagnac_rotate(pos, tr.t_gps[0] - tr.t_tx[0])
    az, el, rng = pymap3d.ecef2aer(pos[:, 0], pos[:, 1], pos[:, 2], *ZURICH)
    assert np.allclose(el, tr.elevation_deg[0], atol=1e-6)
    assert np.allclose(az, tr.azimuth_deg[0], atol=1e-6)
    # every satellite of the file valid then and above the mask is in the record
    all_sig = ConstellationSignal(config(nav, mask_deg=0.0))
    above = all_sig.truth_at([0.0]).elevation_deg[0] >= 10.0
    assert tuple(np.array(all_sig.prns)[above]) == sig.prns
    # the C/N0 model
    assert np.allclose(tr.cn0_dbhz, 47.0 - 10.0 * (1 - np.sin(np.radians(tr.elevation_deg))))


def test_nominal_constellation_is_a_source_too():
    ephs = nominal_constellation(2000, 345600.0)
    cfg = ConstellationConfig(ephs, 2000, 345600.0 + 60.0, StaticReceiver.geodetic(0, 0, 0),
                              fs_hz=2.048e6, duration_s=0.01)
    assert len(ConstellationSignal(cfg).prns) >= 6


glp_navdata = pytest.importorskip("gnss_lib_py.navdata.navdata")
glp_sv = pytest.importorskip("gnss_lib_py.utils.sv_models")


def _glp_navdata(ephs):
    nd = glp_navdata.NavData()
    cols = {"gnss_id": np.array(["gps"] * len(ephs)), "sv_id": [e.prn for e in ephs],
            "gps_week": [e.week for e in ephs], "t_oe": [e.toe for e in ephs],
            "t_oc": [e.toc for e in ephs], "e": [e.e for e in ephs],
            "omega": [e.omega for e in ephs], "Omega_0": [e.Omega0 for e in ephs],
            "OmegaDot": [e.OmegaDot for e in ephs], "sqrtA": [e.sqrtA for e in ephs],
            "deltaN": [e.deltaN for e in ephs], "IDOT": [e.IDOT for e in ephs],
            "i_0": [e.i0 for e in ephs], "C_is": [e.Cis for e in ephs],
            "C_ic": [e.Cic for e in ephs], "C_rs": [e.Crs for e in ephs],
            "C_rc": [e.Crc for e in ephs], "C_uc": [e.Cuc for e in ephs],
            "C_us": [e.Cus for e in ephs], "M_0": [e.M0 for e in ephs],
            "SVclockBias": [e.af0 for e in ephs], "SVclockDrift": [e.af1 for e in ephs],
            "SVclockDriftRate": [e.af2 for e in ephs], "TGD": [e.TGD for e in ephs]}
    for k, v in cols.items():
        nd[k] = np.asarray(v)
    return nd


def test_pseudorange_against_gnss_lib_py(nav):
    # gnss-lib-py iterates the argument of latitude with Cuc/Cus where IS-GPS-200 does not
    # (tests/dsp/gnss/test_ephemeris.py): with Cuc = Cus = 0 both orbit computations agree
    # to < 1 mm, so the light-time solution and the pseudorange are checked at 1 mm.
    ephs = tuple(replace(e, Cuc=0.0, Cus=0.0) for e in nav.ephemerides)
    clk = ReceiverClock(bias_s=2.5e-4, drift_s_s=3e-7, oscillator="tcxo")
    sig = ConstellationSignal(config(nav, ephemerides=ephs, clock=clk, duration_s=2.0))
    tr = sig.truth_at([0.0, 0.7371, 1.9])
    nd = _glp_navdata(list(sig.ephemerides))
    for i in range(tr.s.size):
        for j in range(len(sig.prns)):
            t_tx = tr.t_tx[i, j]
            ms = (WEEK * WEEK_S + t_tx) * 1000.0
            t_used = (ms - WEEK * WEEK_S * 1000.0) / 1000.0    # the time gnss-lib-py sees
            r = glp_sv.find_sv_states(ms, nd.copy(cols=[j]))
            p = np.array([float(np.ravel(r[k])[0]) for k in ("x_sv_m", "y_sv_m", "z_sv_m")])
            v = np.array([float(np.ravel(r[k])[0]) for k in
                          ("vx_sv_mps", "vy_sv_mps", "vz_sv_mps")])
            p = p + v * (t_tx - t_used)
            th = OMEGA_E_DOT * tr.geometric_range_m[i, j] / C_LIGHT
            rot = np.array([[np.cos(th), np.sin(th), 0], [-np.sin(th), np.cos(th), 0],
                            [0, 0, 1]])
            rng = np.linalg.norm(rot @ p - tr.rx_position_m[i])
            assert abs(rng - tr.geometric_range_m[i, j]) < 1e-3
            b_sv = float(np.ravel(r["b_sv_m"])[0])
            pr = rng + C_LIGHT * tr.rx_clock_bias_s[i] - b_sv
            assert abs(pr - tr.pseudorange_m[i, j]) < 1e-3
            # the light-time equation: true reception time minus transmission time
            assert abs((tr.t_gps[i] - t_tx) * C_LIGHT - rng) < 0.05   # float time grain
    # the pseudorange is c (receiver time - satellite time of the code)
    assert np.allclose(C_LIGHT * (tr.tow_rx[:, None] - tr.t_sv), tr.pseudorange_m, atol=0.05)


def _ins_receiver():
    return along_track_receiver(PaperTrajectory(), 30.0, 10.0, 200.0, 90.0)


@pytest.mark.parametrize("case", ["static-ocxo", "ins-trajectory"])
def test_interpolation_error(nav, case):
    if case == "static-ocxo":
        cfg = config(nav, clock=ReceiverClock(1e-4, 1e-6, "ocxo"), duration_s=2.2,
                     iono=lambda lat, lon, az, el, tow: 5.0 / np.sin(np.radians(el)),
                     tropo=lambda el, h: 2.4 / np.sin(np.radians(el)))
        s = np.linspace(0.0, 2.2, 4001) + 0.3e-3 / 7
    else:   # the jerk ramps: 5..15 s and 21.9..31.9 s
        cfg = config(nav, receiver=_ins_receiver(), duration_s=40.0, tow_s=TOW - 2 * 3600,
                     clock=ReceiverClock(oscillator="ocxo"), seed=3)
        s = np.concatenate([np.linspace(a, a + 1, 2003) for a in (4.5, 14.6, 21.5, 31.5)])
    sig = ConstellationSignal(cfg)
    got = sig.interpolated_ranges(s)
    tr = sig.truth_at(s)
    err_code = np.abs(got[..., 0] - tr.pseudorange_m).max()
    err_cyc = np.abs(-got[..., 1] / L1_WAVELENGTH_M - tr.carrier_phase_cycles).max()
    assert err_code < 1e-5         # m: << 1 mm
    assert err_cyc < 1e-4          # cycles: << 1e-3


def test_doppler_is_the_carrier_phase_derivative(nav):
    # The oscillator's time error is linear inside each 1 ms of its grid, so the phase is
    # differenced inside one such interval (mid-interval, +-0.4 ms): the truth's Doppler is
    # the instantaneous one. The absolute GPS time's grain (6e-11 s at tow 3e5 s) moves
    # the ranges by 2e-7 m, 1e-6 cycles: 1.3e-3 Hz over 0.8 ms at most.
    for cfg in (config(nav, clock=ReceiverClock(0.0, 2e-7, "tcxo"), duration_s=1.0),
                config(nav, receiver=_ins_receiver(), duration_s=35.0)):
        sig = ConstellationSignal(cfg)
        s = np.round(np.array([0.2, 0.5, 0.8]) * cfg.duration_s, 3) + 0.5e-3
        h = 0.4e-3
        ph = [sig.truth_at(s + d).carrier_phase_cycles for d in (-h, h)]
        fd = (ph[1] - ph[0]) / (2 * h)
        dop = sig.truth_at(s).doppler_hz
        assert np.abs(fd - dop).max() < 5e-3
    # the INS trajectory's cruise: 8300 m/s at constant geocentric radius
    tr = sig.truth_at([0.0, 34.0])
    assert np.linalg.norm(tr.rx_velocity_mps[1]) == pytest.approx(8300.0, rel=1e-9)
    r = np.linalg.norm(tr.rx_position_m, axis=1)
    assert r[1] == pytest.approx(r[0], abs=1e-6)


def _epoch_window(sig, prn, s):
    """The samples of ``prn``'s received code epoch that begins after ``s``, and the truth
    there."""
    j = sig.prns.index(prn)
    tr = sig.truth_at([s])
    rate = CHIP_RATE_HZ * (1 + tr.doppler_hz[0, j] / L1_HZ)
    s1 = s + (1023.0 - tr.code_phase_chips[0, j]) / rate + 2e-6
    fs = sig.cfg.fs_hz
    n0 = int(np.ceil(s1 * fs))
    n = int(fs * 1e-3 * 0.98)
    t0 = sig.truth_at([n0 / fs])
    return n0, n, j, t0


def _replica(sig, j, t0, n, chip_offset=0.0, doppler_offset=0.0):
    fs = sig.cfg.fs_hz
    t = np.arange(n) / fs
    fd = t0.doppler_hz[0, j] + doppler_offset
    chips = t0.code_phase_chips[0, j] + chip_offset + CHIP_RATE_HZ * (1 + fd / L1_HZ) * t
    code = ca_code_levels(sig.prns[j])[np.floor(chips).astype(np.int64) % 1023]
    # the IF's phase at the sample index (n0 + i) / fs, plus the truth's carrier phase
    ph = sig.cfg.if_hz * (t + t0.s[0]) + t0.carrier_phase_cycles[0, j] + fd * t
    return code * np.exp(2j * np.pi * ph)


def test_stream_matches_the_truth(nav):
    cfg = config(nav, noise=False, if_hz=0.25e6, duration_s=0.4)
    sig = ConstellationSignal(cfg)
    ones = {prn: ConstellationSignal(cfg.replace(prns=(prn,))) for prn in sig.prns}
    # the stream is the sum of the satellites' signals
    total = sum(o.analog(300_000, 5000) for o in ones.values())
    assert np.allclose(sig.analog(300_000, 5000), total, rtol=0, atol=1e-12)
    for s in (0.05, 0.21, 0.33):
        for prn in sig.prns:
            n0, n, j, t0 = _epoch_window(sig, prn, s)
            a = float(np.sqrt(10 ** (t0.cn0_dbhz[0, j] / 10) * 2 / cfg.fs_hz))
            bit = t0.nav_bit[0, j]

            def corr(x, **kw):
                return np.vdot(_replica(sig, j, t0, n, **kw), x) / n / (a * bit)

            # in the whole stream: the prompt in phase, the other satellites'
            # cross-correlation (up to ~0.15 with 11 satellites) its only residue
            assert abs(corr(sig.analog(n0, n)) - 1.0) < 0.25
            # the satellite's own signal: the full amplitude in phase at the truth's code
            # phase, carrier phase and bit, the peak (0.3 chip either side loses 0.25 or
            # 0.5: at 4 samples per chip one or two samples of each chip move); 1/2
            # chip off keeps 1 - 1/2 + R(1)/2, R(1) the code's own lag-1 autocorrelation
            # (the triangle of a finite code); a 250 Hz Doppler error over the ~1 ms loses
            # the sinc of it
            x1 = ones[prn].analog(n0, n)
            p1 = corr(x1)
            assert abs(p1 - 1.0) < 0.01, (prn, s, p1)
            for off in (-0.3, 0.3):
                assert abs(corr(x1, chip_offset=off)) < abs(p1) - 0.2
            code = ca_code_levels(prn).astype(float)
            r1 = float(np.mean(code * np.roll(code, 1)))
            for off in (-0.5, 0.5):
                assert abs(corr(x1, chip_offset=off)) == pytest.approx(0.5 + r1 / 2, abs=0.01)
            assert abs(corr(x1, doppler_offset=250.0)) == pytest.approx(
                abs(np.sinc(250.0 * n / cfg.fs_hz)), abs=0.01)


def test_stream_follows_the_ins_trajectory(nav):
    # the INS paper's trajectory (50 g, 8300 m/s) from 30 N 10 E, 200 m, flying east: the
    # satellite's own signal correlates at the truth in the jerk ramp and in the 50 g hold
    cfg = config(nav, receiver=_ins_receiver(), duration_s=35.0, tow_s=TOW - 2 * 3600,
                 noise=False)
    prn = ConstellationSignal(cfg).prns[0]
    sig = ConstellationSignal(cfg.replace(prns=(prn,)))
    for s in (0.3, 9.71, 18.2, 33.0):
        n0, n, j, t0 = _epoch_window(sig, prn, s)
        a = float(np.sqrt(10 ** (t0.cn0_dbhz[0, j] / 10) * 2 / cfg.fs_hz))
        p = np.vdot(_replica(sig, j, t0, n), sig.analog(n0, n)) / n / (a * t0.nav_bit[0, j])
        assert abs(p - 1.0) < 0.01, (s, p)


@pytest.mark.parametrize("inverted", [False, True])
def test_real_if_stream_matches_the_truth(nav, inverted):
    # real samples A d c cos(2 pi (f_IF n / fs + sgn phase)): the complex replica at the
    # truth's code, carrier phase and Doppler (sign turned with an inverted spectrum)
    # picks up A / 2 (each satellite alone: no cross-correlation residue)
    sgn = -1.0 if inverted else 1.0
    for prn in (8, 14):
        cfg = config(nav, noise=False, complex_output=False, fs_hz=8.184e6, if_hz=2.046e6,
                     inverted=inverted, duration_s=0.3, prns=(prn,))
        sig = ConstellationSignal(cfg)
        fs = cfg.fs_hz
        n0, n, j, t0 = _epoch_window(sig, prn, 0.12)
        x = sig.analog(n0, n)
        t = np.arange(n) / fs
        fd = t0.doppler_hz[0, j]
        chips = t0.code_phase_chips[0, j] + CHIP_RATE_HZ * (1 + fd / L1_HZ) * t
        rep = ca_code_levels(prn)[np.floor(chips).astype(np.int64) % 1023] * np.exp(
            2j * np.pi * (cfg.if_hz * (t + t0.s[0]) + sgn * (t0.carrier_phase_cycles[0, j]
                                                              + fd * t)))
        a = float(np.sqrt(2 * 10 ** (t0.cn0_dbhz[0, j] / 10) * 2 / fs))
        p = np.vdot(rep, x) / n / (a / 2 * t0.nav_bit[0, j])
        assert abs(p - 1.0) < 0.01, (prn, p)
    with pytest.raises(ValueError, match="truth times must be finite, within the record"):
        sig.truth_at([1.0])


def test_bit_edges_fall_on_code_epochs_and_bits_match_truth(nav):
    cfg = config(nav, noise=False, prns=(1, 11), duration_s=0.25, nav_data=True)
    sig = ConstellationSignal(cfg)
    fs = cfg.fs_hz
    for prn in sig.prns:
        s, seen = 0.0, []
        for _ in range(120):
            n0, n, j, t0 = _epoch_window(sig, prn, s)
            x = sig.analog(n0, n)
            p = np.vdot(_replica(sig, j, t0, n), x) / n
            a = float(np.sqrt(10 ** (t0.cn0_dbhz[0, j] / 10) * 2 / fs))
            # full-amplitude prompt in every code epoch: no bit edge inside an epoch
            assert abs(abs(p) / a - 1) < 0.02
            assert np.sign(p.real) == t0.nav_bit[0, j]
            seen.append(t0.nav_bit[0, j])
            s = (n0 + n) / fs
        assert len(set(seen)) == 2           # both levels (bit transitions) were seen
        # the bit in the stream is the encoded bit at the satellite time of the code
        tr = sig.truth_at(np.linspace(0, 0.2, 50))
        ns = sig.nav_stream(prn)
        k = np.floor((tr.t_sv[:, sig.prns.index(prn)] - (ns.tow + (ns.week - WEEK) * WEEK_S))
                     / 0.02).astype(int)
        assert np.array_equal(tr.nav_bit[:, sig.prns.index(prn)], 1 - 2.0 * ns.bits[k])


def test_lnav_message_decodes_from_the_stream(nav):
    # 18.8 s of one satellite at 45 dB-Hz, from 0.5 s before a frame: subframes 1-3 are
    # sent whole. The bits are the signs of the prompt summed over each data bit (the
    # samples binned by the truth's bit index, code and carrier wiped off with the truth).
    frame = 259200.0 + 12 * 3600 + 90.0                 # a multiple of 30 s
    cfg = config(nav, tow_s=frame - 0.5 + 0.075, duration_s=18.8, fs_hz=2.048e6,
                 prns=(11,), cn0=Cn0Model(45.0, 0.0), seed=7)
    sig = ConstellationSignal(cfg)
    fs, block = cfg.fs_hz, 1 << 20
    n_bits = int(cfg.duration_s / 0.02) + 2
    sums, counts = np.zeros(n_bits), np.zeros(n_bits)
    for a in range(0, cfg.n_samples, block):
        x = sig.analog(a, block)
        s = (a + np.arange(x.size)) / fs
        ep = np.arange(np.floor(s[0] * 1e3), np.floor(s[-1] * 1e3) + 2) * 1e-3
        tr = sig.truth_at(ep)
        # satellite time of the code (from the frame start) and carrier phase per sample,
        # linear between the truth's 1 ms points
        tsv = np.interp(s, ep, tr.t_sv[:, 0] - frame)
        cp = tr.carrier_phase_cycles[:, 0]
        ph = np.interp(s, ep, cp - cp[0]) + cp[0]
        chips = np.floor(CHIP_RATE_HZ * tsv).astype(np.int64)
        w = x * ca_code_levels(11)[chips % 1023] * np.exp(-2j * np.pi * (ph - np.floor(ph)))
        k = np.floor(tsv / 0.02).astype(np.int64) + 26         # bit -26 starts the record
        sums += np.bincount(k, weights=w.real, minlength=n_bits)[:n_bits]
        counts += np.bincount(k, minlength=n_bits)[:n_bits]
    whole = counts >= 0.99 * 0.02 * fs
    ks = np.flatnonzero(whole)
    assert np.all(np.diff(ks) == 1) and ks.size >= 920
    soft = sums[ks]
    res = decode_lnav(soft, 11, reference_week=WEEK)
    eph = next(e for e in sig.ephemerides if e.prn == 11)
    assert res.ephemeris == eph
    # the first subframe after the record start is subframe 1 of the frame, sent at
    # `frame`: its bit index in the stream is the frame's first bit
    first = res.subframes[0]
    assert first.subframe_id == 1 and first.tow_start == frame
    assert ks[first.bit_index] - 26 == 0


def test_same_seed_same_samples_for_any_block_length(nav):
    cfg = config(nav, fs_hz=2.048e6, duration_s=1.05, prns=(1, 8, 22),
                 clock=ReceiverClock(1e-5, 1e-7, "tcxo"), seed=3)
    one = ConstellationSignal(cfg).analog(0, cfg.n_samples)
    for block in (100_003, 1 << 16, 777_777):
        sig = ConstellationSignal(cfg)
        got = np.concatenate(list(sig.blocks(block)))
        assert np.array_equal(got, one)
    other = ConstellationSignal(cfg.replace(seed=4)).analog(0, 1000)
    assert not np.array_equal(other, one[:1000])


def test_writer_any_format(nav, tmp_path):
    cfg = config(nav, fs_hz=2.048e6, duration_s=0.02)
    sig = write_constellation(tmp_path / "c.bin", "int8-iq", cfg, block_samples=10_000)
    f = SampleFile(tmp_path / "c.bin", "int8-iq", cfg.fs_hz, cfg.if_hz)
    want = sig.samples(0, cfg.n_samples, AdcMap.parse(None, "int8-iq"))
    assert np.array_equal(f.read(0, cfg.n_samples), want)
    real = config(nav, fs_hz=8.184e6, if_hz=2.046e6, complex_output=False, duration_s=0.01,
                  inverted=True)
    sig = write_constellation(tmp_path / "r.bin", "int8", real, adc_map="odd:2")
    f = SampleFile(tmp_path / "r.bin", "int8", real.fs_hz, real.if_hz, inverted=True)
    assert np.array_equal(f.read(0, real.n_samples),
                          sig.samples(0, real.n_samples, AdcMap.parse("odd:2", "int8")))
    with pytest.raises(ValueError, match="stores real samples but the scenario's output is "
                                         "complex"):
        write_constellation(tmp_path / "x.bin", "int8", cfg)


def test_atmosphere_models_are_pluggable(nav):
    base = ConstellationSignal(config(nav)).truth_at([0.1])
    sig = ConstellationSignal(config(nav, iono=lambda la, lo, az, el, tow: np.full(
        np.shape(el), 5.0), tropo=lambda el, h: 2.0 + 0.0 * el))
    tr = sig.truth_at([0.1])
    assert np.allclose(tr.pseudorange_m - base.pseudorange_m, 7.0, atol=1e-9)
    # the carrier is advanced by the ionosphere: phase range changes by T - I = -3 m
    assert np.allclose((tr.carrier_phase_cycles - base.carrier_phase_cycles) * L1_WAVELENGTH_M,
                       3.0, atol=1e-6)
    with pytest.raises(ValueError, match="the tropo model returned"):
        ConstellationSignal(config(nav, tropo=lambda el, h: 1.0)).truth_at([0.0])


def test_bad_inputs_are_refused_before_work(nav):
    with pytest.raises(ValueError, match="no satellite above the 80 deg elevation mask"):
        ConstellationSignal(config(nav, mask_deg=80.0, prns=(1, 8)))
    with pytest.raises(ValueError, match="no healthy ephemeris valid at GPS week 1866"):
        ConstellationSignal(config(nav, week=1866))
    p0 = StaticReceiver.geodetic(*ZURICH).position_m
    up = p0 / np.linalg.norm(p0)
    rocket = TrajectoryReceiver(lambda u: p0 + np.outer(1.0 + u, 2e4 * up),
                                lambda u: np.outer(np.ones_like(u), 2e4 * up), "rocket")
    with pytest.raises(ValueError, match="exceeds 11200 m/s"):
        ConstellationSignal(config(nav, receiver=rocket))
    liar = TrajectoryReceiver(lambda u: p0 + np.outer(u, 100 * up),
                              lambda u: np.zeros((u.size, 3)), "liar")
    with pytest.raises(ValueError, match="velocity is not the derivative of position"):
        ConstellationSignal(config(nav, receiver=liar))
    with pytest.raises(ValueError, match="leaves the band"):
        ConstellationSignal(config(nav, receiver=StaticReceiver.geodetic(47.0, 8.0, 5e5)))
    with pytest.raises(ValueError, match="samples per 1 ms"):
        config(nav, fs_hz=2.0485e6)
    with pytest.raises(ValueError, match="complex stream must keep the C/A main lobe"):
        config(nav, fs_hz=2.048e6, if_hz=0.1e6)
    with pytest.raises(ValueError, match="real stream must keep the C/A main lobe"):
        config(nav, complex_output=False, if_hz=0.0)
    with pytest.raises(ValueError, match="duration_s"):
        config(nav, duration_s=0.0)
    with pytest.raises(ValueError, match="runs out of its fit interval"):
        ConstellationSignal(config(nav, ephemerides=nominal_constellation(WEEK, 259200.0),
                                   tow_s=259200.0 + 5400.0, duration_s=3000.0))
    with pytest.raises(ValueError, match="clock drift_s_s"):
        ReceiverClock(drift_s_s=1e-3)


def test_a_satellite_sounds_only_above_the_mask(nav):
    # over 20 minutes a satellite crosses the mask set at its elevation half-way: it is in
    # the record, with amplitude on the grid exactly where the truth has it above the mask
    probe = ConstellationSignal(config(nav, mask_deg=0.0, duration_s=1200.0))
    tr = probe.truth_at([0.0, 1200.0])
    j = int(np.argmax(np.abs(tr.elevation_deg[1] - tr.elevation_deg[0])))
    prn = probe.prns[j]
    mask = float(probe.truth_at([600.0]).elevation_deg[0, j])
    sig = ConstellationSignal(config(nav, mask_deg=mask, duration_s=1200.0))
    assert prn in sig.prns
    k = sig.prns.index(prn)
    for page in (0, 1199):
        amp = sig.page(page)["amp"][k]
        s = page * 1.0 + np.arange(amp.size) * 1e-3
        up = sig.truth_at(s).sounding[:, k]
        assert np.array_equal(amp > 0, up)
    assert sig.page(0)["amp"][k].any() != sig.page(1199)["amp"][k].any()
    # a satellite below the mask throughout is not in the record
    low = [p for i, p in enumerate(probe.prns) if tr.elevation_deg[:, i].max() < mask]
    assert low and not set(low) & set(sig.prns)
