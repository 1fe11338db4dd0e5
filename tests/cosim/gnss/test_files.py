"""Sample files: every format written and read back, the ADC maps, every error message."""
import json
import re
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main
from cosim.gnss.files import FIRST_BLOCK, AdcMap, SampleFile, write_samples
from cosim.gnss.synthetic_file import SatelliteSpec, write_synthetic

SATS = [SatelliteSpec(3, 1200.0, 100.25, 45.0), SatelliteSpec(17, -2300.0, 640.5, 40.0, 0.3)]
DATA = Path(__file__).resolve().parents[2] / "data" / "gnss"
CASES = [("int8", 8.184e6, 2.046e6, None), ("int8-iq", 4.092e6, 0.0, None),
         ("int16-iq", 4.092e6, 250e3, None), ("int16-iq", 4.092e6, 0.0, "int:12"),
         ("cf32", 4.092e6, -100e3, None), ("cf32", 4.092e6, 0.0, "float:3"),
         ("cf32", 4.092e6, 0.0, "odd:2")]


@pytest.mark.parametrize("fmt,fs,f_if,amap", CASES)
@pytest.mark.parametrize("inverted", [False, True])
def test_round_trip(tmp_path, fmt, fs, f_if, amap, inverted):
    path = tmp_path / "rec.bin"
    rec = write_synthetic(path, fmt, fs, f_if, 0.01, SATS, adc_map=amap, inverted=inverted,
                          seed=4, block_samples=5000)
    f = SampleFile(path, fmt, fs, f_if, inverted=inverted, adc_map=amap)
    assert f.n_samples == rec.n_samples == int(round(0.01 * fs))
    stored = rec.samples(0, rec.n_samples)
    want = np.conj(stored) if (inverted and f.is_complex) else stored
    if fmt == "cf32":
        want = want.astype(np.complex64).astype(np.complex128)
    got = f.read(0, f.n_samples)
    if amap == "float:3":      # the reader quantises: odd levels, 3 bits
        assert set(np.unique(got.real)) <= {-7, -5, -3, -1, 1, 3, 5, 7}
        assert np.array_equal(got, f.adc_map.quantise(want.real, f.step)
                              + 1j * f.adc_map.quantise(want.imag, f.step))
    else:
        assert np.array_equal(got, want)
    # blocks join to the whole; a block of the generator equals the same part of the whole
    assert np.array_equal(np.concatenate([b for _, b in f.blocks(7777)]), got)
    assert np.array_equal(rec.samples(12345, 1000), stored[12345:13345])
    assert f.doppler_sign_inverted == (inverted and not f.is_complex)


def test_words_and_block_independence(tmp_path):
    a, b = tmp_path / "a.bin", tmp_path / "b.bin"
    write_synthetic(a, "int8-iq", 4.092e6, 0.0, 0.005, SATS, seed=9, block_samples=1000)
    write_synthetic(b, "int8-iq", 4.092e6, 0.0, 0.005, SATS, seed=9, block_samples=1 << 16)
    assert a.read_bytes() == b.read_bytes()
    w = SampleFile(a, "int8-iq", 4.092e6).words(0, 2000)
    assert w.shape == (2000, 2) and set(np.unique(w)) == {-2, -1, 0, 1}
    raw = np.frombuffer(a.read_bytes(), np.int8)[:4000].reshape(-1, 2)
    assert np.array_equal(2 * w + 1, raw)
    # another seed, another file
    write_synthetic(b, "int8-iq", 4.092e6, 0.0, 0.005, SATS, seed=10)
    assert a.read_bytes() != b.read_bytes()


def test_real_recording_window_reads():
    f = SampleFile(str(DATA / "L1_20211202_084700_4MHz_IQ_70ms.bin"), "int8-iq", 4e6,
                   inverted=True)
    raw = np.fromfile(f.path, np.int8, count=200)
    z = f.read(0, 100)
    assert np.array_equal(z, raw[0::2] - 1j * raw[1::2])      # PocketSDR's I - jQ
    assert f.n_ms == 70 and set(np.unique(z.real)) == {-3, -1, 1, 3}


