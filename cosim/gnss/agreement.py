"""The fast path against the IF path (generator + golden correlator), open loop.

A static scenario (constant Doppler), a replica held at fixed offsets from the truth (carrier
phase ``dphi`` cycles, code ``tau`` chips, frequencies exact), no data, the IF path's ADC of
``adc_bits`` (default the generator's 2 bits) and the fast path told the same word length
(its quantisation loss, ``cosim.gnss.fastpath.adc_efficiency``); the same statistics from
both paths:

* C/N0 by the M2M4 estimator (``dsp.gnss.cn0``) of the prompt;
* the variance of the normalised early-minus-late envelope DLL discriminator
  ``(|E| - |L|) / (|E| + |L|)`` and of the two-quadrant arctan phase discriminator
  ``atan(Q_P / I_P)`` (local forms here; the loops' own discriminators live with the loops);
* the E/P/L noise correlation matrix (each arm, I and Q pooled) and the I/Q correlation.

``python -m cosim.gnss.agreement [--json]`` prints the figures for the default case.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from dsp.gnss.ca_code import CHIP_RATE_HZ
from dsp.gnss.cn0 import cn0_m2m4
from dsp.gnss.correlator import correlate

from .dynamics import from_doppler
from .fastpath import adc_efficiency, code_correlation, correlate_fast, noise_correlation
from .signal import CARRIER_PER_CHIP, GnssSignalConfig, GnssSignalGenerator, SampleStream


def dll_nelp(iq):
    """Normalised early-minus-late envelope: ``(|E| - |L|) / (|E| + |L|)``."""
    e, lt = np.abs(iq[..., 0]), np.abs(iq[..., 2])
    return (e - lt) / (e + lt)


def pll_atan(iq):
    """Two-quadrant arctan of the prompt (rad)."""
    p = iq[..., 1]
    return np.arctan(p.imag / p.real)


def noise_corr(iq):
    """E/P/L noise correlation (3x3) and the largest |I-Q| correlation, from the residuals
    about the per-path mean (the signal is constant in this open-loop set-up)."""
    r = iq - iq.mean(axis=-2, keepdims=True)
    re = r.real.reshape(-1, 3)
    im = r.imag.reshape(-1, 3)
    c = np.corrcoef(np.concatenate([re, im]).T)
    ciq = np.corrcoef(re.T, im.T)[:3, 3:]
    return c, float(np.max(np.abs(ciq)))


#: The generator's default ADC word length (the IF path's, unless told otherwise).
DEFAULT_ADC_BITS = GnssSignalConfig.adc_bits


def if_path(cn0_dbhz=40.0, duration_s=2.0, tau_chips=0.125, dphi_cycles=0.05, doppler_hz=1250.0,
            spacing_chips=0.5, adc_bits=DEFAULT_ADC_BITS, prn=7, seed=7, signal_present=True):
    """E/P/L from the IF path, ``(n_epochs, 3)`` complex, and the config."""
    cfg = GnssSignalConfig(prn=prn, cn0_dbhz=cn0_dbhz, duration_s=duration_s,
                           dynamics=from_doppler(doppler_hz), nav_data=False,
                           code_phase_chips=tau_chips, adc_bits=adc_bits, seed=seed,
                           signal_present=signal_present)
    gen = GnssSignalGenerator(cfg)
    sign = -1.0 if cfg.spectrum_inverted else 1.0
    out = correlate(SampleStream(gen), cfg.fs_hz, prn,
                    cfg.digital_if_hz + sign * doppler_hz,
                    CHIP_RATE_HZ + doppler_hz / CARRIER_PER_CHIP, spacing_chips,
                    carrier_phase_cycles=-sign * dphi_cycles, code_phase_chips=0.0,
                    n_epochs=cfg.n_epochs - 1)
    return out.iq(), cfg


def fast_path(cn0_dbhz=40.0, n_epochs=2000, n_trials=20, tau_chips=0.125, dphi_cycles=0.05,
              spacing_chips=0.5, seed=8, prn=7, adc_bits=DEFAULT_ADC_BITS):
    return correlate_fast(cn0_dbhz, dphi_cycles, 0.0, tau_chips, 1.0, spacing_chips=spacing_chips,
                          rng=np.random.default_rng(seed), shape=(n_trials, n_epochs),
                          prn=prn, adc_bits=adc_bits).iq()


def compare(cn0_dbhz=40.0, duration_s=2.0, tau_chips=0.125, dphi_cycles=0.05, spacing_chips=0.5,
            adc_bits=DEFAULT_ADC_BITS, n_trials=20, seed=7, prn=7, noise_duration_s=1.0,
            fast_adc_bits="same") -> dict:
    """All the figures; the noise correlation from a noise-only IF run (``signal_present=False``,
    ``noise_duration_s``), so that the signal's epoch-to-epoch sampling jitter (code Doppler
    slides the chip edges across the samples) does not enter it. ``fast_adc_bits``: the
    word length the fast path is told (``"same"``: ``adc_bits``; None: no ADC, to show the
    loss it leaves out)."""
    fb = adc_bits if fast_adc_bits == "same" else fast_adc_bits
    t0 = time.perf_counter()
    a, cfg = if_path(cn0_dbhz, duration_s, tau_chips, dphi_cycles, spacing_chips=spacing_chips,
                     adc_bits=adc_bits, prn=prn, seed=seed)
    an, _ = if_path(cn0_dbhz, noise_duration_s, tau_chips, dphi_cycles, spacing_chips=spacing_chips,
                    adc_bits=adc_bits, prn=prn, seed=seed + 100, signal_present=False)
    t_if = time.perf_counter() - t0
    b = fast_path(cn0_dbhz, a.shape[0], n_trials, tau_chips, dphi_cycles, spacing_chips, seed + 1, prn,
                  adc_bits=fb)
    bn = correlate_fast(cn0_dbhz, 0.0, 0.0, 0.0, 0.0, spacing_chips=spacing_chips,
                        rng=np.random.default_rng(seed + 2), shape=(4, an.shape[0]), prn=prn,
                        adc_bits=fb).iq()
    loss_db = -10 * np.log10(adc_efficiency(adc_bits))
    ca, iqa = noise_corr(an)
    cb, iqb = noise_corr(bn)
    model = noise_correlation(spacing_chips, prn=prn)
    res = {
        "cn0_dbhz": cn0_dbhz, "prn": prn, "n_epochs_if": int(a.shape[0]),
        "n_epochs_if_noise": int(an.shape[0]), "n_trials_fast": n_trials,
        "tau_chips": tau_chips, "dphi_cycles": dphi_cycles, "spacing_chips": spacing_chips,
        "adc_bits": adc_bits, "fast_adc_bits": fb, "adc_loss_db": float(loss_db),
        "cn0_expected_dbhz": float(cn0_dbhz - loss_db
                                   + 20 * np.log10(code_correlation(tau_chips, prn=prn))),
        "cn0_if_dbhz": float(cn0_m2m4(a[:, 1], 1e-3)),
        "cn0_fast_dbhz": float(np.mean(cn0_m2m4(b[..., 1], 1e-3))),
        "var_dll_if": float(np.var(dll_nelp(a))), "var_dll_fast": float(np.var(dll_nelp(b))),
        "var_atan_if": float(np.var(pll_atan(a))), "var_atan_fast": float(np.var(pll_atan(b))),
        "noise_corr_if": ca.round(4).tolist(), "noise_corr_fast": cb.round(4).tolist(),
        "noise_corr_model": model.round(4).tolist(),
        "max_abs_iq_corr_if": iqa, "max_abs_iq_corr_fast": iqb,
        "if_path_s": round(t_if, 2),
    }
    res["cn0_diff_db"] = res["cn0_if_dbhz"] - res["cn0_fast_dbhz"]
    res["dll_var_ratio"] = res["var_dll_if"] / res["var_dll_fast"]
    res["atan_var_ratio"] = res["var_atan_if"] / res["var_atan_fast"]
    res["noise_corr_max_abs_diff_if"] = float(np.max(np.abs(ca - model)))
    res["noise_corr_max_abs_diff_fast"] = float(np.max(np.abs(cb - model)))
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m cosim.gnss.agreement", description=__doc__.split("\n")[0])
    ap.add_argument("--cn0-dbhz", type=float, default=40.0)
    ap.add_argument("--duration-s", type=float, default=2.0)
    ap.add_argument("--adc-bits", type=int, default=DEFAULT_ADC_BITS)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    r = compare(a.cn0_dbhz, a.duration_s, adc_bits=a.adc_bits, seed=a.seed)
    if a.json:
        print(json.dumps(r, indent=1))
    else:
        for k, v in r.items():
            print(f"{k:26s} {v}")


if __name__ == "__main__":
    main()
