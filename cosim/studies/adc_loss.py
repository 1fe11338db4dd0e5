"""ADC quantisation loss on a noise-dominated narrowband signal: Monte Carlo against theory.

This is the validation-against-theory part of the quantisation study: a sweep of ADC word
lengths on a weak tone in white Gaussian noise must reproduce the classical correlation
losses (1.96 dB at 1 bit, about 0.55 dB at 2 bits, vanishing with more bits). The theory
(the correlation efficiency ``eta`` of a quantiser, the loss ``-10 log10(eta)``, the optimal
step, the quantiser conventions ``"mid_rise"`` and ``"mid_tread"``) is :mod:`dsp.quantizer`;
here are the ADC model that digitises the records (:func:`quantize`), the loadings, the
Monte Carlo (:func:`adc_loss_sweep`), its report (:func:`write_report`) and the command
line (:func:`main`).

ADC model
---------
:func:`quantize` digitises a record with the two's-complement b-bit ADC of a convention of
:mod:`dsp.quantizer` (``"mid_rise"``, the default, or ``"mid_tread"``, the TACAN
generator's ADC).

Loading
-------
The step relative to the noise sigma: ``"optimal"`` maximises ``eta`` for each word length
(:func:`dsp.quantizer.optimal_step`); ``"agc"`` is the AGC of :mod:`cosim.tacan.signal` in
the noise-dominated limit (largest pulse + 4 sigma at 90 % of full scale, so full scale
``= 4 / 0.9 sigma`` when the pulses are negligible); a number is the full scale in noise
sigmas ("as configured").

Monte Carlo
-----------
Each trial is ``N`` samples of ``A cos(2 pi f n + phase) + n_n`` with ``sigma = 1``,
``A = sqrt(2 snr)``, ``f`` an irrational fraction of the sample rate (no pattern between the
tone and the quantiser grid), and a random phase. The same analog record is digitised by
every word length (paired comparison) and correlated with the known tone,
``C = sum_n q_n cos(2 pi f n + phase)``. The output SNR ``mean(C)^2 / var(C)`` over the
trials is computed for the unquantised and for each quantised record; the loss is their
ratio. Its 95 % confidence interval comes from the delta method on the per-trial moments
``(C_u, C_q, C_u^2, C_q^2)`` (paired, so the shared noise largely cancels; over 30 seeds the
empirical spread matches the interval). With the default ``2e5 x 1000`` samples the
half-width is about 0.04 dB at 1 bit and 0.02 dB at 2 bits; the weak-signal bias at -30 dB
is below 0.001 dB. The ``bits=None`` reference row compares the unquantised output SNR
with the ideal matched filter's (computed from the actual phases): it checks the estimator
itself. The default sweep (1..14 bits) takes about 15 s on one core.

Run ``python -m cosim.studies.adc_loss --out build/adc_loss`` for the default sweep and its
report (:func:`write_report`).
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from cosim.core.validate import (MAX_LIST_VALUES, check_choice, check_float, check_int,
                            check_memory, check_out_dir, dumps)
from dsp.quantizer import (MAX_BITS, QUANTIZERS, REFERENCE_LOSS_DB, clip_fraction,
                           optimal_step, quantizer_moments)

#: Full scale over noise sigma of the :mod:`cosim.tacan.signal` AGC when noise dominates.
AGC_FULL_SCALE_SIGMA = 4.0 / 0.9
#: Default tone frequency in cycles per sample: (sqrt(5) - 1) / 8, irrational.
DEFAULT_FREQ = (math.sqrt(5.0) - 1.0) / 8.0

# Trials per batch of the Monte Carlo (bounded memory: batch x n_samples float64).
_BATCH_ELEMENTS = 1 << 19


# -- argument checks (the shared rules of cosim.core.validate) -------------------------------
def _check_bits(bits) -> int:
    return check_int("bits", bits, 1, MAX_BITS)


def _check_quantizer(quantizer) -> str:
    return check_choice("quantizer", quantizer, QUANTIZERS)


def _check_positive(name: str, value) -> float:
    return check_float(name, value, 0, lo_open=True)


def _check_count(name: str, value, minimum: int) -> int:
    return check_int(name, value, minimum)


# -- loading -----------------------------------------------------------------------------
def step_for_loading(bits: int, loading="optimal", *, quantizer: str = "mid_rise") -> float:
    """The step in noise sigmas for a loading: ``"optimal"``, ``"agc"``, or full scale/sigma."""
    b = _check_bits(bits)
    _check_quantizer(quantizer)
    if isinstance(loading, str):
        if loading == "optimal":
            return optimal_step(b, quantizer=quantizer)
        if loading == "agc":
            return AGC_FULL_SCALE_SIGMA / (1 << (b - 1))
        raise ValueError(f"loading must be 'optimal', 'agc' or a full scale in noise sigmas "
                         f"(a number > 0), not {loading!r}")
    try:
        fs = _check_positive("loading (full scale in noise sigmas)", loading)
    except ValueError:
        raise ValueError(f"loading must be 'optimal', 'agc' or a full scale in noise sigmas "
                         f"(a finite number > 0), not {loading!r}") from None
    return fs / (1 << (b - 1))



# -- ADC model ---------------------------------------------------------------------------
def quantize(x, bits: int, step: float, *, quantizer: str = "mid_rise",
             out: np.ndarray | None = None) -> np.ndarray:
    """Digitise ``x`` with the b-bit ADC model; returns the levels in units of ``step``.

    The two's-complement code is ``c = result - 1/2`` (mid-rise) or ``c = result``
    (mid-tread); multiply by ``step`` for the analog value. ``out`` (float, same shape)
    avoids an allocation.
    """
    b = _check_bits(bits)
    d = _check_positive("step", step)
    _check_quantizer(quantizer)
    y = _codes(x, b, d, quantizer, out)
    if quantizer == "mid_rise":
        y += 0.5
    return y


def _codes(x, bits: int, step: float, quantizer: str, out: np.ndarray | None) -> np.ndarray:
    """Two's-complement codes (as floats) of the ADC model; arguments already checked."""
    k = float(1 << (bits - 1))
    y = np.multiply(x, 1.0 / step, out=out)
    if quantizer == "mid_rise":
        np.floor(y, out=y)
    else:
        np.rint(y, out=y)
    np.clip(y, -k, k - 1.0, out=y)
    return y


