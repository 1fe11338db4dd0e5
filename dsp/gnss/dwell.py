"""Sequential acquisition of one GPS L1 C/A PRN on a flowing stream: the dwell extends
(more non-coherent sums, then longer coherent time across data-bit edges) until the PRN is
detected or a stated limit of signal is reached, at a stated false-alarm probability per
search.

Correlation
-----------
The input is zero-IF complex samples at ``fs_d`` with a whole number ``N`` of samples per
1 ms (:class:`Baseband` makes them from a recording: :func:`dsp.gnss.search_frontend.to_baseband`,
2.046 MS/s by default, cells half a chip apart). For every 1 ms period ``k`` and every
*coarse* Doppler ``f_b`` (multiples of :data:`COARSE_HZ` = 500 Hz within
``+-max_doppler_hz``) the circular correlation with the sampled replica is taken by FFT::

    c_b[k, m] = sum_n y[kN + n] exp(-j 2 pi f_b (kN + n) / fs_d) c_r[(n + m) mod N]

(the carrier phase runs continuously across periods; a shift by 1 kHz is a shift of the
1 ms FFT by one bin, so only the input and its 500 Hz-shifted copy are transformed).

A dwell of ``T`` ms coherent sums the ``c_b[k]`` of ``T`` consecutive periods with the
phase ramp of a *fine* Doppler offset ``delta`` (a DFT across the ``T`` periods at
``delta`` on the ``1000 / P`` Hz grid within ``[-250, 250)`` Hz, ``P`` the smallest power
of two >= ``1.5 T``: bins at most ``2 / (3 T)`` wide); for ``T = 1`` the coarse bins are
the bins. ``K`` coherent sums are added in power, each shifted by the code drift
of its coarse Doppler (``f_b / 1540`` chips/s, whole cells), so the cells stay on the code
phase at the dwell's start::

    S[b, delta, m] = sum_{j < K} |Z_j[b, delta, m + drift_j]|^2

Data bits
---------
The 50 bit/s data flips the sign on a 20 ms grid of code epochs whose phase the receiver
does not know. A coherent sum of ``T > 1`` ms is tried at ``A`` start offsets
(bit-edge hypotheses) ``0, s, 2s, .. < T`` ms, ``s = ceil(T / 4)``. When ``T`` divides 20
(the default dwells' ``T`` all do) every edge sits at the same offset modulo ``T``, so one
of the offsets puts every bit edge within ``s / 2`` ms of a sum's boundary. A transition
at ``u`` ms from a boundary leaves ``1 - 2u / T`` of the amplitude.

Statistic, threshold, false alarms
----------------------------------
Under noise only each ``Z`` is circular complex Gaussian with the same variance ``sigma^2``
per real component (every fine bin of the DFT included), so
``Lambda = S / sigma^2`` is chi-square with ``2K`` degrees of freedom;
``sigma^2 = mean(S) / (2K)`` over all cells of the test. A *test* is one (dwell, look
``K``, bit-edge offset): the maximum ``Lambda`` over its ``N_cells`` Doppler x code cells
against the threshold :func:`dsp.gnss.acquisition.threshold` for ``pfa / N_tests``, where
``N_tests`` is every test the schedule can make (its looks x offsets, all dwells within the
limit). By the union bound the probability that a search of an absent PRN reports a
detection is at most ``pfa`` whatever the stage it stops at (the looks of a dwell are
nested sums, positively correlated, and neighbouring cells are correlated: the true rate is
below ``pfa``; :attr:`SearchOutcome.p_min` lets a Monte Carlo measure it at any ``pfa``).

Schedule
--------
The dwells (:class:`Dwell`: ``T`` ms coherent, looks at ``K_1 < K_2 < ..`` sums) run one
after the other on consecutive, disjoint stretches of the stream: the later, longer dwells
use later signal. :data:`DEFAULT_SCHEDULE` is 1 ms x 5/10, 5 ms x 4/8, 10 ms x 5/10/20,
20 ms x 6/11: 498 ms of signal, within :data:`DEFAULT_LIMIT_MS` = 500 ms. The search reports
the first test that exceeds its threshold (its dwell's best offset at that look); the time
to detect is the signal consumed up to that look's end.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from .acquisition import threshold
from .ca_code import CHIP_RATE_HZ, CODE_LENGTH, CODE_PERIOD_S, L1_HZ, ca_code_levels, check_prn

#: Coarse Doppler step (Hz): the 1 ms correlations are taken every 500 Hz.
COARSE_HZ = 500.0
#: Signal the default search may consume (ms).
DEFAULT_LIMIT_MS = 500
#: Longest coherent sum (ms): one data bit.
MAX_COHERENT_MS = 20


def _whole(name, v, lo, hi=None):
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo or \
            (hi is not None and v > hi):
        rng = f"in {lo}..{hi}" if hi is not None else f">= {lo}"
        raise ValueError(f"{name} must be a whole number {rng}, not {v!r}")
    return int(v)


@dataclass(frozen=True)
class Dwell:
    """``coherent_ms`` ms coherent, tested after ``looks[i]`` non-coherent sums (the sum
    keeps growing: the last look is the dwell's ``K``)."""

    coherent_ms: int
    looks: tuple

    def __post_init__(self):
        _whole("--coherent-ms", self.coherent_ms, 1, MAX_COHERENT_MS)
        lk = tuple(self.looks)
        for k in lk:
            _whole("--noncoherent", k, 1)
        if not lk or any(b <= a for a, b in zip(lk, lk[1:])):
            raise ValueError(f"a dwell's looks must be increasing non-coherent counts, "
                             f"not {lk!r}")
        object.__setattr__(self, "looks", lk)

    @property
    def noncoherent(self) -> int:
        return self.looks[-1]

    @property
    def edge_step_ms(self) -> int:
        return max(1, math.ceil(self.coherent_ms / 4))

    def alignments(self, data_bits: bool = True) -> tuple:
        """The bit-edge hypotheses (start offsets, ms)."""
        if not data_bits or self.coherent_ms == 1:
            return (0,)
        return tuple(range(0, self.coherent_ms, self.edge_step_ms))

    def span_ms(self, data_bits: bool = True) -> int:
        """Signal the whole dwell consumes (ms)."""
        return max(self.alignments(data_bits)) + self.coherent_ms * self.noncoherent

    def look_end_ms(self, k: int, data_bits: bool = True) -> int:
        """Signal consumed when the look at ``k`` sums is made (ms from the dwell's start)."""
        return max(self.alignments(data_bits)) + self.coherent_ms * k

    @property
    def fft_len(self) -> int:
        T = self.coherent_ms
        return 1 if T == 1 else 1 << math.ceil(math.log2(1.5 * T))

    @property
    def bin_width_hz(self) -> float:
        return COARSE_HZ if self.coherent_ms == 1 else 1000.0 / self.fft_len

    def __str__(self) -> str:
        return f"{self.coherent_ms} ms x {'/'.join(str(k) for k in self.looks)}"


DEFAULT_SCHEDULE = (Dwell(1, (5, 10)), Dwell(5, (4, 8)), Dwell(10, (5, 10, 20)),
                    Dwell(20, (6, 11)))


def fixed_schedule(coherent_ms: int, noncoherent: int) -> tuple:
    """One dwell of ``coherent_ms`` x ``noncoherent``, one look."""
    return (Dwell(coherent_ms, (noncoherent,)),)


def schedule_within(schedule, limit_ms: int, data_bits: bool = True) -> tuple:
    """The dwells of ``schedule`` that fit, one after the other, in ``limit_ms`` ms of
    signal (ValueError naming ``--acq-limit-ms`` if not even the first does)."""
    sched = tuple(schedule)
    if not sched or any(not isinstance(d, Dwell) for d in sched):
        raise ValueError("schedule must be a non-empty sequence of Dwell")
    _whole("--acq-limit-ms", limit_ms, 1)
    out, used = [], 0
    for d in sched:
        if used + d.span_ms(data_bits) > limit_ms:
            break
        out.append(d)
        used += d.span_ms(data_bits)
    if not out:
        raise ValueError(f"--acq-limit-ms {limit_ms} is shorter than the first dwell "
                         f"({sched[0]}: {sched[0].span_ms(data_bits)} ms of signal)")
    return tuple(out)


@dataclass
class SearchOutcome:
    """A sequential search's outcome. ``doppler_hz`` and ``code_phase_chips`` are at the
    start of the detecting dwell (sample ``start_ms`` ms into the stream); ``t_detect_ms``
    the signal consumed when it decided; ``metric`` peak / threshold of the deciding test;
    ``p_min`` = ``N_tests x`` the smallest per-test false-alarm p-value seen (the search
    would have stopped at a false alarm for any ``pfa > p_min``: a Monte Carlo on noise
    measures the rate at every ``pfa`` from it); ``looks`` the tests made, in order."""

    prn: int
    detected: bool
    doppler_hz: float
    code_phase_chips: float
    stage: int
    dwell: str
    coherent_ms: int
    noncoherent: int
    alignment_ms: int
    start_ms: int
    t_detect_ms: int
    metric: float
    peak: float
    threshold: float
    bin_width_hz: float
    pfa: float
    n_tests: int
    p_min: float
    looks: list = field(default_factory=list)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def _code_fft(prn, fs_d, N):
    code = ca_code_levels(prn).astype(np.float64)
    rep = code[np.floor(np.arange(N) * CHIP_RATE_HZ / fs_d).astype(np.int64) % CODE_LENGTH]
    return np.conj(sfft.fft(rep)).astype(np.complex64)


def _dwell_looks(read_ms, start, fs_d, prn, dwell, data_bits, max_doppler_hz):
    """The tests of one dwell starting at ms ``start`` of the stream, look by look: each
    look reads and correlates only the periods it adds. Yields, per look, for each bit-edge
    offset, (max S, its Doppler, its code cell, sum of S over the cells) and the number of
    cells."""
    N = int(round(fs_d * CODE_PERIOD_S))
    T, P = dwell.coherent_ms, dwell.fft_len
    al = dwell.alignments(data_bits)
    amax = max(al)
    C = _code_fft(prn, fs_d, N)
    nq = int(math.floor(max_doppler_hz / COARSE_HZ))
    fine = np.fft.fftfreq(P, CODE_PERIOD_S) if P > 1 else np.zeros(1)
    fine = np.sort(fine[(fine >= -COARSE_HZ / 2) & (fine < COARSE_HZ / 2)])
    # the fine bins' DFT across the T periods of a coherent sum (a matrix product: only
    # the bins kept, no zero padding)
    dft = np.exp(-2j * np.pi * np.outer(fine, np.arange(T)) * CODE_PERIOD_S) \
        .astype(np.complex64)
    cells = (2 * nq + 1) * fine.size * N
    cell_chips = CHIP_RATE_HZ / fs_d
    S = np.zeros((2 * nq + 1, len(al), fine.size, N))      # running non-coherent sums
    k_prev = 0
    for k in dwell.looks:
        m0, m1 = k_prev * T, k * T + amax                    # the periods this look adds
        W = m1 - m0
        y = np.asarray(read_ms(start + m0, start + m1), np.complex64)
        if y.size < W * N:
            raise ValueError(f"the stream ends before the dwell {dwell} "
                             f"({start + m1} ms needed)")
        n = np.arange(W * N)
        X0 = sfft.fft(y.reshape(W, N), axis=1)
        # the same, 500 Hz lower (exp(-j 2 pi 500 n / fs_d) = exp(-j pi n / N)), the phase
        # referred to the dwell's start
        X5 = sfft.fft((y * np.exp(-1j * np.pi * (n + m0 * N) / N).astype(np.complex64))
                      .reshape(W, N), axis=1)
        best = np.full(len(al), -1.0)
        where = np.zeros((len(al), 2))
        tot = np.zeros(len(al))
        for iq, q in enumerate(range(-nq, nq + 1)):
            fb = q * COARSE_HZ
            X = X0 if q % 2 == 0 else X5
            kshift = (q // 2) if q % 2 == 0 else ((q - 1) // 2)
            # sum_n y[n] c_r[n - m]: the correlation at code cell -m, carrier phase kept
            c = sfft.ifft(np.roll(X, -kshift, axis=1) * C[None, :], axis=1)
            drift = fb / (L1_HZ / CHIP_RATE_HZ) / cell_chips * CODE_PERIOD_S  # cells / ms
            for ai, a in enumerate(al):
                blk = c[a:a + (k - k_prev) * T].reshape(k - k_prev, T, N)
                # (F, blocks, N); tensordot: one matrix product
                Z = np.tensordot(dft, blk, axes=([1], [1])) if T > 1 else blk[None, :, 0, :]
                pw = Z.real ** 2 + Z.imag ** 2
                # each block shifted by its code drift since the dwell's start
                sh = np.rint(drift * (a + T * np.arange(k_prev, k))).astype(np.int64)
                for v in np.unique(sh):
                    j = np.nonzero(sh == v)[0]
                    part = pw[:, j[0]:j[-1] + 1].sum(axis=1, dtype=np.float64)
                    S[iq, ai] += np.roll(part, int(v), axis=1) if v else part
                s = S[iq, ai]
                tot[ai] += float(s.sum())
                j = int(np.argmax(s))
                if s.flat[j] > best[ai]:
                    fi, m = np.unravel_index(j, s.shape)
                    best[ai] = float(s.flat[j])
                    where[ai] = (fb + fine[fi], (N - m) % N)
        k_prev = k
        yield best, where, tot, cells


def sequential_search(read_ms, fs_d: float, prn: int, schedule=DEFAULT_SCHEDULE,
                      limit_ms: int = DEFAULT_LIMIT_MS, pfa: float = 1e-3,
                      max_doppler_hz: float = 7000.0, data_bits: bool = True,
                      stop: bool = True, first: int = 0, last: int | None = None
                      ) -> SearchOutcome:
    """Search ``prn`` on a stream (module docstring).

    Parameters
    ----------
    read_ms : callable
        ``read_ms(k0, k1)`` -> zero-IF complex samples at ``fs_d`` of ms ``k0 .. k1 - 1`` of
        the stream (e.g. :meth:`Baseband.ms`); called once per dwell, in order.
    fs_d : float
        Its rate: a whole number of samples per 1 ms.
    schedule : sequence of Dwell
        Dwells in order; those that do not fit in ``limit_ms`` are not run.
    limit_ms : int
        Signal the search may consume (ms).
    pfa : float
        False-alarm probability of the whole search (an absent PRN reported).
    max_doppler_hz : float
        Doppler searched: coarse bins up to this, fine bins 250 Hz beyond.
    data_bits : bool
        The signal may carry 50 bit/s data (bit-edge hypotheses for ``T > 1``).
    stop : bool
        Stop at the first detection (False: run every test, for a noise Monte Carlo's
        ``p_min``).
    first, last : int
        Run only the dwells ``first .. last - 1`` of the schedule within the limit (default
        all), each at its place in the stream and with the threshold of the whole schedule:
        two calls that split the schedule make the tests of one search
        (:func:`dsp.gnss.search_sequential.sequential_search_all` changes the signal in
        between).
    """
    prn = check_prn(prn)
    if not (isinstance(pfa, (int, float)) and 0 < pfa < 1):
        raise ValueError(f"--pfa must be in (0, 1), not {pfa!r}")
    if not (isinstance(max_doppler_hz, (int, float)) and 0 < max_doppler_hz <= 50e3):
        raise ValueError(f"max_doppler_hz must be in (0, 50000] Hz, not {max_doppler_hz!r}")
    N = int(round(fs_d * CODE_PERIOD_S))
    if abs(N - fs_d * CODE_PERIOD_S) > 1e-6 * N:
        raise ValueError(f"the search rate {fs_d:g} S/s gives no whole number of samples "
                         f"per 1 ms")
    sched = schedule_within(schedule, limit_ms, data_bits)
    n_tests = sum(len(d.looks) * len(d.alignments(data_bits)) for d in sched)
    last = len(sched) if last is None else last
    if not (isinstance(first, int) and isinstance(last, int) and 0 <= first < last
            <= len(sched)):
        raise ValueError(f"first, last must pick dwells of the {len(sched)} within the limit, "
                         f"not {first!r}, {last!r}")
    from scipy import stats      # here, not at import: a command's refusals need no scipy.stats
    pt = pfa / n_tests
    start, out, p_min, looks = 0, None, math.inf, []
    for si, d in enumerate(sched[:last]):
        W = d.span_ms(data_bits)
        if si < first:
            start += W
            continue
        looks_it = _dwell_looks(read_ms, start, fs_d, prn, d, data_bits, max_doppler_hz)
        for k, (best, where, tot, cells) in zip(d.looks, looks_it):
            th = threshold(pt, cells, k)
            lam = best / (tot / cells / (2 * k))
            ai = int(np.argmax(lam / th))
            # each offset's p-value: P(max of its cells > the peak seen | noise)
            sf = stats.chi2.sf(lam, 2 * k)
            p = -np.expm1(cells * np.log1p(-np.minimum(sf, 1.0 - 1e-16)))
            p_min = min(p_min, float(np.min(p)) * n_tests)
            t_end = start + d.look_end_ms(k, data_bits)
            hit = bool(lam[ai] > th)
            looks.append({"stage": si, "noncoherent": k, "t_end_ms": t_end,
                          "metric": float(lam[ai] / th), "detected": hit})
            if hit and out is None:
                f, m = where[ai]
                out = SearchOutcome(prn, True, float(f), float(m * CHIP_RATE_HZ / fs_d), si,
                                    str(d), d.coherent_ms, k,
                                    int(d.alignments(data_bits)[ai]), start, t_end,
                                    float(lam[ai] / th), float(lam[ai]), float(th),
                                    d.bin_width_hz, float(pfa), n_tests, math.inf)
                if stop:
                    break
        start += W
        if out is not None and stop:
            break
    if out is None:
        ld = sched[last - 1]
        out = SearchOutcome(prn, False, math.nan, math.nan, last - 1, str(ld),
                            ld.coherent_ms, ld.noncoherent, 0, start - W,
                            start, looks[-1]["metric"], math.nan, math.nan,
                            ld.bin_width_hz, float(pfa), n_tests, math.inf)
    out.p_min = p_min
    out.looks = looks
    return out


class Baseband:
    """Zero-IF complex samples at the search rate, 1 ms at a time, from a reader of raw
    samples: :func:`dsp.gnss.search_frontend.to_baseband` (mixer referred to the recording's first
    sample, ``firwin`` low-pass, decimation by :func:`dsp.gnss.search_frontend.decimation`) on the
    requested stretch plus the filter's half length on each side, so a stretch equals the
    same samples of the whole record converted at once (in complex64 arithmetic: to
    ~1e-6 of :func:`~dsp.gnss.search_frontend.to_baseband`'s complex128)."""

    def __init__(self, read, n_samples: int, fs_hz: float, if_hz: float,
                 inverted: bool = False, min_rate_hz: float | None = None):
        from .search_frontend import MIN_RATE_HZ, decimation
        self.read, self.n_samples = read, int(n_samples)
        self.fs_hz, self.if_hz, self.inverted = float(fs_hz), float(if_hz), bool(inverted)
        self.N = int(round(fs_hz * CODE_PERIOD_S))
        if abs(self.N - fs_hz * CODE_PERIOD_S) > 1e-6 * self.N:
            raise ValueError(f"--fs-hz {fs_hz:g} gives no whole number of samples per 1 ms")
        self.D = decimation(fs_hz, MIN_RATE_HZ if min_rate_hz is None else min_rate_hz)
        self.fs_d = self.fs_hz / self.D

    def ms(self, k0: int, k1: int) -> np.ndarray:
        """Zero-IF samples at ``fs_d`` of ms ``k0 .. k1 - 1`` (short at the record's end)."""
        from scipy import signal as sps
        N, D = self.N, self.D
        pad = 8 * D if D > 1 else 0
        a = max(0, k0 * N - pad)
        b = min(self.n_samples, k1 * N + pad)
        if b <= k0 * N:
            return np.zeros(0, np.complex128)
        x = np.asarray(self.read(a, b - a))
        x = x.astype(np.complex64 if np.iscomplexobj(x) else np.float32)
        # the mixer exp(-j 2 pi f_IF n / fs), n from the record's first sample: one 1 ms
        # table times each period's start phase (no exp per sample)
        r = math.fmod(self.if_hz / self.fs_hz, 1.0)
        m0, m1 = a // N, -(-b // N)
        tab = np.exp(-2j * np.pi * r * np.arange(N))
        start = np.exp(-2j * np.pi * np.mod(r * N * np.arange(m0, m1, dtype=np.float64), 1.0))
        ph = (start[:, None] * tab[None, :]).astype(np.complex64).ravel()[a - m0 * N:
                                                                          b - m0 * N]
        y = x * ph
        if self.inverted:
            y = np.conj(y)
        i0 = k0 * N - a
        n_out = min(b, k1 * N) - k0 * N
        if D == 1:
            return y[i0:i0 + n_out]
        # centred FIR low-pass (search_frontend.to_baseband's), only the kept samples computed
        h = sps.firwin(16 * D + 1, 1.0 / D).astype(np.float32)
        z = sps.resample_poly(y, 1, D, window=h)      # z[i] at y[i D]; i0 is a multiple of D
        return z[i0 // D:i0 // D - (-n_out // D)]


def refine(x, fs_hz: float, prn: int, if_hz: float, inverted: bool, doppler_hz: float,
           code_phase_chips: float, bin_width_hz: float, n_ms: int) -> tuple:
    """Doppler and code phase of a detection, refined on ``n_ms`` ms of raw samples ``x``
    (real at ``if_hz`` or complex; the received code phase at ``x[0]`` is
    ``code_phase_chips`` within a search cell).

    Doppler: the 1 ms prompts at the detection's Doppler and code phase, squared (the data
    bits removed, the residual doubled), their 16-times zero-padded FFT's peak within
    +- ``bin_width_hz`` of the detection (the residual halved; :data:`COARSE_HZ` wide bins:
    of the peak and it +- 500 Hz those within the bin, the one with the most 1 ms prompt
    power, the squaring's ambiguity). Code phase: the 1 ms prompt power summed over the ``n_ms`` ms (replica at the refined code
    rate) on a 1/16-chip grid +-0.5 chip around the detection, the peak interpolated by a
    parabola through it and its neighbours. Returns ``(doppler_hz, code_phase_chips)`` at
    ``x[0]``."""
    fs = float(fs_hz)
    N = int(round(fs * CODE_PERIOD_S))
    x = np.asarray(x)
    x = x.astype(np.complex128 if np.iscomplexobj(x) else np.float64, copy=False)
    if x.size < n_ms * N:
        raise ValueError(f"the refinement needs {n_ms} ms of samples, not {x.size / N:.1f}")
    n = np.arange(n_ms * N)
    y = x[:n.size] * np.exp(-2j * np.pi * ((if_hz / fs) % 1.0) * n)     # zero IF
    if inverted:
        y = np.conj(y)
    code = ca_code_levels(check_prn(prn)).astype(np.float64)

    def wipe(f):
        return y * np.exp(-2j * np.pi * (f / fs) * n)

    def power(yw, f, cp):
        rate = CHIP_RATE_HZ * (1 + f / L1_HZ) / fs
        c = code[np.floor(cp + n * rate).astype(np.int64) % CODE_LENGTH]
        p = (yw * c).reshape(n_ms, N).sum(axis=1)
        return float(np.sum(p.real ** 2 + p.imag ** 2))

    # code phase first (1 ms power: insensitive to a Doppler error within the bin)
    yw = wipe(doppler_hz)
    grid = code_phase_chips + np.arange(-8, 9) / 16.0
    pw = np.array([power(yw, doppler_hz, c) for c in grid])
    i = int(np.clip(np.argmax(pw), 1, grid.size - 2))
    a, b, c = pw[i - 1], pw[i], pw[i + 1]
    den = a - 2 * b + c
    d = 0.5 * (a - c) / den if den < 0 else 0.0
    cp = float((grid[i] + np.clip(d, -0.5, 0.5) / 16.0) % CODE_LENGTH)
    # then the Doppler, from the squared prompts at that code phase
    pad = 16
    rate = CHIP_RATE_HZ * (1 + doppler_hz / L1_HZ) / fs
    p0 = (yw * code[np.floor(cp + n * rate).astype(np.int64) % CODE_LENGTH]) \
        .reshape(n_ms, N).sum(axis=1)
    F = np.abs(np.fft.fft(p0 * p0, pad * n_ms))
    half = np.fft.fftfreq(pad * n_ms, CODE_PERIOD_S) / 2
    ok = np.abs(half) <= min(bin_width_hz, COARSE_HZ / 2)
    f1 = doppler_hz + float(half[ok][int(np.argmax(F[ok]))])
    cands = [v for v in (f1, f1 - 500.0, f1 + 500.0) if abs(v - doppler_hz) <= bin_width_hz]
    f = cands[int(np.argmax([power(wipe(v), v, cp) for v in cands]))] \
        if len(cands) > 1 else f1
    return float(f), cp
