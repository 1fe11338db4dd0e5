"""The float64 golden correlator channel: the reference the FPGA channel (hdl/gnss/) and its
bit-exact model are compared with, in the same terms.

Per sample ``n`` of an epoch, with the carrier NCO phase ``phi_r`` (cycles) and the code NCO
(prompt) phase ``p`` (chips, ``0 <= p < 1023``)::

    z_X = sum_n x[n] exp(-j 2 pi phi_r[n]) c(p[n] + o_X),   o_E = +d/2, o_P = 0, o_L = -d/2
    I_X = Re z_X,  Q_X = Im z_X

(``c`` the C/A code at chip ``floor(.) mod 1023``; ``d`` the early-late spacing, chips). The
early replica is ``d/2`` chip *ahead* of the prompt: for a signal code phase ``chi``, the
prompt offset ``tau = chi - p`` gives an early correlation ``R(tau - d/2)`` and a late one
``R(tau + d/2)``, so ``E > L`` when the replica lags (``tau > 0``). With the signal model of
``cosim.gnss.signal``, ``I_P + j Q_P ~ (A M / 2) d R(tau) exp(j 2 pi (phi - phi_r))``.

Epochs are the replica's code periods: an epoch starts on the sample after the prompt
phase wraps past 1023 and holds the ``M = ceil((1023 - p0) / dp)`` samples before the next
wrap, ``dp = f_code / fs``. Both NCOs advance ``phi += f / fs`` per sample. Frequencies
written during an epoch (``set_frequencies``) take effect at the next epoch boundary
(double buffering, as the FPGA channel does). Each epoch is computed in one vectorised
pass.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dsp.jit import njit_cached

from .ca_code import CHIP_RATE_HZ, CODE_LENGTH, ca_code_levels, check_prn


@njit_cached(nogil=True)
def _epoch_kernel(x, phase0, fc, code0, dp, half, code, out):
    """One epoch, one pass: out = [IE, QE, IP, QP, IL, QL] (the sums of the docstring).

    A compiled loop rather than numpy temporaries and BLAS dot products: the machine's BLAS
    threads made the numpy form ~50x slower under load; the arithmetic is the same float64.
    """
    for m in range(x.shape[0]):
        ph = 2.0 * np.pi * (phase0 + fc * m)
        zc = x[m] * np.cos(ph)
        zs = -x[m] * np.sin(ph)
        p = code0 + dp * m
        ce = code[np.int64(np.floor(p + half)) % 1023]
        cp = code[np.int64(np.floor(p)) % 1023]
        cl = code[np.int64(np.floor(p - half)) % 1023]
        out[0] += zc * ce
        out[1] += zs * ce
        out[2] += zc * cp
        out[3] += zs * cp
        out[4] += zc * cl
        out[5] += zs * cl


def _finite(name, v):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number, not {v!r}")
    return float(v)


@dataclass
class EpochDump:
    """One epoch's dump: the six correlations and the NCO state at its start and end."""

    ie: float
    qe: float
    ip: float
    qp: float
    il: float
    ql: float
    n_start: int                # first sample of the epoch
    n_samples: int
    carrier_phase_start: float  # replica carrier phase at the first sample (cycles, mod 1)
    code_phase_start: float     # replica prompt code phase at the first sample (chips)
    carrier_phase_dump: float   # after the last sample (cycles, mod 1)
    code_phase_dump: float      # after the last sample, wrapped (chips, in [0, dp))
    carrier_freq_hz: float
    code_freq_hz: float


