"""RINEX 3.04 observation files (cosim.gnss.rinex_obs) read back with georinex: the header,
the epochs and every observable to the written resolution, LLI and signal strength."""
from __future__ import annotations

import datetime as dt

import georinex
import numpy as np
import pytest

from cosim.gnss.rinex_obs import (OBS_TYPES, RinexObsHeader, signal_strength_indicator,
                                  write_rinex_obs)
from dsp.gnss import observables as ob

HEADER = RinexObsHeader(marker_name="SYNTH", observer="test", agency="kfnav",
                        approx_position_m=(4_177_000.1234, 855_000.5, 4_728_000.25),
                        interval_s=0.5, created=dt.datetime(2026, 12, 5, 10, 0, 0))
WEEK, TOW0 = 2400, 345_600.0


def epochs(n=4, seed=3):
    """``n`` epochs 0.5 s apart of 6..8 satellites with seeded values, one missing value,
    a slip and the C/N0 across the signal-strength classes."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        prns = np.sort(rng.choice(np.arange(1, 33), size=6 + k % 3, replace=False))
        m = len(prns)
        pr = rng.uniform(2.0e7, 2.6e7, m)
        phase = rng.uniform(-1.3e8, 1.3e8, m)
        dop = rng.uniform(-4500.0, 4500.0, m)
        cn0 = rng.uniform(10.0, 56.0, m)
        lli = np.zeros(m, dtype=int)
        lli[k % m] = 1
        if k == 2:
            dop[0] = np.nan
        out.append(ob.ObservationEpoch(WEEK, TOW0 + 0.5 * k, prns, pr, phase, dop, cn0, lli,
                                       clock_offset_s=1e-4 * k if k % 2 else None))
    return out


def _written(v):
    return float(f"{v:.3f}")


def test_georinex_reads_back_every_observable(tmp_path):
    eps = epochs()
    path = tmp_path / "synth.26o"
    write_rinex_obs(path, eps, HEADER)
    data = georinex.load(path, useindicators=True)
    assert float(data.attrs["version"]) == pytest.approx(3.04)
    assert data.attrs["interval"] == 0.5 and data.attrs["time_system"] == "GPS"
    np.testing.assert_allclose(data.attrs["position"], HEADER.approx_position_m, atol=5e-5)
    assert data.attrs["receiver_clock_offset_applied"] == 0
    assert [np.datetime64(e.time, "ns") for e in eps] == list(data.time.values)
    assert data.attrs["time_offset"] == [1e-4, 3e-4]
    names = {"C1C": "pseudorange_m", "L1C": "carrier_cycles", "D1C": "doppler_hz",
             "S1C": "cn0_dbhz"}
    for k, e in enumerate(eps):
        for i, prn in enumerate(e.prns):
            sv = f"G{prn:02d}"
            for obs in OBS_TYPES:
                want = getattr(e, names[obs])[i]
                got = float(data[obs].sel(time=data.time[k], sv=sv))
                if np.isnan(want):
                    assert np.isnan(got)
                else:
                    assert got == _written(want), (k, sv, obs)
            lli = float(data["L1Clli"].sel(time=data.time[k], sv=sv))
            assert (0 if np.isnan(lli) else int(lli)) == e.lli[i]
            ssi = float(data["C1Cssi"].sel(time=data.time[k], sv=sv))
            assert ssi == signal_strength_indicator(e.cn0_dbhz[i])
        absent = sorted(set(data.sv.values) - {f"G{p:02d}" for p in e.prns})
        for sv in absent:
            assert np.isnan(float(data["C1C"].sel(time=data.time[k], sv=sv)))


def test_the_header_records_sit_in_their_columns(tmp_path):
    path = tmp_path / "synth.26o"
    write_rinex_obs(path, epochs(1), HEADER)
    lines = path.read_text().splitlines()
    assert lines[0][:9] == "     3.04" and lines[0][20] == "O" and lines[0][40] == "G"
    labels = [ln[60:].strip() for ln in lines[:lines.index(next(
        ln for ln in lines if ln[60:].strip() == "END OF HEADER")) + 1]]
    assert labels[0] == "RINEX VERSION / TYPE" and labels[1] == "PGM / RUN BY / DATE"
    assert labels[-1] == "END OF HEADER"
    for want in ("MARKER NAME", "APPROX POSITION XYZ", "ANTENNA: DELTA H/E/N", "INTERVAL",
                 "SYS / # / OBS TYPES", "TIME OF FIRST OBS", "SYS / PHASE SHIFT"):
        assert want in labels
    obs = next(ln for ln in lines if ln[60:].strip() == "SYS / # / OBS TYPES")
    assert obs[:60].rstrip() == "G    4 C1C L1C D1C S1C"
    first = next(ln for ln in lines if ln[60:].strip() == "TIME OF FIRST OBS")
    assert first[:60].rstrip() == "  2026     1     8     0     0    0.0000000     GPS"
    assert next(ln for ln in lines if ln.startswith(">")) == "> 2026 01 08 00 00  0.0000000  0  6"
    assert all(len(ln) <= 80 for ln in lines)


def test_signal_strength_classes():
    assert [signal_strength_indicator(c) for c in (0.0, 11.9, 12.0, 29.9, 30.0, 53.9, 54.0,
                                                    70.0)] == [1, 1, 2, 4, 5, 8, 9, 9]


def test_bad_input_raises(tmp_path):
    e = epochs(1)[0]
    with pytest.raises(ValueError, match="F14.3"):
        big = ob.ObservationEpoch(WEEK, TOW0, e.prns, e.pseudorange_m * 1e3, e.carrier_cycles,
                                  e.doppler_hz, e.cn0_dbhz, e.lli)
        write_rinex_obs(tmp_path / "x.26o", [big], HEADER)
    with pytest.raises(ValueError, match="increasing"):
        write_rinex_obs(tmp_path / "x.26o", [e, e], HEADER)
    with pytest.raises(ValueError, match="at least one"):
        write_rinex_obs(tmp_path / "x.26o", [], HEADER)
    with pytest.raises(ValueError, match="marker_name"):
        write_rinex_obs(tmp_path / "x.26o", [e], RinexObsHeader(marker_name="x" * 61))
    with pytest.raises(ValueError, match="PRNs"):
        ob.ObservationEpoch(WEEK, TOW0, [0, 1], [1.0, 2.0], [1.0, 2.0], [1.0, 2.0],
                            [40.0, 40.0], [0, 0])
    with pytest.raises(ValueError, match="lli"):
        ob.ObservationEpoch(WEEK, TOW0, [3], [1.0], [1.0], [1.0], [40.0], [9])


def test_pseudoranges_from_channel_counts():
    """t_tx from the counts, P = c (t_rx - t_tx), a wrapped week, implausible channels NaN."""
    c = 299_792_458.0
    tow_sf = np.array([345_594.0, 345_594.0, 604_794.0])
    n_bits, n_codes = np.array([299, 298, 299]), np.array([19, 5, 19])
    chips = np.array([511.5, 0.0, 1000.0])
    t_tx = ob.transmit_time(tow_sf, n_bits, n_codes, chips)
    np.testing.assert_allclose(t_tx[:2], [345_594.0 + 5.98 + 0.019 + 511.5 / 1.023e6,
                                          345_594.0 + 5.96 + 0.005], rtol=0, atol=1e-12)
    pr, ok = ob.pseudoranges_from_channels((345_600, 0.070), tow_sf[:2], n_bits[:2],
                                           n_codes[:2], chips[:2])
    assert pr[0] == pytest.approx(c * (6.070 - 5.980 - 0.019 - 511.5 / 1.023e6), abs=1e-6)
    as_float, _ = ob.pseudoranges_from_channels(345_600.070, tow_sf[:2], n_bits[:2],
                                                n_codes[:2], chips[:2])
    assert as_float[0] == pytest.approx(pr[0], abs=0.035)   # the float's 1.2e-10 s
    assert ok.tolist() == [True, False] and np.isnan(pr[1])   # 105 ms: implausible
    wrap, ok = ob.pseudoranges_from_channels(0.075, tow_sf[2:], n_bits[2:], n_codes[2:],
                                             chips[2:])
    assert ok.all() and wrap[0] == pytest.approx(c * (0.075 + 0.001 - 1000 / 1.023e6),
                                                 abs=1e-6)
    with pytest.raises(ValueError, match="n_codes"):
        ob.transmit_time(tow_sf, n_bits, np.array([19, 20, 0]), chips)
    with pytest.raises(ValueError, match="subframe edge"):
        ob.transmit_time([345_595.0], [0], [0], [0.0])


def test_channel_counts_to_rinex_to_a_fix(tmp_path):
    """End to end: the channel counts of a nominal constellation at a receiver epoch give
    pseudoranges ``c (t_rx - t_tx)``; written to RINEX and read back with georinex they
    solve (dsp.gnss.pvt) to the true position within the file's 1 mm resolution times the
    geometry."""
    import pymap3d

    from dsp.gnss import pvt
    lat, lon, h = 35.0, 139.0, 40.0
    az = np.array([0.0, 70.0, 130.0, 190.0, 250.0, 310.0])
    el = np.array([80.0, 35.0, 20.0, 50.0, 25.0, 40.0])
    prns = np.array([2, 5, 9, 17, 23, 30])
    pos, _ = ob.sky_geometry(lat, lon, h, az, el)
    r = np.array(pymap3d.geodetic2ecef(lat, lon, h))
    dt_s = np.array([1e-4, -2e-4, 5e-5, 0.0, 3e-4, -1e-4])    # satellite clock offsets
    bias_s = 1.5e-3                                          # receiver clock
    t_rx_whole, t_rx_frac = 345_617, 0.25                    # receiver-clock epoch
    _, tau = ob.predict_pseudoranges(r, 0.0, pos, dt_s)
    # satellite-clock transmit time: t_sv = t_GPS + dt_s, t_GPS = t_rx - bias - tau
    since_edge = (t_rx_whole - 345_612) + t_rx_frac - bias_s - tau + dt_s
    n_bits = np.floor(since_edge / 0.020).astype(int)
    rest = since_edge - 0.020 * n_bits
    n_codes = np.floor(rest / 0.001).astype(int)
    chips = (rest - 0.001 * n_codes) * 1.023e6
    pr, ok = ob.pseudoranges_from_channels((t_rx_whole, t_rx_frac), np.full(6, 345_612.0),
                                           n_bits, n_codes, chips)
    assert ok.all()
    want, _ = ob.predict_pseudoranges(r, bias_s * pvt.C_LIGHT, pos, dt_s)
    np.testing.assert_allclose(pr, want, rtol=0, atol=1e-6)
    epoch = ob.ObservationEpoch(WEEK, t_rx_whole + t_rx_frac, prns, pr, np.full(6, np.nan),
                                np.full(6, np.nan), np.full(6, 45.0), np.zeros(6, int))
    path = tmp_path / "fix.26o"
    write_rinex_obs(path, [epoch], HEADER)
    back = georinex.load(path)
    pr_back = np.array([float(back["C1C"].sel(sv=f"G{p:02d}")[0]) for p in prns])
    np.testing.assert_allclose(pr_back, pr, rtol=0, atol=0.0005 + 1e-7)
    # equal weights (elevation floor 90 deg): the rounding error e (|e_i| <= 0.5 mm) moves
    # the position by at most sqrt(lambda_max((H^T H)^-1)) |e| <= PDOP |e|, the bias by TDOP |e|
    sol = pvt.solve(prns, pos, dt_s, pr_back, gps_week=WEEK, gps_tow_s=epoch.tow_s,
                    config=pvt.PvtConfig(elevation_floor_deg=90.0))
    assert sol.valid and sol.used_prns == tuple(prns)
    e_max = 0.0005 * np.sqrt(6)
    assert np.linalg.norm(sol.position_ecef_m - r) < e_max * sol.dop.pdop
    assert abs(sol.clock_bias_m - bias_s * pvt.C_LIGHT) < e_max * sol.dop.tdop
