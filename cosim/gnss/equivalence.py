"""Equivalence of the GNSS channel's bit-exact model, Amaranth simulation and Verilated
Verilog (``python -m cosim check-equivalence --top gnss``): one seeded GPS L1 C/A record with
register writes through the three sessions (:func:`cosim.gnss.session.open_gnss`), every
FIFO word, the cycle it leaves on and the overflow counter compared with the model's
(:func:`cosim.tools.equivalence.compare_backends`).

The record: PRN 7 at 45 dB-Hz, 2-bit ADC, 900 m/s closing with 10 m/s^2, from the signal
generator (:mod:`cosim.gnss.signal`) at a reduced rate (:data:`EQUIV_PARAMS`: 5.115 MS/s,
IF fs/4, 5115 samples per code period, so pysim runs a few periods in seconds). The writes:
the hand-over of the true Doppler and code phase (carrier word, code word, slew), then
seeded writes from the third code period on, every :data:`WRITE_SPACING` cycles on average:
carrier words within +-300 Hz of the true Doppler, code words within +-20 Hz, slews of 0-4
samples, and PRN changes (another PRN, then back to 7), so every register and the double
buffering are exercised on a signal that correlates (the prompt on the peak, E = L).
``stall=True``: the DSP ``ready`` follows :func:`cosim.tools.equivalence.stall_pattern` and the
FIFO holds one record and a marker (``record_words + 2`` words: records dropped, the counter compared).

The complex-input channel (``params.input == "complex"``, e.g. :data:`EQUIV_PARAMS_IQ`:
the same rate at zero IF) is checked on a zero-IF I/Q record of the same satellite from the
synthetic-recording generator (:class:`cosim.gnss.synthetic_file.SyntheticRecording`,
``int8-iq``, 2-bit ``odd`` ADC words, 45 dB-Hz, the same Doppler held constant), with the
same hand-over and seeded writes; every backend is fed the packed I/Q payload words
(:meth:`hdl.gnss.params.GnssChannelParams.pack_samples`).
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from dsp.gnss.ca_code import CHIP_RATE_HZ, L1_HZ
from dsp.gnss.ephemeris import C_LIGHT
from hdl.gnss.params import GnssChannelParams

from ..tools.equivalence import (BACKENDS, PYSIM_MAX_SAMPLES, check_samples_backends,
                                 compare_backends, stall_pattern)

__all__ = ["check_gnss_equivalence", "gnss_equivalence_stimulus", "EQUIV_PARAMS",
           "EQUIV_PARAMS_IQ", "EQUIV_PRN"]

#: Reduced rate for the check: 5 samples per chip, IF fs/4, 0.4-chip early-late spacing.
EQUIV_PARAMS = GnssChannelParams(fs_hz=5.115e6, if_hz=5.115e6 / 4, el_spacing_samples=2,
                                 slew_bits=13, fifo_depth=64)
#: The complex-input channel of the check: the same, I and Q at zero IF.
EQUIV_PARAMS_IQ = replace(EQUIV_PARAMS, input="complex", if_hz=0.0)
#: The satellite in the record.
EQUIV_PRN = 7
#: Mean cycles between two seeded register writes.
WRITE_SPACING = 1500
#: Cycles run after the last sample (the last record leaves the pipeline and the FIFO).
FLUSH_CYCLES = 400


def gnss_equivalence_stimulus(params: GnssChannelParams, samples: int, seed: int, *,
                              write_spacing: int = WRITE_SPACING, first: int | None = None,
                              signal: bool = True):
    """``(adc_words, writes)``: the record's ADC words (complex input: ``(n, 2)`` I/Q
    pairs) and its register writes ``(cycle, register name, value)``, in cycle order: the
    hand-over, then seeded writes every ``write_spacing`` cycles on average from cycle
    ``first`` (default: two code periods, module doc). ``signal=False``: seeded uniform ADC
    words instead of the satellite's signal (for a rate the generator refuses, e.g. a real
    IF at 2 samples per chip), the same writes."""
    from .dynamics import PolynomialProfile
    from .handover import handover_writes
    from .tracking import adc_words
    from .signal import GnssSignalConfig, generate
    rng = np.random.default_rng(seed)
    code0 = float(rng.uniform(0, 1023))
    doppler = 900.0 * L1_HZ / C_LIGHT
    if not signal:
        lo = -(1 << (params.adc_bits - 1))
        x = rng.integers(lo, -lo, (samples, 2) if params.complex_input else samples)
        inverted = False
    elif params.complex_input:
        from .synthetic_file import SatelliteSpec, SyntheticRecording
        rec = SyntheticRecording("int8-iq", params.fs_hz, params.if_hz,
                                 (samples + 1) / params.fs_hz,
                                 [SatelliteSpec(EQUIV_PRN, doppler, code0, 45.0)],
                                 adc_map=f"odd:{params.adc_bits}", seed=seed)
        z = rec.samples(0, samples)
        x = adc_words(np.stack([z.real, z.imag], axis=-1).astype(np.int64))
        inverted = False
    else:
        cfg = GnssSignalConfig(prn=EQUIV_PRN, if_hz=params.if_hz, fs_hz=params.fs_hz,
                               adc_bits=params.adc_bits, cn0_dbhz=45.0,
                               duration_s=(samples + 1) / params.fs_hz,
                               dynamics=PolynomialProfile(range_rate_mps=-900.0,
                                                          range_accel_mps2=10.0),
                               code_phase_chips=code0, seed=seed)
        x = adc_words(generate(cfg).samples[:samples])
        inverted = cfg.spectrum_inverted
    writes = handover_writes(params, doppler, code0, inverted)
    writes = [(0, "prn", EQUIV_PRN)] + [(c + 1, r, v) for c, r, v in writes]
    # The hand-over takes effect at the first dump boundary and its slew during the second
    # code period: the seeded writes start after it, so the third record is on the peak.
    if first is None:
        first = 2 * round(params.fs_hz * 1e-3)
    n_w = max(0, (samples - first) // write_spacing)
    cycles = np.sort(rng.choice(np.arange(first, samples), n_w, replace=False)) if n_w else []
    other = False
    for c in cycles:
        reg = ("carr_freq", "code_freq", "slew", "prn")[int(rng.integers(0, 4))]
        if reg == "carr_freq":
            v = params.carr_word(params.if_hz + doppler + float(rng.uniform(-300, 300)))
        elif reg == "code_freq":
            v = params.code_word(CHIP_RATE_HZ * (1 + doppler / L1_HZ)
                                 + float(rng.uniform(-20, 20)))
        elif reg == "slew":
            v = int(rng.integers(0, 5))
        else:
            v = EQUIV_PRN if other else int(rng.choice([n for n in range(1, 33)
                                                        if n != EQUIV_PRN]))
            other = not other
        writes.append((int(c), reg, int(v)))
    return x, writes


def check_gnss_equivalence(samples: int = 20_000, *, backends=BACKENDS, seed: int = 1,
                           stall: bool = False, params: GnssChannelParams | None = None,
                           pysim_max_samples: int = PYSIM_MAX_SAMPLES,
                           progress: bool = False) -> dict:
    """The keys of :func:`cosim.tacan.equivalence.check_equivalence` (``peaks``: the model's
    records; ``dropped``: its overflow count) for the GNSS channel (module doc)."""
    from .session import open_gnss
    check_samples_backends(samples, backends)
    if params is None:
        params = EQUIV_PARAMS
        if stall:
            params = replace(params, fifo_depth=params.fifo.record_words + 2)
    if not isinstance(params, GnssChannelParams) or params.channel_bits:
        raise ValueError(f"params must be a single-channel GnssChannelParams, not {params!r}")
    samples = int(samples)
    x, writes = gnss_equivalence_stimulus(params, samples, seed)
    words = params.pack_samples(x)      # the i port's payloads (I/Q packed if complex)
    n_cycles = samples + params.latency + params.fifo.record_words + FLUSH_CYCLES
    ready = stall_pattern(n_cycles, seed) if stall else np.ones(n_cycles, bool)

    def run(backend):
        t = time.perf_counter()
        with open_gnss(backend, params) as fe:
            for c, reg, v in writes:
                fe.write(reg, v, cycle=c)
            r = fe.step(words, ready, n_cycles=n_cycles)
            ovf = int(fe.read("overflow_count"))
        return (np.asarray(r.words, np.int64), np.asarray(r.cycles, np.int64), ovf,
                time.perf_counter() - t)

    return compare_backends("gnss", samples, backends, run, seed=seed, stall=stall,
                            record_words=params.fifo.record_words,
                            pysim_max_samples=pysim_max_samples,
                            empty_hint=f"a record every {round(params.fs_hz / 1e3)} "
                                       f"samples, one code period")
