"""GNSS sample files as SDR front ends write them: reading in blocks, writing, checks.

Formats (raw, headerless, little-endian, sample ``n`` at ``t = n / fs``)
----------------------------------------------------------------------
* ``int8``: one signed byte per sample, real samples at the IF;
* ``int8-iq``: signed bytes I0 Q0 I1 Q1 ..., complex ``I + jQ``;
* ``int16-iq``: signed 16-bit words I0 Q0 I1 Q1 ..., complex ``I + jQ``;
* ``cf32``: float32 pairs I0 Q0 ... (GNU Radio's ``gr_complex``), complex ``I + jQ``.

A real file carries the signal at ``if_hz`` (``0 <= if_hz < fs/2``); a complex file at a
complex IF ``-fs/2 < if_hz < fs/2`` (0: zero-IF baseband). ``inverted`` declares a spectrum
inverted by the front end: a complex file is then read as ``I - jQ`` (the Q sign flipped,
which PocketSDR front ends need), a real file keeps its samples and the searcher turns its
Doppler sign (:attr:`SampleFile.doppler_sign_inverted`).

ADC map
-------
How the stored numbers map to ADC words (:class:`AdcMap`, text ``kind[:bits]``):

* ``odd:B`` -- the values are the odd integers ``2q + 1`` of a ``B``-bit midrise quantiser
  (``q`` in ``[-2^(B-1), 2^(B-1) - 1]``; 2 bits: +-1, +-3, MAX2769-class front ends, the
  convention of :mod:`cosim.gnss.signal`); the ADC word is the signed ``q = (v - 1) / 2``;
  the sample value handed on is ``v``.
* ``int:B`` -- two's-complement ``B``-bit words, handed on as they are.
* ``float`` -- floating-point samples handed on as they are (finite values only).
* ``float:B`` -- floating-point samples quantised here by a ``B``-bit midrise quantiser
  whose step is set once, from the rms of the file's first block, by the AGC rule of
  :func:`cosim.gnss.signal.agc_step_sigma` (a static AGC); the values handed on are the odd
  integers ``2q + 1`` as with ``odd:B``.

Checks (all raise :class:`ValueError`, one line naming the command-line option)
--------------------------------------------------------------------------------
Before any work: the file exists and is not empty, its size is a whole number of samples of
the format, ``fs_hz`` gives a whole number of samples per 1 ms code period, ``if_hz`` lies in
the band, and the first block's values lie in the map's range. While reading: every block is
checked again, the error naming the first bad sample's index (and I or Q).
Reads never load the file whole: the file is a read-only :class:`numpy.memmap` and
:meth:`SampleFile.read` / :meth:`SampleFile.blocks` copy only the samples asked for.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dsp.gnss.ca_code import CODE_PERIOD_S

from .signal import agc_step_sigma

#: format -> (stored dtype, complex?)
FORMATS = {"int8": (np.dtype(np.int8), False), "int8-iq": (np.dtype(np.int8), True),
           "int16-iq": (np.dtype("<i2"), True), "cf32": (np.dtype("<f4"), True)}
#: The ADC map a format has unless one is given.
DEFAULT_ADC_MAP = {"int8": "odd:2", "int8-iq": "odd:2", "int16-iq": "int:16", "cf32": "float"}
#: Samples checked when a file is opened.
FIRST_BLOCK = 1 << 16
#: Default block length of :meth:`SampleFile.blocks` (samples).
BLOCK_SAMPLES = 1 << 18


def check_format(fmt) -> str:
    if fmt not in FORMATS:
        raise ValueError(f"--format must be one of {', '.join(FORMATS)}, not {fmt!r}")
    return fmt


def samples_per_ms(fs_hz) -> int:
    """Samples per 1 ms code period; a rate that gives no whole number is refused."""
    ok = not isinstance(fs_hz, bool) and isinstance(fs_hz, (int, float, np.integer, np.floating))
    if not (ok and math.isfinite(fs_hz) and fs_hz > 0):
        raise ValueError(f"--fs-hz must be a finite number > 0 Hz, not {fs_hz!r}")
    n = fs_hz * CODE_PERIOD_S
    if abs(n - round(n)) > 1e-6 * max(1.0, n) or round(n) < 1:
        raise ValueError(f"--fs-hz {fs_hz:g} gives {n:g} samples per 1 ms code period; "
                         f"acquisition needs a whole number")
    return int(round(n))


def check_if(if_hz, fs_hz: float, is_complex: bool) -> float:
    ok = not isinstance(if_hz, bool) and isinstance(if_hz, (int, float, np.integer, np.floating))
    if not (ok and math.isfinite(if_hz)):
        raise ValueError(f"--if-hz must be a finite number (Hz), not {if_hz!r}")
    f = float(if_hz)
    if is_complex and not -fs_hz / 2 < f < fs_hz / 2:
        raise ValueError(f"--if-hz of a complex recording must be in (-fs/2, fs/2) = "
                         f"({-fs_hz / 2:g}, {fs_hz / 2:g}) Hz, not {f:g}")
    if not is_complex and not 0 <= f < fs_hz / 2:
        raise ValueError(f"--if-hz of a real recording must be in [0, fs/2) = "
                         f"[0, {fs_hz / 2:g}) Hz, not {f:g}")
    return f


@dataclass(frozen=True)
class AdcMap:
    """Stored numbers -> ADC words and sample values (module docstring).

    Parameters
    ----------
    kind : {"odd", "int", "float"}
    bits : int or None
        Word length; None only for ``float`` (no quantisation).
    """

    kind: str
    bits: int | None = None

    @classmethod
    def parse(cls, text, fmt: str) -> "AdcMap":
        """``odd:B``, ``int:B``, ``float`` or ``float:B``, checked against the format."""
        fmt = check_format(fmt)
        if text is None:
            text = DEFAULT_ADC_MAP[fmt]
        if not isinstance(text, str):
            raise ValueError(f"--adc-map must be text such as odd:2, int:12, float or float:4, "
                             f"not {text!r}")
        kind, _, b = text.partition(":")
        limit = {"int8": 8, "int8-iq": 8, "int16-iq": 16, "cf32": 16}[fmt]
        if kind not in ("odd", "int", "float") or (kind != "float" and not b) \
                or (b and not b.isdigit()):
            raise ValueError(f"--adc-map must be odd:B, int:B, float or float:B (B = bits), "
                             f"not {text!r}")
        bits = int(b) if b else None
        if bits is not None and not 1 <= bits <= limit:
            raise ValueError(f"--adc-map {text}: bits must be in [1, {limit}] for --format "
                             f"{fmt}, not {bits}")
        if kind == "float" and fmt != "cf32":
            raise ValueError(f"--adc-map {text}: float maps are for --format cf32, not {fmt}")
        return cls(kind, bits)

    def __str__(self) -> str:
        return self.kind + (f":{self.bits}" if self.bits is not None else "")

    @property
    def range_text(self) -> str:
        b = self.bits
        if self.kind == "odd":
            return f"odd integers in [{1 - 2 ** b}, {2 ** b - 1}]"
        if self.kind == "int":
            return f"integers in [{-2 ** (b - 1)}, {2 ** (b - 1) - 1}]"
        return "finite numbers"

    def bad(self, v: np.ndarray) -> np.ndarray:
        """Mask of stored values outside the map."""
        if self.kind == "float":
            return ~np.isfinite(v)
        b = self.bits
        if self.kind == "odd":
            lo, hi = 1 - 2 ** b, 2 ** b - 1
        else:
            lo, hi = -2 ** (b - 1), 2 ** (b - 1) - 1
        with np.errstate(invalid="ignore"):
            out = ~((v >= lo) & (v <= hi))
            if v.dtype.kind == "f":
                out |= v != np.floor(v)
            if self.kind == "odd":
                out |= np.mod(v, 2) != 1
        return out

    @property
    def odd_levels(self) -> bool:
        """Whether the values handed on are the odd levels ``2q + 1`` of the ADC word ``q``
        (``odd:B`` and ``float:B``): a channel must take the word as ``2q + 1``, the
        two's-complement reading ``q`` leaving a DC of -1/2 LSB beside the signal."""
        return self.kind == "odd" or (self.kind == "float" and self.bits is not None)

    def quantise(self, x: np.ndarray, step: float) -> np.ndarray:
        """``float:B``: midrise codes ``2q + 1`` of ``x`` with step ``step``."""
        b = self.bits
        q = np.clip(np.floor(x / step), -2.0 ** (b - 1), 2.0 ** (b - 1) - 1)
        return 2 * q + 1


