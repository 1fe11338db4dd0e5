"""Bit-error studies: injection, each target end to end, the receiver survives."""
import json

import numpy as np
import pytest

from cosim.backends.verilator_harness import verilator_available
from cosim.cli import main
from cosim.studies.faults import FaultConfig, flip_bits, flip_signed, parse_ber, run_faults
from dsp.tacan.kalman import EnvelopeKalman
from dsp.tacan.kalman_config import KalmanFixedConfig

QUICK = dict(trials=1, duration_s=1.2, memory_s=0.25)


def test_parse_ber():
    assert parse_ber("1e-6:1e-3") == (1e-6, 1e-5, 1e-4, 1e-3)
    assert parse_ber("1e-5,3e-5") == (1e-5, 3e-5)
    for bad in ("1e-3:1e-6", "0:1e-3", "1e-3:2", "1:2:3"):
        with pytest.raises(ValueError, match="BER"):
            parse_ber(bad)


def test_flip_bits_rate_positions_and_signed_codes():
    rng = np.random.default_rng(0)
    w = np.zeros(200_000, np.int64)
    out, wi, bi = flip_bits(w, 12, 1e-3, rng)
    assert abs(wi.size - 2400) < 4 * np.sqrt(2400)          # binomial(2.4M bits, 1e-3)
    want = np.zeros_like(w)
    np.bitwise_xor.at(want, wi, np.int64(1) << bi)
    np.testing.assert_array_equal(out, want)                # exactly the reported flips
    assert np.unique(wi * 12 + bi).size == wi.size          # each bit at most once
    _, _, bi2 = flip_bits(w, 12, 1e-3, rng, bits=[10, 11])
    assert set(bi2.tolist()) <= {10, 11}
    codes = np.array([-2048, -1, 0, 2047], np.int16)
    flipped, wi3, _ = flip_signed(codes, 12, 0.999, np.random.default_rng(1), bits=[11])
    assert flipped.dtype == codes.dtype
    np.testing.assert_array_equal(flipped[wi3], np.array([0, 2047, -2048, -1], np.int16)[wi3])
    with pytest.raises(ValueError, match="bit positions"):
        flip_bits(w, 12, 1e-3, rng, bits=[12])


def test_kalman_upsets_equal_a_manual_split_and_flip():
    rng = np.random.default_rng(3)
    cfg = KalmanFixedConfig()
    dts = rng.integers(1000, 8000, 3000)
    ys = (0.8 + 0.1 * rng.standard_normal(3000))[None, :]
    steps = np.array([5, 5, 400, 2999])
    words = np.array([0, 7, 19, 3])          # x0, P[0,2] (word 7), P[4,4], x3
    bits = np.array([30, 40, 5, 33])
    a = EnvelopeKalman(cfg)
    a.schedule_upsets(steps, words, bits)
    for lo, hi in ((0, 1000), (1000, 3000)):
        a.run(dts[lo:hi], ys[:, lo:hi])
    b = EnvelopeKalman(cfg)
    edges = [0, 5, 400, 2999, 3000]
    for lo, hi in zip(edges[:-1], edges[1:]):
        for k in np.flatnonzero(steps == lo):
            b._flip(int(words[k]), int(bits[k]))
        b.run(dts[lo:hi], ys[:, lo:hi])
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)
    assert a.upsets_applied == 4 and np.array_equal(a.P[0], a.P[0].T)
    with pytest.raises(ValueError, match="sorted"):
        a.schedule_upsets([3], [0], [0])                    # before n_updates
    with pytest.raises(ValueError, match="inside the word"):
        EnvelopeKalman(cfg).schedule_upsets([1], [0], [cfg.x.width])
    with pytest.raises(ValueError, match="fixed-point"):
        EnvelopeKalman().schedule_upsets([1], [0], [0])


@pytest.fixture(scope="module")
def adc_fifo(tmp_path_factory):
    out = tmp_path_factory.mktemp("faults")
    return out, {t: run_faults(FaultConfig(target=t, ber=(1e-5, 1e-3), **QUICK), out,
                               progress=False)
                 for t in ("adc", "fifo")}


def _row(s, ber):
    return next(r for r in s["rows"] if r["ber"] == ber)


