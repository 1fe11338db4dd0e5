"""Bit errors in the navigation data, from the generator to the fix.

* The generator flips LNAV bits at the requested rate, the same bits for the same seed
  (per PRN, whatever the other satellites), the signal and its truth carry the flipped
  bits, and a decoder given them uses no subframe that holds one.
* :func:`cosim.gnss.fix_integrity.fix_jumps` counts a fix off the truth, a step that the
  truth (or the Doppler velocity) does not make, once each.
* (slow) The full receiver on a generated scenario with bit errors: hot start (the
  ephemerides are the generator's, so the words that matter are the TLM/HOW words and the
  subframes that date the channels: a wrong TOW would put a fix kilometres off), 9 s of 8
  satellites at 45 dB-Hz, BER 2e-3 drawn from seed 4: 6 flipped bits, three satellites lose
  their first subframe. The words failing parity are counted, no subframe holding a flipped
  bit is used, the fix comes from the five clean channels, and no fix jumps.
"""
import json

import numpy as np
import pymap3d
import pytest

from cosim.gnss.constellation import ConstellationConfig, ConstellationSignal
from cosim.gnss.constellation_geometry import StaticReceiver
from cosim.gnss.fix_integrity import fix_jumps, navigation_counts
from dsp.gnss.nominal_orbits import nominal_constellation
from dsp.gnss.ephemeris import WEEK_S
from dsp.gnss.lnav import SUBFRAME_BITS, WORD_BITS
from dsp.gnss.lnav_decode import decode_lnav

WEEK, TOE = 2300, 345_600.0
HOME = StaticReceiver.geodetic(52.0, 4.4, 30.0).position_m


def _cfg(**kw):
    base = dict(ephemerides=nominal_constellation(WEEK, TOE), week=WEEK, tow_s=TOE + 60.0,
                receiver=StaticReceiver(HOME), fs_hz=5e6, if_hz=1.25e6,
                complex_output=False, duration_s=0.5, seed=7)
    base.update(kw)
    return ConstellationConfig(**base)


def test_the_generator_flips_bits_at_the_rate_the_same_for_the_same_seed():
    p = 0.02
    sig = ConstellationSignal(_cfg(bit_error_rate=p))
    clean = ConstellationSignal(_cfg())
    n = flips = 0
    for prn in sig.prns:
        ns, ns0 = sig.nav_stream(prn), clean.nav_stream(prn)
        assert np.array_equal(ns.encoded, ns0.bits) and ns0.flipped.size == 0
        assert np.array_equal(np.flatnonzero(ns.bits != ns0.bits), ns.flipped)
        n, flips = n + ns.bits.size, flips + ns.flipped.size
    assert abs(flips - p * n) < 4 * np.sqrt(n * p * (1 - p)), (flips, n)
    # the same seed, the same flips (for a PRN whatever the other satellites); another seed,
    # others
    again = ConstellationSignal(_cfg(bit_error_rate=p))
    one = ConstellationSignal(_cfg(bit_error_rate=p, prns=(sig.prns[3],)))
    other = ConstellationSignal(_cfg(bit_error_rate=p, seed=8))
    for prn in sig.prns:
        assert np.array_equal(sig.nav_stream(prn).flipped, again.nav_stream(prn).flipped)
        assert not np.array_equal(sig.nav_stream(prn).flipped, other.nav_stream(prn).flipped)
    assert np.array_equal(one.nav_stream(sig.prns[3]).flipped,
                          sig.nav_stream(sig.prns[3]).flipped)
    # the modulated bit is the flipped one, in the signal's truth too
    tr = sig.truth_at(np.linspace(0.0, 0.5, 400))
    for j, prn in enumerate(sig.prns):
        ns = sig.nav_stream(prn)
        k = np.floor((tr.t_sv[:, j] - (ns.tow + (ns.week - WEEK) * WEEK_S)) / 0.02).astype(int)
        assert np.array_equal(tr.nav_bit[:, j], 1 - 2.0 * ns.bits[k])
    # the flipped bits the record receives, by transmit time
    fl = sig.flipped_bits()
    for j, prn in enumerate(sig.prns):
        ns = sig.nav_stream(prn)
        t = ns.tow + 0.02 * ns.flipped
        inside = (t + 0.02 > tr.t_sv[0, j]) & (t < tr.t_sv[-1, j])
        assert fl[prn] == pytest.approx(list(t[inside]))
    assert sum(map(len, fl.values())) > 0