def _write(path, data: bytes):
    path.write_bytes(data)
    return path


ERRORS = [
    (lambda p: (p / "none.bin", "int8", 4e6, 0.0, None), "--file: no such file: "),
    (lambda p: (_write(p / "e.bin", b""), "int8", 4e6, 0.0, None), "is empty"),
    (lambda p: (_write(p / "o.bin", b"\x01" * 7), "int8-iq", 4e6, 0.0, None),
     "--format int8-iq: .* holds 7 values, an odd number; interleaved I/Q needs pairs"),
    (lambda p: (_write(p / "b.bin", b"\x01" * 7), "int16-iq", 4e6, 0.0, None),
     "--format int16-iq: .* has 7 bytes, not a whole number of 2-byte values"),
    (lambda p: (_write(p / "c.bin", b"\x01\x00" * 3), "int16-iq", 4e6, 0.0, None),
     "--format int16-iq: .* holds 3 values, an odd number"),
    (lambda p: (_write(p / "f.bin", b"\x00" * 10), "cf32", 4e6, 0.0, None),
     "--format cf32: .* has 10 bytes, not a whole number of 4-byte values"),
    (lambda p: (_write(p / "r.bin", b"\x01" * 8), "int8", 4.0915e6, 0.0, None),
     r"--fs-hz 4\.0915e\+06 gives 4091\.5 samples per 1 ms code period; acquisition needs "
     r"a whole number"),
    (lambda p: (_write(p / "i.bin", b"\x01" * 8), "int8", 4e6, 2.5e6, None),
     r"--if-hz of a real recording must be in \[0, fs/2\)"),
    (lambda p: (_write(p / "j.bin", b"\x01" * 8), "int8-iq", 4e6, -2e6, None),
     r"--if-hz of a complex recording must be in \(-fs/2, fs/2\)"),
    (lambda p: (_write(p / "k.bin", b"\x01" * 8), "int8", 4e6, 0.0, "odd2"),
     "--adc-map must be odd:B, int:B, float or float:B"),
    (lambda p: (_write(p / "l.bin", b"\x01" * 8), "int8", 4e6, 0.0, "int:9"),
     r"--adc-map int:9: bits must be in \[1, 8\] for --format int8, not 9"),
    (lambda p: (_write(p / "m.bin", b"\x01" * 8), "int16-iq", 4e6, 0.0, "float:4"),
     "--adc-map float:4: float maps are for --format cf32, not int16-iq"),
    (lambda p: (_write(p / "n.bin", b"\x01" * 8), "int12", 4e6, 0.0, None),
     "--format must be one of int8, int8-iq, int16-iq, cf32, not 'int12'"),
    (lambda p: (_write(p / "q.bin", bytes([1, 3, 253, 2, 1])), "int8", 4e6, 0.0, None),
     r"--adc-map odd:2: sample 3 of .* is 2, outside the map's odd integers in "
     r"\[-3, 3\]"),
    (lambda p: (_write(p / "s.bin", np.array([1, 1, 1, 5], np.int8).tobytes()), "int8-iq",
                4e6, 0.0, None), r"sample 1 \(Q\) of .* is 5, outside"),
    (lambda p: (_write(p / "t.bin", np.array([0.5, np.nan], np.float32).tobytes()), "cf32",
                4e6, 0.0, None), r"--adc-map float: sample 0 \(Q\) of .* is nan, "
                                 r"outside the map's finite numbers"),
]


@pytest.mark.parametrize("case,message", ERRORS)
def test_errors(tmp_path, case, message):
    args = case(tmp_path)
    with pytest.raises(ValueError, match=message):
        SampleFile(args[0], args[1], args[2], args[3], adc_map=args[4])


def test_bad_value_after_the_first_block_named_on_read(tmp_path):
    v = np.ones(FIRST_BLOCK + 5000, np.int8)
    v[FIRST_BLOCK + 1234] = 4
    f = SampleFile(_write(tmp_path / "late.bin", v.tobytes()), "int8", 4e6)  # first block ok
    with pytest.raises(ValueError, match=rf"sample {FIRST_BLOCK + 1234} of .* is 4, outside"):
        for _ in f.blocks(10000):
            pass