def test_bit_errors_at_1e5_in_adc_or_fifo_words_leave_the_bearing_intact(adc_fifo):
    _, res = adc_fifo
    for t, s in res.items():
        base, r = _row(s, 0.0), _row(s, 1e-5)
        assert r["exceptions"] == 0 and r["nan_bearings"] == 0, t
        assert r["flips"] > 0, t
        assert r["rmse_deg"] < 0.25 and r["max_abs_error_deg"] < 1.0, t
        assert r["rmse_deg"] < 1.5 * base["rmse_deg"], t


def test_heavy_bit_errors_are_survived(adc_fifo):
    """BER 1e-3: no exception, no NaN, the FIFO receiver rejects implausible words, and the
    bearing stays bounded (no wrap-sized time jump, no filter lost for good)."""
    out, res = adc_fifo
    for t, s in res.items():
        r = _row(s, 1e-3)
        assert r["exceptions"] == 0 and r["nan_bearings"] == 0, t
        assert r["rmse_deg"] is not None and r["max_abs_error_deg"] < 20, t
        assert r["longest_disturbance_s"] < 1.0, t
    assert _row(res["fifo"], 1e-3)["rx"]["ts_rejected"] > 0
    for f in ("faults_adc.md", "faults_adc.csv", "faults_adc.png", "faults_fifo.json"):
        assert (out / f).stat().st_size > 0


def test_dsp_state_upsets_are_detected_and_recovered(tmp_path):
    s = run_faults(FaultConfig(target="dsp-state", ber=(1e-6, 1e-5), seed=2,
                               **{**QUICK, "duration_s": 2.0}), tmp_path, progress=False)
    r = _row(s, 1e-5)
    assert r["exceptions"] == 0 and r["nan_bearings"] == 0
    assert r["flips"] > 10 and r["reinit"] > 0              # divergence detected ...
    assert r["state_faults"] > 0                            # ... corrupted words too
    rec = s["records"][-1]
    assert rec["n_bearings"] > 100                          # ... and the receiver goes on
    assert r["longest_disturbance_s"] < 1.5
    # Integrity: the receiver's flag covers the disturbed bearings.
    assert _row(s, 0.0)["flagged_fraction"] == 0.0
    lo = _row(s, 1e-6)
    assert lo["flips"] > 0 and lo["disturbed_fraction"] > 0
    assert lo["misleading_fraction"] == 0.0                 # every disturbed bearing flagged
    assert lo["valid_rmse_deg"] < 0.25 and lo["valid_max_abs_error_deg"] < 1.0
    assert r["misleading_fraction"] < 0.25 * r["disturbed_fraction"]
    assert "| flagged | misleading |" in (tmp_path / "faults_dsp_state.md").read_text()
    # What a user sees: every display epoch of the fault-free run shows a valid bearing;
    # upsets cost availability (flagged bearings), never integrity
    assert _row(s, 0.0)["shown"]["availability"] == 1.0
    for row in (lo, r):
        assert row["shown"]["misleading"] == 0 and row["excess_misleading"] == 0
        assert row["shown"]["rmse"] < 0.25
    assert "| BER | valid RMSE |" in (tmp_path / "faults_dsp_state.md").read_text()


def test_fifo_parity_turns_link_errors_into_skipped_words(tmp_path):
    """FIFO words at BER 1e-3 can hurt the bearing (corrupted timestamps slip through: 36 deg
    worst in `make faults`); with the parity bit the DSP skips the corrupted words instead
    and the bearing stays intact."""
    s = run_faults(FaultConfig(target="fifo", ber=(1e-3,), fifo_parity=True, **QUICK), tmp_path,
                   progress=False)
    r = _row(s, 1e-3)
    assert r["exceptions"] == 0 and r["rx"]["parity_errors"] > 0.8 * r["flips"]
    assert r["rmse_deg"] < 0.25 and r["max_abs_error_deg"] < 1.0 and r["misleading_fraction"] == 0
    assert (tmp_path / "faults_fifo_parity.md").exists()
    with pytest.raises(ValueError, match="fifo_parity must be a bool"):
        FaultConfig(fifo_parity="yes")


def test_register_upsets_are_scrubbed(tmp_path):
    s = run_faults(FaultConfig(target="register", ber=(3e-3,), seed=1, scrub_period_s=0.005,
                               **QUICK), tmp_path, progress=False)
    r = _row(s, 3e-3)
    assert r["exceptions"] == 0 and r["nan_bearings"] == 0 and r["flips"] > 0
    assert r["longest_disturbance_s"] < 1.0