# -- Monte Carlo -------------------------------------------------------------------------
def _loss_and_ci(u: np.ndarray, q: np.ndarray) -> tuple[float, float, float, float]:
    """Paired estimate of ln(SNR_u / SNR_q), its delta-method std, and the two SNRs."""
    z = np.stack([u, q, u * u, q * q])
    mean = z.mean(axis=1)
    cov = np.cov(z)
    mu, mq, suu, sqq = mean
    vu, vq = suu - mu * mu, sqq - mq * mq
    snr_u, snr_q = mu * mu / vu, mq * mq / vq
    grad = np.array([2.0 / mu + 2.0 * mu / vu, -2.0 / mq - 2.0 * mq / vq, -1.0 / vu, 1.0 / vq])
    var = float(grad @ cov @ grad) / u.size
    return math.log(snr_u / snr_q), math.sqrt(max(var, 0.0)), snr_u, snr_q


def _ideal_snr_and_ci(u: np.ndarray, energy: np.ndarray, amp: float
                      ) -> tuple[float, float, float, float]:
    """ln(ideal / measured) output SNR of the unquantised correlator, with its std."""
    # C_u = amp * E_i + noise of variance E_i (E_i = sum_n r_n^2 of trial i).
    m_e = energy.mean()
    snr_ideal = amp * amp * m_e * m_e / (m_e + amp * amp * energy.var())
    z = np.stack([u, u * u])
    mu, suu = z.mean(axis=1)
    vu = suu - mu * mu
    snr_u = mu * mu / vu
    grad = np.array([-(2.0 / mu + 2.0 * mu / vu), 1.0 / vu])
    var = float(grad @ np.cov(z) @ grad) / u.size
    return math.log(snr_ideal / snr_u), math.sqrt(max(var, 0.0)), snr_ideal, snr_u