def test_writer_refuses_values_outside_the_map(tmp_path):
    with pytest.raises(ValueError, match=r"--adc-map odd:2: value 2\.0 at sample 1 is outside"):
        write_samples(tmp_path / "w.bin", "int8", [np.array([1.0, 2.0])])
    with pytest.raises(ValueError, match="--format int8 stores real samples"):
        write_samples(tmp_path / "w.bin", "int8", [np.array([1 + 1j])])
    assert AdcMap.parse(None, "int16-iq") == AdcMap("int", 16)


def test_cli_errors_are_one_line(tmp_path, capsys):
    rc = main(["gnss-acquire", "--file", str(tmp_path / "none.bin"), "--format", "int8",
               "--fs-hz", "4e6"])
    err = capsys.readouterr().err
    assert rc == 2 and err == f"error: --file: no such file: {tmp_path / 'none.bin'}\n"
    rc = main(["gnss-acquire", "--file", str(DATA / "L1_20211125_004000_12MHz_I_70ms.bin"),
               "--format", "int8", "--fs-hz", "12e6", "--if-hz", "3e6", "--prns", "0-3"])
    assert rc == 2 and "--prns must name PRNs in 1-32" in capsys.readouterr().err
    rc = main(["gnss-acquire", "--file", str(DATA / "L1_20211125_004000_12MHz_I_70ms.bin"),
               "--format", "int8", "--fs-hz", "12e6", "--if-hz", "3e6", "--search", "verified",
               "--stages", "1y10"])
    assert rc == 2 and "--stages entries must be TxK" in capsys.readouterr().err


def test_cli_table_and_json(capsys):
    args = ["gnss-acquire", "--file", str(DATA / "L1_20211125_004000_12MHz_I_70ms.bin"),
            "--format", "int8", "--fs-hz", "12e6", "--if-hz", "3e6", "--prns", "5,6,13",
            "--search", "verified", "--stages", "1x10"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert re.search(r"^\s+5\s+\S+\s+\S+\s+\S+\s+\S+\s+1ms x 10", out, re.M)
    assert re.search(r"^\s+13\s", out, re.M) and not re.search(r"^\s+6\s", out, re.M)
    assert main(args + ["--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert [x["prn"] for x in d["detections"]] == [5, 13]
    assert d["recording"]["n_samples"] == 840000 and d["decimation"] == 5


def test_cli_sequential_search_by_default_and_the_frequency_plan_warning(tmp_path, capsys):
    """gnss-acquire searches sequentially unless told --search verified (21 ms hold its first
    dwell only); a rate commensurate with the chip rate (2.046 MS/s, 2 samples per chip) is
    warned about on stderr, by gnss-acquire and gnss-track alike."""
    path = tmp_path / "two.bin"
    write_synthetic(path, "int8-iq", 2.046e6, 0.0, 0.021,
                    [SatelliteSpec(4, 1200.0, 100.0, 50.0), SatelliteSpec(9, -2100.0, 700.0, 48.0)],
                    seed=2)
    args = ["--file", str(path), "--format", "int8-iq", "--fs-hz", "2.046e6"]
    assert main(["gnss-acquire", *args, "--prns", "4,9,12", "--json"]) == 0
    out = capsys.readouterr()
    d = json.loads(out.out)
    assert d["search"] == "sequential" and [x["prn"] for x in d["detections"]] == [4, 9]
    assert d["stages_run"] == ["1 ms x 5/10"] and d["pfa_per_prn"] == pytest.approx(1e-3 / 3)
    for x in d["detections"]:
        assert x["verify_metric"] is None and x["stage_text"] == "1 ms x 5 at 5 ms"
    warning = "warning: --fs-hz 2.046 MS/s = 2 x 1.023 MHz puts the samples at only 2 offsets"
    assert out.err.startswith(warning)
    assert main(["gnss-track", *args, "--prns", "12", "--json"]) == 1      # nothing found
    assert capsys.readouterr().err.startswith(warning)
