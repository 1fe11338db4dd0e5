"""GPS L1 C/A acquisition from a sample snapshot: parallel code-phase search by FFT.

Search
------
The snapshot ``x[n]`` (real IF samples, or complex samples at a complex IF such as 0;
``n = 0 .. N_tot - 1`` from sample ``n0`` of the record) is cut into code periods of
``N = fs T_code`` samples (``fs`` must give a whole number per 1 ms period). For each
Doppler bin ``f_D`` the carrier is wiped off,
``y[n] = x[n] exp(-j 2 pi (f_IF + s f_D) n / fs)`` (``s = -1`` for an inverted spectrum),
and for every code period ``p`` the circular correlation with the sampled replica
``c_r[n] = c(floor(n f_chip / fs))`` is taken by FFT::

    Y_p[m] = sum_n y[pN + n] c_r[(n + m) mod N]        (m = code-phase cell, samples)

``Y_p`` of ``n_coherent`` consecutive periods are summed coherently (coherent time
``T = n_coherent`` ms; the carrier phase runs continuously across periods), and the squared
magnitudes of ``K = n_noncoherent`` such sums are added: ``S[bin, m] = sum_k |Y_k[m]|^2``.
Doppler bins are spaced ``bin_width_hz`` (default ``2 / (3 T)``: the worst-case loss of a
``sinc`` coherent response at a third of its null spacing off-centre, 1.65 dB) over
``[-max_doppler_hz, +max_doppler_hz]``.

Detection statistic and threshold
---------------------------------
Under H0 (no signal of this PRN), each ``Y_k[m]`` is zero-mean circular complex Gaussian
with a variance ``sigma^2`` per real component (the input noise summed over ``n_coherent N``
samples); ``|Y_k|^2 / sigma^2`` is chi-square with 2 degrees of freedom and the normalised
non-coherent sum ``Lambda = S / sigma^2`` is chi-square with ``2K`` degrees of freedom.
``sigma^2`` is estimated from the search itself: ``sigma_hat^2 = mean(S) / (2K)`` over all
cells (a present signal occupies a few cells of ~1e5; its bias on the estimate is below
0.1 % at 50 dB-Hz). The threshold is set for a *per-search* false-alarm probability
``pfa`` over all ``N_cells = n_bins N`` cells::

    pfa_cell = 1 - (1 - pfa)^(1 / N_cells),   Lambda_th = chi2_{2K}.isf(pfa_cell)

which treats the cells as independent. Neighbouring cells are correlated (cells are
``f_chip / fs`` chip apart and Doppler bins closer than the ``1/T`` null spacing), so the
true per-search false-alarm rate is *at most* ``pfa`` (the Monte Carlo test checks it
against a binomial bound, from above). The PRN is reported if ``max Lambda > Lambda_th``.

Hand-over
---------
``doppler_hz`` is the peak's bin centre and ``code_phase_chips`` the received code phase
at the snapshot's first sample, ``m f_chip / fs`` (chips, in ``[0, 1023)``): the initial
``carrier_freq_hz = f_IF + s doppler_hz``, ``code_freq_hz = f_chip (1 + doppler / L1)``
and ``code_phase_chips`` of a :class:`dsp.gnss.correlator.GoldenCorrelator` started at
sample ``n0`` (:meth:`AcquisitionResult.channel_init`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .ca_code import CHIP_RATE_HZ, CODE_LENGTH, CODE_PERIOD_S, L1_HZ, ca_code_levels, check_prn


def _samples(x) -> np.ndarray:
    """Real samples as float64, complex (baseband) samples as complex128."""
    x = np.asarray(x)
    return x.astype(np.complex128 if np.iscomplexobj(x) else np.float64, copy=False)


def threshold(pfa: float, n_cells: int, n_noncoherent: int) -> float:
    """``Lambda_th`` for a per-search false-alarm probability ``pfa`` over ``n_cells``
    independent chi-square(2K) cells (module docstring)."""
    if not (0 < pfa < 1):
        raise ValueError(f"pfa must be in (0, 1), not {pfa!r}")
    from scipy import stats      # here, not at import: a command's refusals need no scipy.stats
    pfa_cell = -math.expm1(math.log1p(-pfa) / n_cells)
    return float(stats.chi2.isf(pfa_cell, 2 * n_noncoherent))


@dataclass
class AcquisitionResult:
    prn: int
    detected: bool
    doppler_hz: float           # peak bin centre (Hz)
    code_phase_chips: float     # received code phase at the snapshot's first sample
    code_phase_samples: int
    peak: float                 # max Lambda (normalised statistic)
    threshold: float
    noise_var: float            # sigma_hat^2 per real component
    bin_width_hz: float
    n_bins: int
    n_cells: int
    pfa: float
    n0: int                     # record index of the snapshot's first sample
    if_hz: float
    inverted: bool
    grid: np.ndarray | None = None   # Lambda[bin, cell] if keep_grid

    def channel_init(self) -> dict:
        """Keyword arguments for ``GoldenCorrelator`` started at sample ``n0``."""
        s = -1.0 if self.inverted else 1.0
        return {"prn": self.prn, "carrier_freq_hz": self.if_hz + s * self.doppler_hz,
                "code_freq_hz": CHIP_RATE_HZ * (1 + self.doppler_hz / L1_HZ),
                "code_phase_chips": float(self.code_phase_chips), "n_start": self.n0}


def acquire(x, fs_hz: float, prn: int, if_hz: float, inverted: bool = False,
            n_coherent: int = 1, n_noncoherent: int = 5, max_doppler_hz: float = 7000.0,
            bin_width_hz: float | None = None, pfa: float = 1e-3, n0: int = 0,
            keep_grid: bool = False) -> AcquisitionResult:
    """Search ``prn`` in the snapshot ``x`` (needs ``n_coherent * n_noncoherent`` ms)."""
    prn = check_prn(prn)
    fs = float(fs_hz)
    if not (math.isfinite(fs) and fs > 0):
        raise ValueError(f"fs_hz must be > 0, not {fs_hz!r}")
    N = int(round(fs * CODE_PERIOD_S))
    if abs(N - fs * CODE_PERIOD_S) > 1e-6:
        raise ValueError(f"acquisition needs a whole number of samples per 1 ms code period, "
                         f"not fs * 1 ms = {fs * CODE_PERIOD_S!r}")
    for name, v in (("n_coherent", n_coherent), ("n_noncoherent", n_noncoherent)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be an integer >= 1, not {v!r}")
    T = n_coherent * CODE_PERIOD_S
    bw = 2.0 / (3.0 * T) if bin_width_hz is None else float(bin_width_hz)
    if not (math.isfinite(bw) and bw > 0):
        raise ValueError(f"bin_width_hz must be > 0, not {bin_width_hz!r}")
    x = _samples(x)
    need = N * n_coherent * n_noncoherent
    if x.size < need:
        raise ValueError(f"the snapshot needs {need} samples ({n_coherent} x {n_noncoherent} ms), "
                         f"not {x.size}")
    x = x[:need]
    nb = int(math.floor(max_doppler_hz / bw))
    dopplers = bw * np.arange(-nb, nb + 1)
    code = ca_code_levels(prn).astype(np.float64)
    rep = code[(np.floor(np.arange(N) * CHIP_RATE_HZ / fs)).astype(np.int64) % CODE_LENGTH]
    Cf = np.fft.fft(rep)
    n = np.arange(need)
    s = -1.0 if inverted else 1.0
    S = np.zeros((dopplers.size, N))
    for i, fd in enumerate(dopplers):
        y = (x * np.exp(-2j * np.pi * ((if_hz + s * fd) / fs) * n)).reshape(-1, N)
        # sum_n y[n] c[n + m] = conj( sum_n c[n + m] conj(y[n]) ) = conj(ifft(C conj(Yf)))
        Yp = np.fft.ifft(Cf[None, :] * np.conj(np.fft.fft(y, axis=1)), axis=1)
        Yk = Yp.reshape(n_noncoherent, n_coherent, N).sum(axis=1)
        S[i] = np.sum(Yk.real ** 2 + Yk.imag ** 2, axis=0)
    K = n_noncoherent
    var = float(S.mean() / (2 * K))
    if not (math.isfinite(var) and var > 0):
        raise ValueError(f"the snapshot has no noise power to normalise by (mean cell {var!r})")
    lam = S / var
    th = threshold(pfa, lam.size, K)
    b, m = np.unravel_index(int(np.argmax(lam)), lam.shape)
    peak = float(lam[b, m])
    return AcquisitionResult(prn, peak > th, float(dopplers[b]), float(m * CHIP_RATE_HZ / fs),
                             int(m), peak, th, var, bw, dopplers.size, lam.size, float(pfa),
                             int(n0), float(if_hz), bool(inverted), lam if keep_grid else None)


def refine_doppler(x, fs_hz: float, prn: int, if_hz: float, doppler_hz: float,
                   code_phase_chips: float, inverted: bool = False, n_ms: int = 20,
                   pad: int = 16) -> float:
    """A finer Doppler than the acquisition bin, for the hand-over to a PLL.

    With the code wiped at the acquired code phase and the carrier at the acquired Doppler,
    the 1 ms prompt sums ``P_k`` carry the residual ``s (f_true - doppler_hz)``; squaring
    them removes the data bits (BPSK) and doubles it. The peak of the ``pad``-times
    zero-padded FFT of ``P_k^2`` over ``n_ms`` ms gives the residual (unambiguous within
    +-250 Hz, so the coarse bins must be <= 500 Hz wide; resolution ``1000 / (2 pad n_ms)``
    Hz). Returns the refined Doppler (Hz)."""
    prn = check_prn(prn)
    fs = float(fs_hz)
    N = int(round(fs * CODE_PERIOD_S))
    if isinstance(n_ms, bool) or not isinstance(n_ms, (int, np.integer)) or n_ms < 2:
        raise ValueError(f"n_ms (refinement length, ms) must be an integer >= 2, not {n_ms!r}")
    x = _samples(x)
    if x.size < n_ms * N:
        raise ValueError(f"Doppler refinement needs {n_ms * N} samples ({n_ms} ms), not {x.size}")
    s = -1.0 if inverted else 1.0
    n = np.arange(n_ms * N)
    code = ca_code_levels(prn).astype(np.float64)
    chips = np.floor(code_phase_chips + n * CHIP_RATE_HZ / fs).astype(np.int64) % CODE_LENGTH
    y = x[:n.size] * code[chips] * np.exp(-2j * np.pi * ((if_hz + s * doppler_hz) / fs) * n)
    p = y.reshape(n_ms, N).sum(axis=1)
    F = np.abs(np.fft.fft(p * p, pad * n_ms))
    fr = np.fft.fftfreq(pad * n_ms, CODE_PERIOD_S)
    return float(doppler_hz + s * fr[int(np.argmax(F))] / 2)