def test_bad_bit_error_rates_are_refused():
    for bad in (-0.1, 0.6, float("nan"), True):
        with pytest.raises(ValueError, match="bit_error_rate"):
            _cfg(bit_error_rate=bad)
    with pytest.raises(ValueError, match="needs nav_data"):
        _cfg(bit_error_rate=0.01, nav_data=False)


def test_no_subframe_holding_a_flipped_bit_is_decoded():
    """Three frames of every satellite at BER 3e-3: each word holding a single flipped bit
    (or whose D29*/D30* was flipped) fails parity, and every subframe decoded is flip-free
    and the clean stream's."""
    sig = ConstellationSignal(_cfg(bit_error_rate=3e-3, duration_s=61.0, seed=3))
    failed_words = lost = 0
    for prn in sig.prns:
        ns = sig.nav_stream(prn)
        got = decode_lnav(ns.bits, prn, reference_week=WEEK)
        ref = {s.bit_index: s for s in decode_lnav(ns.encoded, prn, reference_week=WEEK).subframes}
        bad = np.zeros(ns.bits.size + 2, bool)
        bad[ns.flipped] = True
        for s in got.subframes:
            assert not bad[max(s.bit_index - 2, 0):s.bit_index + SUBFRAME_BITS].any()
            assert s == ref[s.bit_index]
        lost += len(ref) - len(got.subframes)
        failed = {f.bit_index for f in got.parity_failures}
        for w in range(got.sync_bit, ns.bits.size - WORD_BITS + 1, WORD_BITS):
            hit = bad[w - 2:w + WORD_BITS] if w >= 2 else bad[:w + WORD_BITS]
            if hit.sum() == 1:
                assert w in failed, (prn, w)
                failed_words += 1
    assert failed_words > 10 and lost > 0


def _row(t, pos, err=None, truth=None, vel_enu=(0.0, 0.0, 0.0)):
    lat, lon, _ = pymap3d.ecef2geodetic(*pos)
    r = {"t_s": t, "status": "fix", "x_m": pos[0], "y_m": pos[1], "z_m": pos[2],
         "lat_deg": lat, "lon_deg": lon, "vel_e_mps": vel_enu[0], "vel_n_mps": vel_enu[1],
         "vel_u_mps": vel_enu[2]}
    if truth is not None:
        r.update(err_3d_m=float(np.linalg.norm(np.asarray(pos) - truth)),
                 truth_x_m=truth[0], truth_y_m=truth[1], truth_z_m=truth[2])
    return r


def test_fix_jumps_are_counted_against_the_truth_and_between_fixes():
    east = np.array(pymap3d.enu2uvw(1.0, 0.0, 0.0, 52.0, 4.4))
    up = HOME / np.linalg.norm(HOME)
    # a receiver moving east at 100 m/s, fixes 0.1 s apart within 3 m of the truth...
    truth = [HOME + 10.0 * k * east for k in range(6)]
    rows = [_row(0.1 * k, truth[k] + 3.0 * up * (-1) ** k, truth=truth[k]) for k in range(6)]
    j = fix_jumps(rows, 30.0)
    assert j["count"] == 0 and j["off_truth"] == 0 and j["steps"] == 0
    # ... one 40 m off: off the truth, and two steps (to it and back)
    rows[3] = _row(0.3, truth[3] + 40.0 * up, truth=truth[3])
    j = fix_jumps(rows, 30.0)
    assert (j["count"], j["off_truth"], j["steps"]) == (2, 1, 2)
    assert j["t_s"] == pytest.approx([0.3, 0.4])
    assert fix_jumps(rows, 50.0)["count"] == 0
    # without a truth the Doppler velocity predicts the step: 100 m/s east is no jump,
    # a static claim is (each step 10 m, bound 5 m)
    moving = [_row(0.1 * k, truth[k], vel_enu=(100.0, 0.0, 0.0)) for k in range(6)]
    assert fix_jumps(moving, 5.0) == {"bound_m": 5.0, "count": 0, "off_truth": None,
                                      "steps": 0, "t_s": []}
    still = [_row(0.1 * k, truth[k]) for k in range(6)]
    assert fix_jumps(still, 5.0)["count"] == 5
    # no-fix rows are left out, bad bounds refused
    assert fix_jumps([dict(rows[0], status="no_fix_too_few_satellites")])["count"] == 0
    with pytest.raises(ValueError, match="--jump-bound-m"):
        fix_jumps(rows, 0.0)


