"""Synthetic multi-satellite GPS L1 C/A recordings with known truth, written as sample files.

A recording of ``N`` satellites goes through exactly the path a real one does: written here
by :func:`cosim.gnss.files.write_samples` in a front end's format, read back by
:class:`cosim.gnss.files.SampleFile`.

Model
-----
Each satellite ``i`` is the one-satellite model of :mod:`cosim.gnss.signal` (rectangular
chips, 50 bit/s data with edges on code epochs, code Doppler = carrier Doppler / 1540),
computed by that module's sample kernel, with a constant Doppler ``f_i``, the code phase
``tau_i`` (chips) and carrier phase ``phi_i`` (cycles) at sample 0. Real files::

    x[n] = sum_i A_i d_i c_i cos(2 pi (f_IF n / fs + s (phi_i + f_i n / fs))) + w[n]

(``s = -1`` for an inverted spectrum); complex files carry
``sqrt(C_i) d_i c_i exp(j 2 pi (f_IF n / fs + phi_i + f_i n / fs))`` plus complex noise, and
are stored as ``I - jQ`` when inverted. The noise is white Gaussian, variance 1 per real
component, so ``N0 = 2 / fs`` over the sampled band; the carrier powers are
``C_i = (C/N0)_i N0`` (real: ``A_i = sqrt(2 C_i)``). With these definitions a correlator
summing ``M = T fs`` samples sees the post-correlation SNR ``(C/N0) T`` (as in
:mod:`cosim.gnss.signal` and :mod:`dsp.gnss.cn0`).

The ADC is the declared map's quantiser with an ideal static AGC: the step is
:func:`cosim.gnss.signal.agc_step_sigma` times the known input rms per component
(``odd:B``: values ``2q + 1``; ``int:B``: the words ``round(x / step)`` clipped; ``float``:
no quantiser, ``float:B``: floats written, the reader quantises).

Random streams: ``SeedSequence(seed, spawn_key=(0, c))`` noise chunk ``c`` of
:data:`cosim.gnss.signal.NOISE_CHUNK` samples (so any block is generated alone),
``(1, i)`` satellite ``i``'s navigation bits. Same seed, same file, for any block length.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dsp.gnss.ca_code import CHIP_RATE_HZ, CODE_LENGTH, L1_HZ, ca_code_levels, check_prn

from .files import BLOCK_SAMPLES, FORMATS, AdcMap, check_format, check_if, samples_per_ms, \
    write_samples
from .signal import CHIPS_PER_BIT, NOISE_CHUNK, if_kernel, agc_step_sigma


def noise_block(seed: int, n0: int, n: int, stream: int) -> np.ndarray:
    """Unit-variance white Gaussian noise, samples ``n0 .. n0 + n - 1`` of component
    ``stream`` (0: real or I, 1: Q): chunk ``c`` of :data:`cosim.gnss.signal.NOISE_CHUNK`
    samples from ``SeedSequence(seed, spawn_key=(0, c, stream))``, so any block is the same
    whatever the blocks around it."""
    out = np.empty(n)
    pos = 0
    for c in range(n0 // NOISE_CHUNK, (n0 + n - 1) // NOISE_CHUNK + 1):
        z = np.random.default_rng(np.random.SeedSequence(
            int(seed), spawn_key=(0, c, stream))).standard_normal(NOISE_CHUNK)
        a, b = max(n0 - c * NOISE_CHUNK, 0), min(n0 + n - c * NOISE_CHUNK, NOISE_CHUNK)
        out[pos:pos + b - a] = z[a:b]
        pos += b - a
    return out


def adc_levels(x: np.ndarray, amap: AdcMap, step: float | None) -> np.ndarray:
    """The ADC map's values of real samples ``x`` with the AGC step ``step`` (module notes;
    ``step`` None: no quantiser, the floats as they are)."""
    if step is None:
        return x
    b = amap.bits
    if amap.kind == "odd":
        return amap.quantise(x, step)
    return np.clip(np.round(x / step), -2.0 ** (b - 1), 2.0 ** (b - 1) - 1)


@dataclass(frozen=True)
class SatelliteSpec:
    """One satellite of a synthetic recording: PRN, Doppler (Hz), code phase at sample 0
    (chips, ``[0, 1023)``), C/N0 (dB-Hz), carrier phase at sample 0 (cycles)."""

    prn: int
    doppler_hz: float
    code_phase_chips: float
    cn0_dbhz: float
    carrier_phase_cycles: float = 0.0

    def __post_init__(self):
        check_prn(self.prn)
        for name in ("doppler_hz", "code_phase_chips", "cn0_dbhz", "carrier_phase_cycles"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v):
                raise ValueError(f"satellite PRN {self.prn}: {name} must be a finite number, "
                                 f"not {v!r}")
        if not 0 <= self.code_phase_chips < CODE_LENGTH:
            raise ValueError(f"satellite PRN {self.prn}: code_phase_chips must be in "
                             f"[0, {CODE_LENGTH}), not {self.code_phase_chips!r}")


class SyntheticRecording:
    """The scenario realised: any block of samples (levels of the ADC map).

    Parameters
    ----------
    fmt : str
        File format (:data:`cosim.gnss.files.FORMATS`): real for ``int8``, complex otherwise.
    fs_hz, if_hz : float
    duration_s : float
    satellites : sequence of SatelliteSpec
        Distinct PRNs (none: a noise-only recording).
    adc_map : str, AdcMap or None
    inverted : bool
    nav_data : bool
    seed : int
    """

    def __init__(self, fmt: str, fs_hz: float, if_hz: float, duration_s: float, satellites,
                 adc_map=None, inverted: bool = False, nav_data: bool = True, seed: int = 1):
        self.fmt = check_format(fmt)
        self.is_complex = FORMATS[fmt][1]
        samples_per_ms(fs_hz)
        self.fs_hz = float(fs_hz)
        self.if_hz = check_if(if_hz, self.fs_hz, self.is_complex)
        self.adc_map = adc_map if isinstance(adc_map, AdcMap) else AdcMap.parse(adc_map, fmt)
        if isinstance(duration_s, bool) or not isinstance(duration_s, (int, float)) \
                or not math.isfinite(duration_s) or duration_s <= 0:
            raise ValueError(f"duration_s must be a number > 0 s, not {duration_s!r}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be an integer >= 0, not {seed!r}")
        sats = tuple(satellites)
        if any(not isinstance(s, SatelliteSpec) for s in sats):
            raise ValueError("satellites must be SatelliteSpec entries")
        prns = [s.prn for s in sats]
        if len(set(prns)) != len(prns):
            raise ValueError(f"satellite PRNs must be distinct, not {prns}")
        self.satellites, self.inverted, self.seed = sats, bool(inverted), int(seed)
        self.n_samples = int(round(duration_s * self.fs_hz))
        n0 = 2.0 / self.fs_hz
        self.amps = [math.sqrt((2.0 if not self.is_complex else 1.0) * 10 ** (s.cn0_dbhz / 10) * n0)
                     for s in sats]
        # input rms per real component: unit noise + each carrier's share
        share = [a * a / 2 for a in self.amps]
        self.rms = math.sqrt(1.0 + sum(share))
        self.step = None
        if self.adc_map.bits is not None and self.adc_map.kind != "float":
            self.step = agc_step_sigma(self.adc_map.bits) * self.rms
        self._bits = []
        for i, s in enumerate(sats):
            chi_hi = s.code_phase_chips + \
                duration_s * CHIP_RATE_HZ * (1 + abs(s.doppler_hz) / L1_HZ)
            bit0 = -1
            nb = int(math.floor(chi_hi / CHIPS_PER_BIT)) - bit0 + 2
            rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(1, i)))
            bits = 1.0 - 2.0 * rng.integers(0, 2, nb) if nav_data else np.ones(nb)
            self._bits.append((bit0, bits))

    def _noise(self, n0: int, n: int, stream: int) -> np.ndarray:
        return noise_block(self.seed, n0, n, stream)

    def _carrier(self, i: int, n0: int, n: int, quarter: bool) -> np.ndarray:
        s = self.satellites[i]
        m = s.doppler_hz * np.arange(n0, n0 + n, dtype=np.float64) / self.fs_hz
        sign = -1.0 if (self.inverted and not self.is_complex) else 1.0
        out = np.empty(n)
        bit0, bits = self._bits[i]
        if_kernel(n0, self.if_hz / self.fs_hz, sign,
                   s.carrier_phase_cycles - (0.25 if quarter else 0.0), s.code_phase_chips,
                   CHIP_RATE_HZ / self.fs_hz, m, m, ca_code_levels(s.prn).astype(np.float64),
                   bits, bit0, 0.0, np.zeros(0), self.amps[i], out)
        return out

    def analog(self, n0: int, n: int) -> np.ndarray:
        """Samples ``n0 .. n0 + n - 1`` before the ADC (float64 or complex128, ``I + jQ``
        before any inversion)."""
        n = max(0, min(n, self.n_samples - n0))
        x = self._noise(n0, n, 0)
        for i in range(len(self.satellites)):
            x += self._carrier(i, n0, n, False)
        if not self.is_complex:
            return x
        y = self._noise(n0, n, 1)
        for i in range(len(self.satellites)):
            y += self._carrier(i, n0, n, True)
        return x + 1j * y

    def _adc(self, x: np.ndarray) -> np.ndarray:
        return adc_levels(x, self.adc_map, self.step)

    def samples(self, n0: int, n: int) -> np.ndarray:
        """Samples as stored (the ADC map's values; complex: ``I - jQ`` if inverted)."""
        x = self.analog(n0, n)
        if not self.is_complex:
            return self._adc(x)
        if self.inverted:       # the front end's Q sign, before its ADC
            x = np.conj(x)
        return self._adc(x.real) + 1j * self._adc(x.imag)

    def blocks(self, block_samples: int = BLOCK_SAMPLES):
        for a in range(0, self.n_samples, block_samples):
            yield self.samples(a, min(block_samples, self.n_samples - a))

    def truth(self) -> list[dict]:
        """Per satellite: PRN, Doppler (Hz), code phase at sample 0 (chips), C/N0 (dB-Hz)."""
        return [{"prn": s.prn, "doppler_hz": float(s.doppler_hz),
                 "code_phase_chips": float(s.code_phase_chips), "cn0_dbhz": float(s.cn0_dbhz)}
                for s in self.satellites]


def write_synthetic(path, fmt: str, fs_hz: float, if_hz: float, duration_s: float, satellites,
                    adc_map=None, inverted: bool = False, nav_data: bool = True, seed: int = 1,
                    block_samples: int = BLOCK_SAMPLES) -> SyntheticRecording:
    """Write a synthetic recording (:class:`SyntheticRecording`) to ``path`` in blocks and
    return it (its :meth:`~SyntheticRecording.truth` is the known answer)."""
    rec = SyntheticRecording(fmt, fs_hz, if_hz, duration_s, satellites, adc_map, inverted,
                             nav_data, seed)
    write_samples(path, fmt, rec.blocks(block_samples), rec.adc_map)
    return rec