def test_cli_faults_json(tmp_path, capsys):
    rc = main(["faults", "tacan", "--target", "adc", "--ber", "1e-4", "--trials", "1",
               "--duration-s", "1.2", "--memory-s", "0.25", "--out", str(tmp_path), "--json"])
    assert rc == 0
    r = json.loads(capsys.readouterr().out)
    assert [row["ber"] for row in r["rows"]] == [0.0, 1e-4]
    assert (tmp_path / "faults_adc.md").exists()
    assert main(["faults", "tacan", "--bits", "x,y"]) == 2


@pytest.mark.skipif(not verilator_available(),
                    reason="Verilator not installed")
def test_register_upsets_in_the_compiled_rtl_equal_the_model(tmp_path):
    """The same NCO-register upsets and scrubs, applied as port writes to the Verilated
    front end, give the same bearings as on the bit-exact model."""
    kw = dict(target="register", ber=(3e-3,), seed=1, scrub_period_s=0.005, trials=1,
              duration_s=0.7, memory_s=0.15)
    m = run_faults(FaultConfig(**kw), None, progress=False)
    v = run_faults(FaultConfig(**kw, backend="verilator"), None, progress=False)
    rm, rv = (next(r for r in s["records"] if r["ber"] == 3e-3) for s in (m, v))
    assert rm["flips"] == rv["flips"] > 0
    for k in ("rmse_deg", "max_abs_error_deg", "n_bearings", "events"):
        assert rm[k] == rv[k], k


def test_report_words_come_from_the_receiver(tmp_path):
    """The generic report names what the receiver measures: TACAN's bearing, the monopulse
    azimuth tracking estimate (it said "TACAN bearing" and "NaN bearings" for both)."""
    from cosim.studies.faults import FaultConfig, _write
    from cosim.core.provenance import machine_info
    row = {"ber": 0.0, "trials": 1, "exceptions": 0, "nan_bearings": 0, "flips": 0,
           "rmse_deg": 0.05, "max_abs_error_deg": 0.1, "disturbed_fraction": 0.0,
           "longest_disturbance_s": 0.0, "flagged_fraction": None, "misleading_fraction": None,
           "valid_rmse_deg": None, "valid_max_abs_error_deg": None, "reinit": 0, "gated": 0,
           "p_neg": 0, "saturations": 0, "rx": {}}
    s = {"machine": machine_info(), "elapsed_s": 1.0, "rows": [row]}
    for rx, want, not_want in (("monopulse", "NaN azimuth tracking estimates", "bearing"),
                               ("tacan", "NaN bearings", "azimuth")):
        fc = FaultConfig(receiver=rx, target="fifo", duration_s=0.3, memory_s=0.05, snr_db=10)
        _write(fc, s, tmp_path / rx)
        md = (tmp_path / rx / "faults_fifo.md").read_text()
        assert want in md and not_want not in md.lower(), md


def test_dsp_state_upsets_with_both_searches(tmp_path):
    """``--detector both``: the core's state upsets on the two searches' tagged stream (the
    references decoded on the pulses, the pairs measured): no exception or NaN, corrupted
    words found by the continuity check, the clean record's bearings all valid and
    accurate, and at 1e-6 every disturbed bearing flagged (before the check: 0.49 % of
    them misleading on `make faults`' records, 4.82 % on 100 records)."""
    s = run_faults(FaultConfig(target="dsp-state", ber=(1e-6, 1e-5), seed=2, detector="both",
                               **{**QUICK, "duration_s": 2.0}), tmp_path, progress=False)
    clean, lo, r = _row(s, 0.0), _row(s, 1e-6), _row(s, 1e-5)
    assert clean["exceptions"] == 0 and clean["flagged_fraction"] == 0.0
    assert clean["rmse_deg"] < 0.15 and clean["state_faults"] == 0
    assert r["exceptions"] == 0 and r["nan_bearings"] == 0 and r["flips"] > 10
    assert r["state_faults"] > 0 and r["reinit"] > 0
    assert lo["flips"] > 0 and lo["misleading_fraction"] == 0.0
    assert "detector both" in (tmp_path / "faults_dsp_state_both.md").read_text()


def test_fault_detector_option_is_validated():
    with pytest.raises(ValueError, match="detector must be one of"):
        FaultConfig(target="dsp-state", detector="pairs")
    with pytest.raises(ValueError, match="monopulse receiver has none"):
        FaultConfig(receiver="monopulse", target="adc", detector="both")