def test_navigation_counts_sum_the_channels():
    ch = [{"prn": 5, "parity_failures": 3, "subframes": [{}, {}], "subframes_withheld": 1,
           "tow_known_s": 7.7, "ephemeris_decoded": False, "ephemeris_withheld": "subframe 1"},
          {"prn": 9, "parity_failures": 0, "subframes": [], "subframes_withheld": 0,
           "tow_known_s": None, "ephemeris_decoded": False, "ephemeris_withheld": None}]
    assert navigation_counts(ch) == {
        "parity_failures": 3, "subframes": 2, "subframes_withheld": 1, "channels_with_tow": 1,
        "ephemerides_decoded": 0, "ephemerides_withheld": {"G05": "subframe 1"}}


@pytest.mark.slow
def test_the_receiver_with_bit_errors_uses_no_corrupted_word_and_its_fix_never_jumps(
        capsys, tmp_path):
    """(module doc) 9 s, hot start, BER 2e-3 from seed 4, on the bit-exact array: ~85 s of
    CPU (2-10 minutes on the shared cores)."""
    from cosim.cli import main
    out = tmp_path / "gps"
    rc = main(["gps", "--duration-s", "9", "--hot-start", "--rate", "10", "--seed", "4",
               "--bit-error-rate", "2e-3", "--out", str(out), "--no-plots", "--json"])
    s = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert json.loads((out / "truth.json").read_text())["bit_errors"] == s["truth"]["bit_errors"]
    flips = {int(k[1:]): np.array(v) for k, v in
             s["truth"]["bit_errors"]["flipped_tow_s"].items()}
    chans = {c["prn"]: c for c in s["channels"]}
    assert sorted(chans) == sorted(s["truth"]["prns"]) and len(chans) >= 8
    # every subframe the receiver decoded (a TOW source) is free of flipped bits, D29*/D30*
    # of the word before included
    starts = [sf["tow_start"] for c in chans.values() for sf in c["subframes"]]
    for prn, c in chans.items():
        for sf in c["subframes"]:
            t0 = sf["tow_start"]
            assert not np.any((flips[prn] >= t0 - 0.04) & (flips[prn] < t0 + 6.0)), (prn, t0)
    # the first whole subframe and the next TLM/HOW (its confirmation) date a channel: the
    # satellites with a flipped bit there have no TOW, the others have one
    t1 = min(starts)
    hit = {p for p, f in flips.items() if np.any((f >= t1 - 0.04) & (f < t1 + 7.2))}
    with_tow = {p for p, c in chans.items() if c["tow_known_s"] is not None}
    assert hit and with_tow == set(chans) - hit and len(with_tow) >= 4
    n = s["navigation"]
    assert n["parity_failures"] > 0 and n["subframes_withheld"] > 0
    assert n["parity_failures"] == sum(c["parity_failures"] for c in chans.values())
    # fixes from the clean channels, within metres of the truth, none jumping
    assert s["fixes"] >= 10 and 7.6 <= s["ttff_s"] <= 8.0
    assert set(map(int, s["last_fix"]["used_prns"].split())) == with_tow
    assert s["error"]["3d_m"]["max"] < 5.0
    assert s["fix_jumps"] == {"bound_m": 30.0, "count": 0, "off_truth": 0, "steps": 0,
                              "t_s": []}