class GoldenCorrelator:
    """Carrier NCO wipe-off, code NCO with E/P/L replicas, integrate-and-dump per code epoch.

    Parameters
    ----------
    fs_hz : float
        Sample rate (S/s).
    prn : int
    spacing_chips : float
        Early-late spacing ``d`` (chips), 0 < d <= 2 (0.5 default).
    carrier_freq_hz, code_freq_hz : float
        Initial NCO frequencies (IF + Doppler as seen in the samples; chip rate + code Doppler).
    carrier_phase_cycles, code_phase_chips : float
        NCO phases at the first sample (code phase in [0, 1023)).
    n_start : int
        Index of the first sample fed (for the dump records).
    """

    def __init__(self, fs_hz: float, prn: int, spacing_chips: float = 0.5,
                 carrier_freq_hz: float = 0.0, code_freq_hz: float = CHIP_RATE_HZ,
                 carrier_phase_cycles: float = 0.0, code_phase_chips: float = 0.0,
                 n_start: int = 0):
        self.fs_hz = _finite("fs_hz", fs_hz)
        if self.fs_hz <= 0:
            raise ValueError(f"fs_hz must be > 0, not {fs_hz}")
        self.prn = check_prn(prn)
        d = _finite("spacing_chips", spacing_chips)
        if not 0 < d <= 2:
            raise ValueError(f"spacing_chips must be in (0, 2], not {spacing_chips!r}")
        self.spacing_chips = d
        cp = _finite("code_phase_chips", code_phase_chips)
        if not 0 <= cp < CODE_LENGTH:
            raise ValueError(f"code_phase_chips must be in [0, {CODE_LENGTH}), not {cp!r}")
        self.code = ca_code_levels(self.prn).astype(np.float64)
        self.carrier_phase = float(_finite("carrier_phase_cycles", carrier_phase_cycles) % 1.0)
        self.code_phase = cp
        self.n_next = int(n_start)
        self._cf = self._kf = None
        self.carrier_freq_hz = self.code_freq_hz = 0.0
        self.set_frequencies(carrier_freq_hz, code_freq_hz)
        self._apply()

    def set_frequencies(self, carrier_freq_hz: float, code_freq_hz: float) -> None:
        """Write the NCO frequencies; they apply from the next epoch boundary."""
        cf = _finite("carrier_freq_hz", carrier_freq_hz)
        kf = _finite("code_freq_hz", code_freq_hz)
        if not 0 < kf < self.fs_hz:
            raise ValueError(f"code_freq_hz must be in (0, fs), not {kf!r}")
        self._cf, self._kf = cf, kf

    def _apply(self):
        self.carrier_freq_hz, self.code_freq_hz = self._cf, self._kf

    def samples_needed(self) -> int:
        """Samples in the next epoch (with the frequencies that will be in force)."""
        self._apply()
        dp = self.code_freq_hz / self.fs_hz
        return max(1, int(math.ceil((CODE_LENGTH - self.code_phase) / dp)))

    def integrate(self, x: np.ndarray) -> EpochDump:
        """Run one epoch over ``x`` (exactly :meth:`samples_needed` samples)."""
        M = self.samples_needed()
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (M,):
            raise ValueError(f"this epoch needs {M} samples, not {x.shape}")
        fc, dp = self.carrier_freq_hz / self.fs_hz, self.code_freq_hz / self.fs_hz
        out = np.zeros(6)
        _epoch_kernel(x, self.carrier_phase, fc, self.code_phase, dp, self.spacing_chips / 2,
                      self.code, out)
        dump = EpochDump(out[0], out[1], out[2], out[3], out[4], out[5], self.n_next, M,
                         self.carrier_phase, self.code_phase,
                         float((self.carrier_phase + fc * M) % 1.0),
                         float(self.code_phase + dp * M - CODE_LENGTH),
                         self.carrier_freq_hz, self.code_freq_hz)
        self.carrier_phase = dump.carrier_phase_dump
        self.code_phase = dump.code_phase_dump
        self.n_next += M
        return dump


@dataclass
class CorrelatorOutput:
    """Per-epoch arrays of an open-loop run (fields as :class:`EpochDump`)."""

    ie: np.ndarray
    qe: np.ndarray
    ip: np.ndarray
    qp: np.ndarray
    il: np.ndarray
    ql: np.ndarray
    n_start: np.ndarray
    n_samples: np.ndarray
    carrier_phase_start: np.ndarray
    code_phase_start: np.ndarray

    def iq(self) -> np.ndarray:
        """``(n, 3)`` complex E, P, L."""
        return np.stack([self.ie + 1j * self.qe, self.ip + 1j * self.qp,
                         self.il + 1j * self.ql], axis=1)


def correlate(source, fs_hz: float, prn: int, carrier_freq_hz, code_freq_hz,
              spacing_chips: float = 0.5, carrier_phase_cycles: float = 0.0,
              code_phase_chips: float = 0.0, n_epochs: int | None = None,
              n_start: int = 0) -> CorrelatorOutput:
    """Open-loop golden correlation: frequencies per epoch (arrays, or scalars held).

    ``source`` is an array of samples (starting at sample ``n_start``) or a callable
    ``source(n0, n) -> samples`` (e.g. ``GnssSignalGenerator.analog``); epochs run while the
    samples last, at most ``n_epochs``.
    """
    cf = np.atleast_1d(np.asarray(carrier_freq_hz, dtype=np.float64))
    kf = np.atleast_1d(np.asarray(code_freq_hz, dtype=np.float64))
    if n_epochs is None:
        n_epochs = max(cf.size, kf.size) if max(cf.size, kf.size) > 1 else 1 << 62
    corr = GoldenCorrelator(fs_hz, prn, spacing_chips, float(cf[0]), float(kf[0]),
                            carrier_phase_cycles, code_phase_chips, n_start)
    get = source if callable(source) else None
    arr = None if callable(source) else np.asarray(source)
    dumps = []
    for k in range(n_epochs):
        corr.set_frequencies(float(cf[min(k, cf.size - 1)]), float(kf[min(k, kf.size - 1)]))
        M = corr.samples_needed()
        n0 = corr.n_next
        if arr is not None:
            if n0 - n_start + M > arr.size:
                break
            x = arr[n0 - n_start:n0 - n_start + M]
        else:
            x = get(n0, M)
            if len(x) < M:
                break
        dumps.append(corr.integrate(x))
    f = lambda a: np.array([getattr(d, a) for d in dumps])  # noqa: E731
    return CorrelatorOutput(f("ie"), f("qe"), f("ip"), f("qp"), f("il"), f("ql"),
                            f("n_start"), f("n_samples"), f("carrier_phase_start"),
                            f("code_phase_start"))
