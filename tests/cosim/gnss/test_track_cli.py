"""``python -m cosim gnss-track``: every satellite of a recording tracked at once on the
channel array (bit-exact model, fixed-point trackers), on the real PocketSDR window and on
synthetic recordings with known truth; bad input refused before work."""
import json
import math
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.gnss.files import SampleFile
from cosim.gnss.synthetic_file import SatelliteSpec, write_synthetic
from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, L1_HZ, ca_code_levels
from dsp.gnss.cn0 import cn0_m2m4

DATA = Path(__file__).resolve().parents[2] / "data" / "gnss"
REAL = DATA / "L1_20211125_004000_12MHz_I_70ms.bin"
FULL = DATA / "L1_20211125_004000_12MHz_I.bin"
FULL_IQ = DATA / "L1_20211202_084700_4MHz_IQ.bin"
REAL_OPTS = ["--format", "int8", "--fs-hz", "12e6", "--if-hz", "3e6"]
#: What gnss-acquire finds on the 70 ms window (tests/cosim/gnss/test_files.py pins it).
REAL_PRNS = {2, 5, 11, 13, 15, 18, 20, 24, 28, 29, 30}


def _track(capsys, *args):
    rc = main(["gnss-track", *map(str, args), "--json"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    return json.loads(out.out)


def test_three_satellites_and_an_absent_prn_on_the_real_window(capsys, tmp_path):
    s = _track(capsys, "--file", REAL, *REAL_OPTS, "--prns", "5,7,13,20", "--channels", 4,
               "--plots", tmp_path / "plots")
    assert [d["prn"] for d in s["acquisition"]["detections"]] == [5, 13, 20]
    assert {a["prn"] for a in s["assignments"]} == {5, 13, 20}      # PRN 7: nothing tracked
    for a in s["assignments"]:
        assert a["locked_at_end"], a["prn"]
        assert a["status"] == "tracked"
        assert a["end_s"] == pytest.approx(0.07)
        assert abs(a["doppler_hz"] - a["handover"]["doppler_hz"]) < 10.0
        assert a["cn0_dbhz"] > 40.0
        assert a["lock_time_s"] < 0.07
        assert set(a["windows"]) >= {"t_s", "pli", "cn0_dbhz", "phase_lock", "cn0_lock"}
        assert {"synchronised", "count", "times_s"} <= set(a["nav_bits"])
    assert s["fifo_dropped"] == 0 and s["broken_records"] == 0
    assert s["channels"] == 4 and s["backend"] == "model" and s["dsp"] == "fixed"
    for p in s["plots"]:
        assert Path(p).stat().st_size > 1000


def test_the_table_and_the_same_bits_twice(capsys):
    args = ["gnss-track", "--file", str(REAL), *REAL_OPTS, "--prns", "20", "--channels", "2",
            "--duration-s", "0.03"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "PRN" in out and "C/N0" in out and "\n  20   0 " in out
    d1 = out.split("digest ")[1].split()[0]
    assert main(args) == 0
    assert capsys.readouterr().out.split("digest ")[1].split()[0] == d1


@pytest.mark.parametrize("extra,match", [
    (["--channels", "13"], "--channels"),
    (["--channels", "0"], "--channels"),
    (["--duration-s", "1"], "--duration-s"),
    (["--duration-s", "0"], "--duration-s"),
    (["--pfa", "2"], "--pfa"),
    (["--prns", "33"], "--prns"),
    (["--fs-hz", "12.5e3"], "--fs-hz"),
    (["--if-hz", "7e6"], "--if-hz"),
    (["--adc-map", "odd:9"], "--adc-map"),
    (["--pull-in-ms", "5"], "--pull-in-ms"),
    (["--backend", "pysim"], "--backend pysim"),
])
def test_bad_input_is_refused_before_work(capsys, extra, match):
    args = ["gnss-track", "--file", str(REAL), "--format", "int8", "--fs-hz", "12e6",
            "--if-hz", "3e6", "--prns", "20"]
    opts = dict(zip(args[1::2], args[2::2]))
    opts.update(dict(zip(extra[::2], extra[1::2])))
    argv = ["gnss-track"] + [x for kv in opts.items() for x in kv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and match in err and "Traceback" not in err


def test_a_missing_file_and_a_plots_file_are_refused(capsys, tmp_path):
    assert main(["gnss-track", "--file", str(tmp_path / "no.bin"), *REAL_OPTS]) == 2
    assert "--file" in capsys.readouterr().err
    (tmp_path / "f").write_text("x")
    assert main(["gnss-track", "--file", str(REAL), *REAL_OPTS, "--plots",
                 str(tmp_path / "f")]) == 2
    assert "--plots" in capsys.readouterr().err


@pytest.mark.slow
def test_every_satellite_of_the_real_window_tracked_to_its_end(capsys):
    """All 32 PRNs searched: the 11 verified satellites, each tracked to the end of the
    70 ms window with phase and C/N0 lock in its last window; the PRNs not found are not
    tracked (their first dwells were below threshold or refused by the verification)."""
    s = _track(capsys, "--file", REAL, *REAL_OPTS)
    found = {d["prn"] for d in s["acquisition"]["detections"]}
    assert found == REAL_PRNS
    assert {a["prn"] for a in s["assignments"]} == REAL_PRNS
    for a in s["assignments"]:
        assert a["locked_at_end"] and a["end_s"] == pytest.approx(0.07), a
    confirmed = [a["prn"] for a in s["assignments"] if a["status"] == "tracked"]
    assert len(confirmed) >= 10             # the weakest confirms its lock after 62 ms
    assert not (found & {r["prn"] for r in s["acquisition"]["rejected"]})


@pytest.mark.slow
def test_every_satellite_of_the_full_recording_locked_until_its_sample_slip(capsys):
    """The full 100 ms: the same 11 satellites, each in lock in its last window (62-82 ms,
    ten confirmed); the recording skips about 965 samples near 88 ms (every code phase
    jumps by 82.3 chips: gnss-acquire on 89-99 ms finds them there), and every channel's
    records after its last window show it (C/N0 under the lock threshold)."""
    s = _track(capsys, "--file", FULL, *REAL_OPTS)
    assert {d["prn"] for d in s["acquisition"]["detections"]} == REAL_PRNS
    assert {a["prn"] for a in s["assignments"]} == REAL_PRNS
    assert len(s["tracked"]) >= 10 and not s["dropped"] and not s["lost"]
    for a in s["assignments"]:
        assert a["locked_at_end"] and a["end_s"] == pytest.approx(0.1)
        assert a["cn0_dbhz"] > 30.0
        assert a["tail_records"] >= 15 and (a["tail_cn0_dbhz"] is None
                                             or a["tail_cn0_dbhz"] < 30.0)


# -- synthetic recordings with known truth --------------------------------------------------
SATS = [SatelliteSpec(3, -3200.0, 101.3, 35.0, 0.1), SatelliteSpec(7, 2450.0, 877.9, 37.0, 0.3),
        SatelliteSpec(10, -1210.0, 455.2, 39.0, 0.7), SatelliteSpec(14, 350.0, 12.6, 41.0, 0.2),
        SatelliteSpec(19, 4100.0, 640.4, 43.0, 0.9), SatelliteSpec(22, -2600.0, 300.0, 45.0, 0.5),
        SatelliteSpec(26, 1500.0, 999.1, 47.5, 0.4), SatelliteSpec(31, -450.0, 733.3, 50.0, 0.8)]
FORMATS = [("int8", 1.25e6, None), ("int8-iq", 250e3, None), ("int16-iq", 250e3, "int:4"),
           ("cf32", 250e3, "float:4")]


def recording_cn0(f, sat, n0, n1):
    """The C/N0 of ``sat`` in the recording ``f`` between samples ``n0`` and ``n1``: M2M4
    on 1 ms prompts of an ideal correlator that knows the truth (code phase, Doppler),
    epoch-aligned, on the values as stored -- the satellite as the ADC delivered it, with
    the ADC's loss and the other satellites' cross-correlation."""
    r = CHIP_RATE_HZ * (1 + sat.doppler_hz / L1_HZ) / f.fs_hz
    k0 = math.ceil((sat.code_phase_chips + n0 * r) / CODE_LENGTH)
    k1 = math.floor((sat.code_phase_chips + n1 * r) / CODE_LENGTH)
    edges = np.ceil((np.arange(k0, k1 + 1) * CODE_LENGTH - sat.code_phase_chips) / r)
    a, b = int(edges[0]), int(edges[-1])
    x = f.read(a, b - a)
    n = np.arange(a, b)
    code = ca_code_levels(sat.prn)[np.floor(sat.code_phase_chips + n * r).astype(np.int64)
                                   % CODE_LENGTH]
    y = x * code * np.exp(-2j * np.pi * (f.if_hz + sat.doppler_hz) * n / f.fs_hz)
    prompts = np.add.reduceat(y, (edges[:-1] - a).astype(np.int64))
    return float(cn0_m2m4(prompts, 1e-3))


@pytest.mark.slow
@pytest.mark.parametrize("fmt,f_if,amap", FORMATS)
def test_eight_synthetic_satellites_found_and_tracked_to_the_truth(capsys, tmp_path, fmt, f_if,
                                                                   amap):
    """8 satellites 35-50 dB-Hz written in the format and read back: all found, none
    invented; after 0.5 s of tracking each holds its lock (the lock rule: confirmed, never
    five windows out of lock in a row), its Doppler within 5 Hz of the
    truth, its code phase within 0.1 chip, its C/N0 within 1 dB of the C/N0 the recording
    holds (:func:`recording_cn0`, reported against the nominal one)."""
    path = tmp_path / f"eight.{fmt}"
    write_synthetic(path, fmt, 4e6, f_if, 0.6, SATS, adc_map=amap, seed=5)
    opts = ["--file", path, "--format", fmt, "--fs-hz", "4e6", "--if-hz", f_if]
    if amap:
        opts += ["--adc-map", amap]
    s = _track(capsys, *opts)
    truth = {x.prn: x for x in SATS}
    assert {d["prn"] for d in s["acquisition"]["detections"]} == set(truth)
    assert set(s["tracked"]) == set(truth) and not s["dropped"] and not s["lost"]
    f = SampleFile(path, fmt, 4e6, f_if, adc_map=amap)
    cn0 = {}
    for a in s["assignments"]:
        x = truth[a["prn"]]
        assert a["status"] == "tracked" and a["end_s"] == pytest.approx(0.6)
        assert a["end_s"] - a["start_s"] >= 0.5 and a["locked_at_s"] < 0.2
        assert abs(a["doppler_hz"] - x.doppler_hz) < 5.0, a["prn"]
        g = round(a["code_phase_at_s"] * 4e6)
        tau = (x.code_phase_chips + g * CHIP_RATE_HZ * (1 + x.doppler_hz / L1_HZ) / 4e6) \
            % CODE_LENGTH
        assert abs((a["code_phase_chips"] - tau + 511.5) % CODE_LENGTH - 511.5) < 0.1
        held = recording_cn0(f, x, round(a["locked_at_s"] * 4e6), f.n_samples)
        cn0[a["prn"]] = (round(a["cn0_dbhz"], 2), round(held, 2), x.cn0_dbhz)
    # (tracked, in the recording, nominal) per PRN
    assert all(abs(v[0] - v[1]) < 1.0 for v in cn0.values()), str(cn0)


@pytest.mark.parametrize("fmt,f_if,amap", FORMATS)
def test_the_channel_mixes_the_values_the_adc_map_hands_on(tmp_path, fmt, f_if, amap):
    """Whatever the map, the channel's mixer takes exactly the sample values the file hands
    on (:meth:`SampleFile.read`), the ones acquisition and :func:`recording_cn0` see: odd-level
    maps (``odd:B``, ``float:B``) as ``2q + 1`` of the word ``q``, not ``q`` with its DC of
    -1/2 LSB beside a low IF's carrier."""
    from cosim.gnss.multichannel import channel_params_for
    path = tmp_path / f"two.{fmt}"
    write_synthetic(path, fmt, 4e6, f_if, 0.002, SATS[:2], adc_map=amap, seed=3)
    f = SampleFile(path, fmt, 4e6, f_if, adc_map=amap)
    p = channel_params_for(f)
    w = f.words(0, f.n_samples)
    mixed = 2 * w + 1 if p.odd_levels else w
    x = f.read(0, f.n_samples)
    ref = np.stack([x.real, x.imag], axis=-1) if f.is_complex else x
    assert np.array_equal(mixed, ref)
    assert p.odd_levels == (f.adc_map.kind in ("odd", "float"))


def test_the_throughput_bench_is_registered_and_measures_every_count(tmp_path):
    from cosim.gnss.track_bench import COUNTS, gnss_throughput
    from cosim.tools.bench import benchmarks
    assert "gnss-throughput" in benchmarks()
    r = gnss_throughput(tmp_path, quick=True)
    assert [x["channels"] for x in r["rows"]] == list(COUNTS)
    for x in r["rows"]:
        assert x["channel_samples_per_s"] > 0 and x["x_real_time"] > 0
        assert x["fifo_dropped"] == 0
    assert r["parallel_12_channels"]["digest"] == r["rows"][-1]["digest"]   # same bits
    p = r["profile_12_channels"]
    assert 0 < p["array_kernel_s"] < p["total_s"] and 0 < p["trackers_s"] < p["total_s"]
    assert json.loads((tmp_path / "gnss_throughput.json").read_text())["rows"] == r["rows"]
    assert "x real time" in (tmp_path / "gnss_throughput.md").read_text()