def adc_loss_sweep(bits=range(1, 15), *, snr_db: float = -30.0, n_samples: int = 1000,
                   trials: int = 200_000, seed: int = 0, loading="optimal",
                   quantizer: str = "mid_rise", freq: float = DEFAULT_FREQ,
                   reference: bool = True, progress: bool = False) -> list[dict]:
    """Monte Carlo matched-filter loss of b-bit ADCs on a weak tone in white Gaussian noise.

    Parameters
    ----------
    bits : iterable of int
        Word lengths, each 1..24 (duplicates ignored, order kept).
    snr_db : float
        Per-sample SNR (tone power over noise power), finite. The theory is the weak-signal
        limit: keep it far below 0 dB (at the default -30 dB the bias is < 0.001 dB; at
        -20 dB about 0.01 dB at 1 bit).
    n_samples : int
        Samples per trial (correlation length ``N``), >= 1.
    trials : int
        Independent trials (noise, phase), >= 100.
    seed : int
        Seeds everything; the record does not depend on ``bits``, so a word length gives
        the same row whatever else is swept.
    loading : "optimal", "agc" or float
        Step per word length: the ``eta``-optimal step, the :mod:`cosim.tacan.signal` AGC
        (full scale ``4/0.9`` sigma), or a given full scale in noise sigmas.
    quantizer : {"mid_rise", "mid_tread"}
        ADC convention (module docstring).
    freq : float
        Tone frequency in cycles per sample, in (0, 0.5).
    reference : bool
        Append the ``bits=None`` row: unquantised output SNR against the ideal matched
        filter's (checks the estimator; its loss should be 0 within the CI).

    Returns
    -------
    list of dict
        One row per word length: ``bits``, ``quantizer``, ``loading``, ``step_over_sigma``,
        ``full_scale_over_sigma``, ``clip_fraction`` (theoretical probability of the two
        outer cells), ``eta_theory``, ``loss_db_theory``, ``loss_db_measured``,
        ``ci95_db`` (half-width), ``ci95_low_db``, ``ci95_high_db``, the correlator output
        SNRs ``out_snr_db_measured`` (this ADC), ``out_snr_db_unquantized`` (measured, no
        ADC) and ``out_snr_db_ideal`` (ideal matched filter, about ``snr_db + 10 log10 N``),
        and the run parameters (``snr_db``, ``n_samples``, ``trials``, ``seed``, ``freq``).
        The ``bits=None`` reference row has ``loss_db_measured`` = ideal over measured
        unquantised output SNR (theory 0).

    Raises
    ------
    ValueError
        Any argument out of range (message names it and repeats the value).
    """
    if isinstance(bits, (int, np.integer)) and not isinstance(bits, bool):
        bits = [bits]
    try:
        bits_in = list(bits)
    except TypeError:
        raise ValueError(f"bits must be an iterable of integers in [1, {MAX_BITS}], "
                         f"not {bits!r}") from None
    bits_list: list[int] = []
    for b in bits_in:
        b = _check_bits(b)
        if b not in bits_list:
            bits_list.append(b)
    if not bits_list:
        raise ValueError("bits must not be empty")
    if isinstance(snr_db, bool) or not isinstance(snr_db, (int, float, np.integer, np.floating)) \
            or not math.isfinite(snr_db):
        raise ValueError(f"snr_db must be a finite number, not {snr_db!r}")
    n = _check_count("n_samples", n_samples, 1)
    m = _check_count("trials", trials, 100)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, not {seed!r}")
    f = _check_positive("freq", freq)
    if not f < 0.5:
        raise ValueError(f"freq must be in (0, 0.5) cycles per sample, not {freq!r}")
    _check_quantizer(quantizer)
    steps = {b: step_for_loading(b, loading, quantizer=quantizer) for b in bits_list}

    amp = math.sqrt(2.0 * 10.0 ** (snr_db / 10.0))
    w = 2.0 * math.pi * f * np.arange(n)
    cos_w, sin_w = np.cos(w), np.sin(w)
    # sum_n cos^2(w n + p) = N/2 + Re(e^{2jp} S)/2 with S = sum_n e^{2jwn}
    s2 = complex(np.sum(np.exp(2j * w)))

    rng = np.random.default_rng(seed)
    batch = max(1, min(m, _BATCH_ELEMENTS // n))
    c_u = np.empty(m)
    c_q = {b: np.empty(m) for b in bits_list}
    energy = np.empty(m)
    x = np.empty((batch, n))
    r = np.empty((batch, n))
    buf = np.empty((batch, n))
    # Row-wise dot products by einsum: no BLAS call, so no thread pool fighting over the
    # cores (a skinny multithreaded GEMM is 10x slower on a loaded machine). The quantiser
    # output is correlated as integer codes c; the mid-rise half LSB is added back through
    # sum_n r_n (sum_n (c + 1/2) r = sum_n c r + sum_n r / 2).
    sum_cos, sum_sin = float(cos_w.sum()), float(sin_w.sum())
    half = 0.5 if quantizer == "mid_rise" else 0.0
    from tqdm import tqdm
    bar = tqdm(total=m, desc="adc-loss trials", file=sys.stderr, leave=False,
               disable=not progress or not sys.stderr.isatty())
    for t0 in range(0, m, batch):
        t1 = min(m, t0 + batch)
        nb = t1 - t0
        bar.update(nb)
        phase = rng.uniform(0.0, 2.0 * math.pi, nb)
        cp, sp = np.cos(phase), np.sin(phase)
        xb, rb, tmp = x[:nb], r[:nb], buf[:nb]
        rng.standard_normal(out=xb)
        # reference r = cos(w n + p) = cos p cos wn - sin p sin wn; signal A r
        np.multiply(cp[:, None], cos_w, out=rb)
        np.multiply(sp[:, None], sin_w, out=tmp)
        rb -= tmp
        np.multiply(rb, amp, out=tmp)
        xb += tmp
        energy[t0:t1] = 0.5 * n + 0.5 * (np.cos(2 * phase) * s2.real - np.sin(2 * phase) * s2.imag)
        c_u[t0:t1] = np.einsum("ij,ij->i", xb, rb)
        sum_r = cp * sum_cos - sp * sum_sin
        for b in bits_list:
            codes = _codes(xb, b, steps[b], quantizer, tmp)
            c_q[b][t0:t1] = np.einsum("ij,ij->i", codes, rb) + half * sum_r
    for b in bits_list:
        c_q[b] *= steps[b]

    bar.close()
    common = {"quantizer": quantizer,
              "loading": loading if isinstance(loading, str) else float(loading),
              "snr_db": float(snr_db), "n_samples": n, "trials": m, "seed": int(seed), "freq": f}
    to_db = 10.0 / math.log(10.0)
    ln_ideal, sd_ideal, snr_ideal, snr_u_meas = _ideal_snr_and_ci(c_u, energy, amp)
    rows = []
    for b in bits_list:
        step = steps[b]
        lnl, sd, snr_u, snr_q = _loss_and_ci(c_u, c_q[b])
        e1, exq, e2 = quantizer_moments(b, step, quantizer)
        eta = exq * exq / (e2 - e1 * e1) if e2 - e1 * e1 > 0 else 0.0
        clip = clip_fraction(b, step, quantizer)
        rows.append({
            "bits": b, **{k: common[k] for k in ("quantizer", "loading")},
            "step_over_sigma": step, "full_scale_over_sigma": step * (1 << (b - 1)),
            "clip_fraction": clip,
            "eta_theory": eta,
            "loss_db_theory": -10.0 * math.log10(eta) if eta > 0 else math.inf,
            "loss_db_measured": to_db * lnl,
            "ci95_db": 1.96 * to_db * sd,
            "ci95_low_db": to_db * (lnl - 1.96 * sd),
            "ci95_high_db": to_db * (lnl + 1.96 * sd),
            "out_snr_db_measured": 10.0 * math.log10(snr_q),
            "out_snr_db_unquantized": 10.0 * math.log10(snr_u),
            "out_snr_db_ideal": 10.0 * math.log10(snr_ideal),
            **{k: common[k] for k in ("snr_db", "n_samples", "trials", "seed", "freq")},
        })
    if reference:
        lnl, sd = ln_ideal, sd_ideal
        rows.append({
            "bits": None, **{k: common[k] for k in ("quantizer", "loading")},
            "step_over_sigma": 0.0, "full_scale_over_sigma": math.inf, "clip_fraction": 0.0,
            "eta_theory": 1.0, "loss_db_theory": 0.0,
            "loss_db_measured": to_db * lnl,
            "ci95_db": 1.96 * to_db * sd,
            "ci95_low_db": to_db * (lnl - 1.96 * sd),
            "ci95_high_db": to_db * (lnl + 1.96 * sd),
            "out_snr_db_measured": 10.0 * math.log10(snr_u_meas),
            "out_snr_db_unquantized": 10.0 * math.log10(snr_u_meas),
            "out_snr_db_ideal": 10.0 * math.log10(snr_ideal),
            **{k: common[k] for k in ("snr_db", "n_samples", "trials", "seed", "freq")},
        })
    return rows


# -- report ------------------------------------------------------------------------------
_CSV_FIELDS = ("bits", "quantizer", "loading", "step_over_sigma", "full_scale_over_sigma",
               "clip_fraction", "eta_theory", "loss_db_theory", "loss_db_measured", "ci95_db",
               "ci95_low_db", "ci95_high_db", "out_snr_db_measured", "out_snr_db_unquantized",
               "out_snr_db_ideal", "snr_db", "n_samples", "trials", "seed", "freq")


def write_report(rows: list[dict], out_dir, *, elapsed_s: float | None = None) -> dict:
    """Write ``adc_loss.json``, ``adc_loss.csv``, ``adc_loss.md`` and ``adc_loss.png``.

    Parameters
    ----------
    rows : list of dict
        The output of :func:`adc_loss_sweep`.
    out_dir : str or Path
        Directory (created if needed), e.g. under ``build/`` or ``results/``.
    elapsed_s : float, optional
        Run time to mention in the report.

    Returns
    -------
    dict
        ``{"json": Path, "csv": Path, "md": Path, "png": Path}``.
    """
    rows = list(rows)
    if not rows:
        raise ValueError("rows must not be empty")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {k: out / f"adc_loss.{k}" for k in ("json", "csv", "md", "png")}

    finite = [r for r in rows if r["bits"] is not None]
    refs = [r for r in rows if r["bits"] is None]
    r0 = rows[0]
    meta = {k: r0[k] for k in ("quantizer", "loading", "snr_db", "n_samples", "trials",
                               "seed", "freq")}
    if elapsed_s is not None:
        meta["elapsed_s"] = round(float(elapsed_s), 2)
    from cosim.core.provenance import machine_info
    machine = machine_info()
    meta["machine"] = machine
    checks = []
    for b, ref in REFERENCE_LOSS_DB.items():
        hit = [r for r in finite if r["bits"] == b]
        if hit and r0["quantizer"] == "mid_rise":
            err = hit[0]["loss_db_measured"] - ref
            checks.append({"bits": b, "reference_db": ref,
                           "measured_db": hit[0]["loss_db_measured"],
                           "error_db": err, "pass_0p1db": abs(err) <= 0.1})
    doc = {"meta": meta, "checks": checks,
           "rows": rows}
    paths["json"].write_text(dumps(doc, indent=2) + "\n")

    with paths["csv"].open("w", newline="") as fh:
        wr = csv.DictWriter(fh, fieldnames=_CSV_FIELDS, extrasaction="ignore")
        wr.writeheader()
        for r in rows:
            wr.writerow({k: ("inf" if r[k] is None and k == "bits" else r[k]) for k in _CSV_FIELDS})

    lines = [
        "# ADC quantisation loss: Monte Carlo vs theory",
        "",
        f"`{machine['command']}`, {machine['date']}, {machine['cpu']}, commit "
        f"{machine['commit']}.",
        "",
        f"Weak tone (per-sample SNR {meta['snr_db']:g} dB, f = {meta['freq']:.6f} cycles/sample, "
        f"random phase) in white Gaussian noise, {meta['trials']} trials x {meta['n_samples']} "
        f"samples, seed {meta['seed']}; {meta['quantizer']} ADC, loading `{meta['loading']}`. "
        "Loss = matched-filter output SNR of the unquantised record over that of the quantised "
        "one (paired); theory = -10 log10(eta), eta = E[nQ]^2 / Var Q (Van Vleck / "
        "Thompson, Moran & Swenson ch. 8 / Max)."
        + (f" Run time {meta['elapsed_s']:.1f} s." if "elapsed_s" in meta else ""),
        "",
        "| bits | step/sigma | FS/sigma | clip prob. | loss theory (dB) | loss measured (dB) "
        "| 95 % CI (dB) | measured - theory (dB) |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    def db(v: float, sign: str = "") -> str:
        return f"{v:{sign}.4f}" if abs(v) >= 1e-3 or v == 0 else f"{v:{sign}.2e}"

    for r in finite:
        lines.append(
            f"| {r['bits']} | {r['step_over_sigma']:.5g} | {r['full_scale_over_sigma']:.4g} | "
            f"{r['clip_fraction']:.3g} | {db(r['loss_db_theory'])} | {db(r['loss_db_measured'])} | "
            f"+-{db(r['ci95_db'])} | {db(r['loss_db_measured'] - r['loss_db_theory'], '+')} |")
    for r in refs:
        lines += ["", f"Estimator check (no ADC): ideal matched-filter output SNR "
                  f"{r['out_snr_db_ideal']:.3f} dB, measured {r['out_snr_db_measured']:.3f} dB, "
                  f"difference {r['loss_db_measured']:+.4f} +- {r['ci95_db']:.4f} dB (95 %)."]
    if checks:
        lines += ["", "Reference points (issue: within 0.1 dB):", ""]
        for c in checks:
            lines.append(f"- {c['bits']} bit: reference {c['reference_db']:.3f} dB, measured "
                         f"{c['measured_db']:.3f} dB, error {c['error_db']:+.3f} dB: "
                         f"{'PASS' if c['pass_0p1db'] else 'FAIL'}")
    paths["md"].write_text("\n".join(lines) + "\n")

    from ..tools.plots import pyplot, save_figure
    plt = pyplot()

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    for bref, ref in REFERENCE_LOSS_DB.items():
        ax.plot([bref], [ref], marker="*", ms=18, color="C3", mfc="none", ls="none", zorder=4,
                label="reference 1.96 / 0.55 dB" if bref == 1 else None)
        ax.annotate(f"{ref:.2f} dB", (bref, ref), textcoords="offset points", xytext=(9, 3))
    if finite:
        bb = np.array([r["bits"] for r in finite], dtype=float)
        meas = np.array([r["loss_db_measured"] for r in finite])
        ci = np.array([r["ci95_db"] for r in finite])
        th = np.array([r["loss_db_theory"] for r in finite])
        order = np.argsort(bb)
        ax.plot(bb[order], th[order], "-", color="C0", label=r"theory $-10\log_{10}\eta$")
        # Log axis: a measurement whose CI reaches 0 is drawn as its upper bound (v marker).
        sig = meas - ci > 0
        ax.errorbar(bb[sig], meas[sig], yerr=ci[sig], fmt="o", color="C1", capsize=3,
                    label="Monte Carlo, 95 % CI")
        if np.any(~sig):
            ax.plot(bb[~sig], meas[~sig] + ci[~sig], "v", color="C1", mfc="none",
                    label="Monte Carlo upper 95 % bound (CI includes 0)")
        pos = th[th > 0]
        ax.set_yscale("log")
        ax.set_ylim(max(pos.min() / 3 if pos.size else 1e-9, 1e-12), 5)
        ax2.errorbar(bb, meas - th, yerr=ci, fmt="o", color="C1", capsize=3)
        ax2.axhline(0.0, color="C0", lw=1)
        for y in (-0.1, 0.1):
            ax2.axhline(y, color="C3", ls="--", lw=1)
        ax2.set_ylim(-0.15, 0.15)
        ax2.text(0.02, 0.95, "dashed: +-0.1 dB (issue tolerance)", transform=ax2.transAxes,
                 va="top", fontsize=9)
    ax.set_xlabel("ADC bits")
    ax.set_ylabel("matched-filter SNR loss (dB)")
    ax.set_title(f"{meta['quantizer']} ADC, loading {meta['loading']}, "
                 f"SNR {meta['snr_db']:g} dB/sample",
                 fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax2.set_xlabel("ADC bits")
    ax2.set_ylabel("measured - theory (dB), 95 % CI")
    ax2.set_title(f"{meta['trials']} trials x {meta['n_samples']} samples, seed {meta['seed']}",
                  fontsize=10)
    ax2.grid(True, alpha=0.3)
    save_figure(fig, paths["png"])
    return paths


def main(argv=None, parser_class=argparse.ArgumentParser) -> int:
    """CLI: run the sweep and write the report; exit 1 when a reference point FAILs
    (``parser_class``: ``python -m cosim adc-loss`` gives its one-line-error parser)."""
    p = parser_class(prog="python -m cosim adc-loss",
                                description=__doc__.split("\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--out", default="build/adc_loss", help="output directory")
    p.add_argument("--bits", default="1:14", help="ADC word lengths: a:b or a comma list")
    p.add_argument("--snr-db", type=float, default=-30.0, help="per-sample SNR of the tone (dB)")
    p.add_argument("--n-samples", type=int, default=1000, help="samples per trial")
    p.add_argument("--trials", type=int, default=200_000, help="Monte Carlo trials (>= 100)")
    p.add_argument("--seed", type=int, default=0, help="random seed (>= 0)")
    p.add_argument("--loading", default="optimal",
                   help="ADC loading: optimal, agc, or full scale in noise sigmas")
    p.add_argument("--quantizer", default="mid_rise", choices=QUANTIZERS,
                   type=str.lower, help="quantiser characteristic")
    p.add_argument("--debug", action="store_true", help="show the traceback of an error")
    a = p.parse_args(argv)
    try:
        check_out_dir(a.out, "--out")
        try:
            if ":" in a.bits:
                lo, hi = (int(v) for v in a.bits.split(":"))
                bits = range(lo, hi + 1)
            else:
                bits = [int(v) for v in a.bits.split(",")]
        except ValueError:
            raise ValueError(f"--bits takes integers a:b or a comma list, not {a.bits!r}") \
                from None
        if len(bits) > MAX_LIST_VALUES:
            raise ValueError(f"--bits gives {len(bits)} values, at most {MAX_LIST_VALUES}")
        if a.loading in ("optimal", "agc"):
            loading = a.loading
        else:
            try:
                loading = float(a.loading)
            except ValueError:
                raise ValueError(f"--loading must be optimal, agc or a number (full scale in "
                                 f"noise sigmas), not {a.loading!r}") from None
        if isinstance(a.trials, int) and a.trials > 0:
            check_memory(8.0 * a.trials * (len(bits) + 3), f"--trials {a.trials:,} x "
                         f"{len(bits)} word lengths", "--trials or --bits")
        t0 = time.perf_counter()
        rows = adc_loss_sweep(bits, snr_db=a.snr_db, n_samples=a.n_samples, trials=a.trials,
                              seed=a.seed, loading=loading, quantizer=a.quantizer,
                              progress=True)
        elapsed = time.perf_counter() - t0
        paths = write_report(rows, a.out, elapsed_s=elapsed)
    except (ValueError, OSError, OverflowError, MemoryError) as exc:
        if a.debug:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(paths["md"].read_text())
    print(f"wrote {', '.join(str(v) for v in paths.values())}")
    failed = [c for c in json.loads(paths["json"].read_text())["checks"] if not c["pass_0p1db"]]
    if failed:
        print("error: reference points FAIL (measured loss more than 0.1 dB from the "
              "reference): " + ", ".join(f"{c['bits']} bit {c['measured_db']:.3f} dB vs "
                                         f"{c['reference_db']:.3f} dB" for c in failed),
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
