"""ADC quantisation loss study: the ADC model, the loadings, and the Monte Carlo that must
reproduce the theory of :mod:`dsp.quantizer` (1.96 dB at 1 bit, 0.55 dB at 2 bits, within
0.1 dB), and its report."""
import json
import math

import numpy as np
import pytest

from cosim.studies import adc_loss as al
from dsp.quantizer import optimal_step

LOSS_1BIT = 10 * math.log10(math.pi / 2)   # 1.961 dB
LOSS_2BIT = 0.55


@pytest.fixture(scope="module")
def sweep():
    # Reduced run (~4 s): 1.3e5 trials x 1000 samples at -30 dB per sample is enough for a
    # 95 % CI below 0.05 dB at 1 and 2 bits.
    return al.adc_loss_sweep((1, 2, 3, 4, 6, 8), trials=130_000, n_samples=1000, seed=0)


def _row(rows, bits):
    return next(r for r in rows if r["bits"] == bits)


# -- ADC model ---------------------------------------------------------------------------
def test_quantize_models():
    rng = np.random.default_rng(3)
    x = rng.normal(0, 2.0, 10_000)
    for bits in (1, 2, 5, 12):
        full = 1 << (bits - 1)
        step = 4.0 / full
        # mid-tread is exactly the ADC of cosim.tacan.signal (x in full-scale units)
        tacan = np.clip(np.rint((x / 4.0) * full), -full, full - 1)
        np.testing.assert_array_equal(al.quantize(x, bits, step, quantizer="mid_tread"), tacan)
        # mid-rise: two's-complement code + 1/2, symmetric levels, clipping at full scale
        q = al.quantize(x, bits, step)
        codes = q - 0.5
        assert codes.min() >= -full and codes.max() <= full - 1
        np.testing.assert_array_equal(codes, np.round(codes))
        nz = x[x != 0]
        np.testing.assert_array_equal(al.quantize(-nz, bits, step), -al.quantize(nz, bits, step))
    np.testing.assert_array_equal(al.quantize(x, 1, 3.0), np.where(x >= 0, 0.5, -0.5))


def test_step_for_loading():
    assert al.step_for_loading(4, "optimal") == optimal_step(4)
    assert al.step_for_loading(4, "agc") == pytest.approx(al.AGC_FULL_SCALE_SIGMA / 8)
    assert al.step_for_loading(3, 4.0) == pytest.approx(1.0)


# -- Monte Carlo -------------------------------------------------------------------------
def test_one_bit_loss_reproduced(sweep):
    r = _row(sweep, 1)
    assert r["loss_db_theory"] == pytest.approx(LOSS_1BIT, abs=1e-9)
    assert abs(r["loss_db_measured"] - LOSS_1BIT) < 0.1
    assert r["ci95_db"] < 0.05
    assert r["ci95_low_db"] < r["loss_db_measured"] < r["ci95_high_db"]


def test_two_bit_loss_reproduced(sweep):
    r = _row(sweep, 2)
    assert abs(r["loss_db_measured"] - LOSS_2BIT) < 0.1
    assert abs(r["loss_db_measured"] - r["loss_db_theory"]) < 0.1
    assert r["ci95_db"] < 0.05


def test_losses_decrease_with_bits_and_match_theory(sweep):
    rows = [r for r in sweep if r["bits"] is not None]
    meas = [r["loss_db_measured"] for r in rows]
    assert all(a > b for a, b in zip(meas, meas[1:]))
    assert _row(sweep, 8)["loss_db_measured"] < 0.05
    for r in rows:   # within 4 half-widths of the CI (or 0.01 dB)
        assert abs(r["loss_db_measured"] - r["loss_db_theory"]) < max(2 * r["ci95_db"], 0.01)


def test_estimator_reference_row(sweep):
    ref = _row(sweep, None)
    assert ref["out_snr_db_ideal"] == pytest.approx(0.0, abs=0.01)   # -30 dB + 10 log10(1000)
    assert abs(ref["loss_db_measured"]) < max(ref["ci95_db"], 0.1)


def test_deterministic_and_independent_of_the_bits_swept():
    kw = dict(trials=400, n_samples=64, snr_db=-20.0)
    a = al.adc_loss_sweep((1, 2, 5), seed=7, **kw)
    b = al.adc_loss_sweep((1, 2, 5), seed=7, **kw)
    assert a == b
    only2 = al.adc_loss_sweep((2,), seed=7, reference=False, **kw)
    assert only2 == [_row(a, 2)]
    c = al.adc_loss_sweep((1, 2, 5), seed=8, **kw)
    assert _row(c, 1)["loss_db_measured"] != _row(a, 1)["loss_db_measured"]


def test_as_configured_loading_and_mid_tread():
    rows = al.adc_loss_sweep((1, 2), trials=400, n_samples=64, loading="agc",
                             quantizer="mid_tread", reference=False)
    assert [r["full_scale_over_sigma"] for r in rows] == pytest.approx([4 / 0.9] * 2)
    # the 1-bit two's-complement mid-tread ADC thresholds at -FS/2: far worse than the sign
    assert rows[0]["loss_db_theory"] > 10.0


@pytest.mark.parametrize("kwargs, match", [
    (dict(bits=[0]), "bits"),
    (dict(bits=[25]), "bits"),
    (dict(bits=[1.5]), "bits"),
    (dict(bits=[True]), "bits"),
    (dict(bits=[]), "bits"),
    (dict(bits=None), "bits"),
    (dict(n_samples=0), "n_samples"),
    (dict(n_samples=2.5), "n_samples"),
    (dict(snr_db=float("nan")), "snr_db"),
    (dict(snr_db=float("inf")), "snr_db"),
    (dict(snr_db="-30"), "snr_db"),
    (dict(trials=10), "trials"),
    (dict(seed=-1), "seed"),
    (dict(loading="max"), "loading"),
    (dict(loading=-2.0), "loading"),
    (dict(quantizer="round"), "quantizer"),
    (dict(freq=0.5), "freq"),
])
def test_bad_arguments(kwargs, match):
    kw = dict(bits=[1], trials=200, n_samples=16)
    kw.update(kwargs)
    bits = kw.pop("bits")
    with pytest.raises(ValueError, match=match):
        al.adc_loss_sweep(bits, **kw)


def test_write_report(tmp_path):
    rows = al.adc_loss_sweep((1, 2, 3), trials=300, n_samples=64, snr_db=-20.0)
    paths = al.write_report(rows, tmp_path / "out")
    for key in ("json", "csv", "md", "png"):
        assert paths[key].exists() and paths[key].stat().st_size > 0
    doc = json.loads(paths["json"].read_text())
    assert [r["bits"] for r in doc["rows"]] == [1, 2, 3, None]
    assert {c["bits"] for c in doc["checks"]} == {1, 2}
    lines = paths["csv"].read_text().splitlines()
    assert len(lines) == 5 and lines[0].startswith("bits,")
    md = paths["md"].read_text()
    assert "| 2 |" in md and "Estimator check" in md