class SampleFile:
    """A recording on disk, read in blocks (module docstring).

    Parameters
    ----------
    path : str or Path
    fmt : {"int8", "int8-iq", "int16-iq", "cf32"}
    fs_hz : float
        Sample rate (S/s); must give a whole number of samples per 1 ms.
    if_hz : float
        IF (Hz): real ``[0, fs/2)``, complex ``(-fs/2, fs/2)``.
    inverted : bool
        Spectrum inverted by the front end (complex: read as ``I - jQ``).
    adc_map : str, AdcMap or None
        ``odd:B``, ``int:B``, ``float`` or ``float:B``; None = the format's default
        (:data:`DEFAULT_ADC_MAP`).
    """

    def __init__(self, path, fmt: str, fs_hz: float, if_hz: float = 0.0,
                 inverted: bool = False, adc_map=None):
        self.fmt = check_format(fmt)
        self.dtype, self.is_complex = FORMATS[fmt]
        self.adc_map = adc_map if isinstance(adc_map, AdcMap) else AdcMap.parse(adc_map, fmt)
        self.fs_hz = float(fs_hz) if not isinstance(fs_hz, bool) and \
            isinstance(fs_hz, (int, float, np.integer, np.floating)) else fs_hz
        self.samples_per_ms = samples_per_ms(fs_hz)
        self.if_hz = check_if(if_hz, self.fs_hz, self.is_complex)
        if not isinstance(inverted, bool):
            raise ValueError(f"--invert-spectrum must be True or False, not {inverted!r}")
        self.inverted = inverted
        self.path = Path(path)
        if not self.path.is_file():
            raise ValueError(f"--file: no such file: {self.path}")
        size = os.path.getsize(self.path)
        if size == 0:
            raise ValueError(f"--file: {self.path} is empty")
        item = self.dtype.itemsize
        if size % item:
            raise ValueError(f"--format {fmt}: {self.path} has {size} bytes, not a whole number "
                             f"of {item}-byte values")
        if self.is_complex and (size // item) % 2:
            raise ValueError(f"--format {fmt}: {self.path} holds {size // item} values, an odd "
                             f"number; interleaved I/Q needs pairs")
        self._raw = np.memmap(self.path, dtype=self.dtype, mode="r")
        self.n_samples = self._raw.size // (2 if self.is_complex else 1)
        self.step = None
        if self.adc_map.kind == "float" and self.adc_map.bits is not None:
            x = self._stored(0, min(FIRST_BLOCK, self.n_samples))
            self._check(x, 0)
            rms = float(np.sqrt(np.mean(x.astype(np.float64) ** 2)))
            if not rms > 0:
                raise ValueError(f"--adc-map {self.adc_map}: the first block of {self.path} is "
                                 f"all zeros; the quantiser step cannot be set")
            self.step = agc_step_sigma(self.adc_map.bits) * rms
        self.read(0, min(FIRST_BLOCK, self.n_samples))     # the up-front range check

    @property
    def doppler_sign_inverted(self) -> bool:
        """Whether a searcher must turn the Doppler sign: a real file with an inverted
        spectrum (a complex one is already read as ``I - jQ``)."""
        return self.inverted and not self.is_complex

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.fs_hz

    @property
    def n_ms(self) -> int:
        """Whole 1 ms code periods in the file."""
        return self.n_samples // self.samples_per_ms

    def _stored(self, n0: int, n: int) -> np.ndarray:
        k = 2 if self.is_complex else 1
        return np.array(self._raw[k * n0:k * (n0 + n)])

    def _check(self, v: np.ndarray, n0: int) -> None:
        bad = self.adc_map.bad(v)
        if bad.any():
            i = int(np.argmax(bad))
            where = (f"sample {n0 + i // 2} ({'IQ'[i % 2]})" if self.is_complex
                     else f"sample {n0 + i}")
            raise ValueError(f"--adc-map {self.adc_map}: {where} of {self.path} is "
                             f"{v[i].item()!r}, "
                             f"outside the map's {self.adc_map.range_text}")

    def read(self, n0: int, n: int) -> np.ndarray:
        """Samples ``n0 .. n0 + n - 1`` (fewer at the end of the file): float64 for a real
        file, complex128 (``I + jQ``, or ``I - jQ`` if inverted) for a complex one, the
        values of the ADC map (module docstring)."""
        if isinstance(n0, bool) or not isinstance(n0, (int, np.integer)) or n0 < 0 \
                or isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"sample range must be integers >= 0, not n0={n0!r}, n={n!r}")
        n = max(0, min(int(n), self.n_samples - int(n0)))
        v = self._stored(int(n0), n)
        self._check(v, int(n0))
        x = v.astype(np.float64)
        if self.step is not None:
            x = self.adc_map.quantise(x, self.step)
        if not self.is_complex:
            return x
        z = x[0::2] + 1j * x[1::2]
        return np.conj(z) if self.inverted else z

    def words(self, n0: int, n: int) -> np.ndarray:
        """Signed ADC words of samples ``n0 ..`` (int64; complex files: shape (n, 2), I and Q
        as read, after the Q sign of ``inverted``). Not for the unquantised ``float`` map."""
        if self.adc_map.kind == "float" and self.adc_map.bits is None:
            raise ValueError("--adc-map float has no ADC words (give float:B to quantise)")
        x = self.read(n0, n)
        if self.is_complex:
            x = np.stack([x.real, x.imag], axis=-1)
        if self.adc_map.kind == "int":
            return x.astype(np.int64)
        return ((x - 1) / 2).astype(np.int64)

    def blocks(self, block_samples: int = BLOCK_SAMPLES, n0: int = 0, n: int | None = None):
        """Iterate ``(first_sample_index, samples)`` over the file (or ``n`` samples from
        ``n0``) in blocks of ``block_samples``."""
        if isinstance(block_samples, bool) or not isinstance(block_samples, (int, np.integer)) \
                or block_samples < 1:
            raise ValueError(f"block_samples must be an integer >= 1, not {block_samples!r}")
        end = self.n_samples if n is None else min(self.n_samples, n0 + n)
        for a in range(n0, end, block_samples):
            yield a, self.read(a, min(block_samples, end - a))

    def describe(self) -> dict:
        return {"file": str(self.path), "format": self.fmt, "fs_hz": self.fs_hz,
                "if_hz": self.if_hz, "inverted": self.inverted, "adc_map": str(self.adc_map),
                "n_samples": self.n_samples, "duration_s": self.duration_s}


def write_samples(path, fmt: str, blocks, adc_map=None) -> int:
    """Write sample blocks (real arrays for ``int8``, complex ``I + jQ`` for the I/Q formats,
    values of the ADC map) to ``path`` in format ``fmt``, block by block; every value is
    checked against the map first. Returns the number of samples written. A spectrum
    inversion is the caller's (write ``conj`` for a file to be read with ``inverted``)."""
    fmt = check_format(fmt)
    amap = adc_map if isinstance(adc_map, AdcMap) else AdcMap.parse(adc_map, fmt)
    dtype, cplx = FORMATS[fmt]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    n_done = 0
    with open(path, "wb") as f:
        for b in blocks:
            b = np.asarray(b)
            if cplx:
                v = np.empty(2 * b.size)
                v[0::2], v[1::2] = b.real, b.imag
            else:
                if np.iscomplexobj(b):
                    raise ValueError(f"--format {fmt} stores real samples, not complex ones")
                v = b.astype(np.float64)
            bad = amap.bad(v)
            if bad.any():
                i = int(np.argmax(bad))
                raise ValueError(f"--adc-map {amap}: value {v[i].item()!r} at sample "
                                 f"{n_done + (i // 2 if cplx else i)} is outside the map's "
                                 f"{amap.range_text}")
            f.write(v.astype(dtype).tobytes())
            n_done += b.size
    return n_done
