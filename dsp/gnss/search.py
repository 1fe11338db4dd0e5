"""Acquisition of every GPS L1 C/A PRN on a recording: dwell schedule, verification, refinement.

The search runs :func:`dsp.gnss.acquisition.acquire` (parallel code-phase FFT search, its
docstring gives the statistic) PRN by PRN over a schedule of dwells, each detection checked
by a second, independent dwell before it is reported, then refined at the full sample rate.
Only the first ``max(2 x longest dwell, refine_ms)`` ms of the recording are read, after
the front end of :mod:`dsp.gnss.search_frontend` (periodic interference removed, mixed to
zero IF, narrowband interference excised, filtered and decimated for the dwells).

Dwells and the bit edge
-----------------------
A :class:`Stage` is ``n_coherent`` ms summed coherently, ``n_noncoherent`` such sums added
in power, tried at each start offset of ``alignments_ms``: a data-bit edge (every 20 ms, on a
code epoch) inside a coherent sum cancels part of it, and one of the offsets puts the sums'
boundaries within ``max gap / 2`` ms of the edges. Doppler bins are ``min(2 / (3 T), 500)``
Hz wide (:func:`dsp.gnss.acquisition.refine_doppler` needs <= 500 Hz).
:data:`DEFAULT_STAGES` is 1 ms x 10, then 5 ms x 6 at offsets 0 / 2 ms;
:data:`DEEP_STAGES` adds 10 ms x 4 at offsets 0 / 3 / 6 ms. A PRN not detected at one stage
is searched at the next (the dwell extends) until it is detected or the schedule (its stated
limit) ends. A stage runs only if the recording holds it twice (dwell and verification).
All PRNs go through the first stage first; the satellites it finds are then subtracted from
the samples (:func:`cancel`) before the longer dwells, whose sensitivity would otherwise reach
their cross-correlation with the other codes.

False alarms and the threshold
------------------------------
Under noise only, a cell's normalised statistic ``Lambda`` is chi-square with ``2K`` degrees
of freedom (``K = n_noncoherent``); ``acquire`` sets the threshold for a per-search
false-alarm probability over all its cells. Here ``pfa`` is the false-alarm probability of
one PRN's whole first-dwell schedule: each of the ``S`` stages that run and each of its
``A`` offsets gets ``pfa / (S A)`` (union bound), so a PRN absent from noise passes a first
dwell with probability at most ``pfa``. Real recordings break "noise only" (interference,
other satellites' cross-correlation), which is what the verification is for.

Verification
------------
A first-dwell detection at Doppler ``f`` and code phase ``tau`` is reported only if the same
stage, run on the next, disjoint window of the recording (``Dt`` later), exceeds a threshold
in the cells within one Doppler bin of ``f`` and one cell of ``tau + f Dt / 1540`` chips (the
code drift in between), the threshold set for ``verify_pfa`` (1e-3) over those few cells and
the offsets, and above every other cell of that grid. Noise in the two windows is
independent, so an absent PRN is reported with probability at most ``pfa x verify_pfa``;
the second condition holds whatever the cells' distribution (interference, cross-correlation)
as long as no cell is favoured: an absent PRN's local cells are the grid's maximum with
probability ``n_local / N_cells`` (about 1e-4). Last, a detection at a stronger one's Doppler plus
a multiple of 1 kHz and :data:`XCORR_MARGIN_DB` or more below it is refused as its
cross-correlation (:func:`cross_correlation_suspects`).

Refinement and C/N0
-------------------
At the full sample rate (zero IF, no filter): the Doppler by
:func:`dsp.gnss.acquisition.refine_doppler` over up to ``refine_ms`` ms, then of it and
it +- 500 Hz (the squaring's ambiguity), within one bin of the dwell's, the one with the most
1 ms prompt power; the code phase where early minus late (1 chip apart) of the
1 ms non-coherent amplitude over 40 ms, on a 0.1-chip grid around the dwell's cell, crosses
zero; then 1 ms prompt sums from code epoch to code epoch with a replica at that code phase
(or at the grid's peak if that has more power) and code rate, and C/N0 by
:func:`dsp.gnss.cn0.cn0_m2m4` on 20 ms blocks averaged
(:func:`cn0_blocks`; insensitive to data bits and carrier phase).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from .acquisition import acquire, refine_doppler, threshold
from .ca_code import CHIP_RATE_HZ, CODE_LENGTH, CODE_PERIOD_S, L1_HZ, ca_code_levels, check_prn
from .cn0 import cn0_m2m4
from .search_frontend import EXCISE_DB, MIN_RATE_HZ, PERIODIC_RATIO, decimation, front_end, \
    to_baseband

#: Code-phase refinement: grid step (chips) and recording used (ms).
CODE_GRID_CHIPS, CODE_MS = 0.1, 40
#: C/N0: M2M4 blocks (ms). Short blocks follow a slowly changing amplitude (the code
#: drifting across a sample grid commensurate with the chip rate); the price: an M2M4 on
#: 20 prompts reads +0.6-0.9 dB high, 0.9-1.3 dB rms (Monte Carlo, 35-50 dB-Hz, 70 ms).
CN0_BLOCK_MS = 20
#: A detection this far (dB) below a stronger one at its Doppler + k kHz is refused as its
#: cross-correlation (C/A Gold codes: worst 1 ms cross-correlation -23.9 dB).
XCORR_MARGIN_DB = 15.0
#: False-alarm probability of a verification dwell over its cells (one bin / one cell
#: around the first detection, predicted drift applied).
VERIFY_PFA = 1e-3


@dataclass(frozen=True)
class Stage:
    """One dwell: ``n_coherent`` ms coherent x ``n_noncoherent`` sums, at each start offset
    (ms) of ``alignments_ms``."""

    n_coherent: int
    n_noncoherent: int
    alignments_ms: tuple = (0,)

    def __post_init__(self):
        for name in ("n_coherent", "n_noncoherent"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"stage {name} must be an integer >= 1, not {v!r}")
        if self.n_coherent > 20:
            raise ValueError(f"stage n_coherent must be <= 20 ms (one data bit), "
                             f"not {self.n_coherent}")
        a = tuple(self.alignments_ms)
        if not a or any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0
                        for v in a):
            raise ValueError(f"stage alignments_ms must be integers >= 0 ms, not {a!r}")

    @property
    def span_ms(self) -> int:
        """Recording length one dwell needs (ms)."""
        return max(self.alignments_ms) + self.n_coherent * self.n_noncoherent

    @property
    def bin_width_hz(self) -> float:
        return min(2.0 / (3.0 * self.n_coherent * CODE_PERIOD_S), 500.0)

    def __str__(self) -> str:
        return f"{self.n_coherent}ms x {self.n_noncoherent} @ {list(self.alignments_ms)} ms"

    @classmethod
    def parse(cls, text: str) -> "Stage":
        """``TxK`` or ``TxK@a/b/c`` (ms, sums, offsets in ms), e.g. ``10x4@0/3/6``."""
        try:
            tk, _, al = str(text).partition("@")
            t, k = tk.split("x")
            offs = tuple(int(v) for v in al.split("/")) if al else (0,)
            return cls(int(t), int(k), offs)
        except ValueError as e:
            if str(e).startswith("stage"):
                raise
            raise ValueError(f"--stages entries must be TxK or TxK@a/b (coherent ms x sums @ "
                             f"offsets ms), not {text!r}") from None


DEFAULT_STAGES = (Stage(1, 10), Stage(5, 6, (0, 2)))
#: The deep schedule: the default, then 10 ms coherent (ms offsets 0 / 3 / 6).
DEEP_STAGES = DEFAULT_STAGES + (Stage(10, 4, (0, 3, 6)),)


@dataclass
class Detection:
    """A satellite found. Doppler (Hz) and code phase (chips, at the recording's first
    sample, ``[0, 1023)``) refined at the full rate; ``metric`` = first-dwell peak /
    threshold; ``dwell_*`` / ``verify_*`` the two dwells' raw results (:func:`search_all`;
    the sequential search of :mod:`dsp.gnss.search_sequential` has no verification dwell:
    ``verify_metric`` None, ``stage_text`` its deciding look and when it was made)."""

    prn: int
    doppler_hz: float
    code_phase_chips: float
    cn0_dbhz: float
    metric: float
    stage: int
    stage_text: str
    dwell_doppler_hz: float
    dwell_code_phase_chips: float
    dwell_peak: float
    dwell_threshold: float
    verify_metric: float | None
    alignment_ms: int
    bin_width_hz: float

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class SearchReport:
    """The search's outcome: verified detections (by PRN), first-dwell detections the
    verification refused, the stages run / skipped, the front end, the false-alarm budget."""

    detections: list
    rejected: list
    stages_run: list
    stages_skipped: list
    fs_hz: float
    decimation: int
    pfa: float
    max_doppler_hz: float
    prns: list
    n_samples: int
    excised_hz: list = field(default_factory=list)
    periodic_ratio: float | None = None

    def as_dict(self) -> dict:
        return {"detections": [d.as_dict() for d in self.detections], "rejected": self.rejected,
                "stages_run": self.stages_run, "stages_skipped": self.stages_skipped,
                "fs_hz": self.fs_hz, "decimation": self.decimation,
                "search_rate_hz": self.fs_hz / self.decimation, "pfa_per_prn": self.pfa,
                "max_doppler_hz": self.max_doppler_hz, "prns": self.prns,
                "n_samples": self.n_samples, "excised_hz": self.excised_hz,
                "periodic_removed_ratio": self.periodic_ratio}


def _check_stages(stages):
    st = tuple(stages)
    if not st or any(not isinstance(s, Stage) for s in st):
        raise ValueError("stages must be a non-empty sequence of Stage")
    return st


def _dwell(xb, fs_d, prn, stage, pfa_each, max_doppler_hz):
    """The best (by peak / threshold) of a stage's offsets on the window ``xb``."""
    n = int(round(fs_d * CODE_PERIOD_S))
    best = None
    for a in stage.alignments_ms:
        r = acquire(xb[a * n:], fs_d, prn, 0.0, n_coherent=stage.n_coherent,
                    n_noncoherent=stage.n_noncoherent, max_doppler_hz=max_doppler_hz,
                    bin_width_hz=stage.bin_width_hz, pfa=pfa_each)
        if best is None or r.peak / r.threshold > best[0].peak / best[0].threshold:
            best = (r, a)
    return best


def _verify(xb, fs_d, prn, stage, doppler_hz, code_phase_chips, pfa_v, max_doppler_hz):
    """The second dwell: at some offset, the largest ``Lambda`` of the cells within one
    Doppler bin and one cell of (``doppler_hz``, ``code_phase_chips``) must exceed the
    threshold for ``pfa_v`` over those cells and offsets *and* every other cell of that
    grid. Returns (passed, best local Lambda / threshold, its Doppler, its code phase)."""
    n = int(round(fs_d * CODE_PERIOD_S))
    bw = stage.bin_width_hz
    nb = int(math.floor(max_doppler_hz / bw))
    dop = bw * np.arange(-nb, nb + 1)
    bins = np.nonzero(np.abs(dop - doppler_hz) <= 1.01 * bw)[0]
    m0 = int(round(code_phase_chips * fs_d / CHIP_RATE_HZ))
    cells = (m0 + np.arange(-1, 2)) % n
    th = threshold(pfa_v / len(stage.alignments_ms), bins.size * cells.size,
                   stage.n_noncoherent)
    best = (False, -1.0, 0.0, 0.0)
    for a in stage.alignments_ms:
        grid = acquire(xb[a * n:], fs_d, prn, 0.0, n_coherent=stage.n_coherent,
                       n_noncoherent=stage.n_noncoherent, max_doppler_hz=max_doppler_hz,
                       bin_width_hz=bw, keep_grid=True).grid
        g = grid[np.ix_(bins, cells)].copy()
        grid[np.ix_(bins, cells)] = -np.inf
        i, j = np.unravel_index(int(np.argmax(g)), g.shape)
        ok = g[i, j] > th and g[i, j] > grid.max()
        if (ok, g[i, j] / th) > best[:2]:
            best = (bool(ok), float(g[i, j] / th), float(dop[bins[i]]),
                    float(cells[j] * CHIP_RATE_HZ / fs_d))
    return best


@functools.lru_cache(maxsize=32)
def _levels(prn: int) -> np.ndarray:
    return ca_code_levels(prn).astype(np.float64)


def _code(fs, prn, f, cp, n):
    """Code at phase ``cp`` (chips at sample 0) and the code rate of Doppler ``f``, samples
    ``0 .. n - 1``."""
    code = _levels(prn)
    nn = np.arange(n)
    chips = np.floor(cp + nn * (CHIP_RATE_HZ * (1 + f / L1_HZ) / fs)).astype(np.int64)
    return code[chips % CODE_LENGTH]


def _replica(fs, prn, f, cp, n):
    """:func:`_code` times the carrier ``exp(j 2 pi f n / fs)``."""
    return _code(fs, prn, f, cp, n) * np.exp(2j * np.pi * (f / fs) * np.arange(n))


def _wipe(xf, fs, f, n):
    """The first ``n`` samples with the carrier at ``f`` wiped off."""
    return xf[:n] * np.exp(-2j * np.pi * (f / fs) * np.arange(n))


def _epoch(fs, f, cp):
    """Index of the first sample at or after the first code epoch (chip phase a multiple of
    1023) of a code at phase ``cp`` with the code rate of Doppler ``f``."""
    rate = CHIP_RATE_HZ * (1 + f / L1_HZ) / fs
    return int(math.ceil((CODE_LENGTH - cp % CODE_LENGTH) / rate))


def _prompts(y, fs, prn, f, cp, n_ms, epochs=False):
    """1 ms prompt sums over up to ``n_ms`` ms of carrier-wiped samples ``y``
    (:func:`_wipe`) against :func:`_code`; with ``epochs`` the sums start at the first code
    epoch, so data-bit edges fall between them."""
    N = int(round(fs * CODE_PERIOD_S))
    e = _epoch(fs, f, cp) if epochs else 0
    n_ms = min(n_ms, (y.size - e) // N)
    z = y[e:e + n_ms * N] * _code(fs, prn, f, cp, e + n_ms * N)[e:]
    return z.reshape(n_ms, N).sum(axis=1)


def refine_detection(xf, fs, prn, fd, cp, cell_chips, refine_ms, bin_width_hz):
    """Full-rate Doppler, code phase and C/N0 of a detection at Doppler ``fd`` and code
    phase ``cp`` (chips at ``xf[0]``) on zero-IF samples ``xf`` (module docstring):
    ``(doppler_hz, code_phase_chips, cn0_dbhz)``."""
    N = int(round(fs * CODE_PERIOD_S))
    n_ms = min(refine_ms, xf.size // N)
    f = refine_doppler(xf, fs, prn, 0.0, fd, cp, n_ms=n_ms) if n_ms >= 2 else fd
    # the squaring leaves a 500 Hz ambiguity: keep the candidate with the most 1 ms power
    cands = [c for c in (f, f - 500.0, f + 500.0) if abs(c - fd) <= bin_width_hz] or [fd]
    pw = [np.sum(np.abs(_prompts(_wipe(xf, fs, c, n_ms * N), fs, prn, c, cp, n_ms)) ** 2)
          for c in cands]
    f = cands[int(np.argmax(pw))]
    # code phase: the zero of early - late (1 chip apart) of the 1 ms non-coherent amplitude
    n_c = min(n_ms, CODE_MS)
    h = int(round(0.5 / CODE_GRID_CHIPS))
    k = int(math.ceil(cell_chips / CODE_GRID_CHIPS))
    grid = cp + CODE_GRID_CHIPS * np.arange(-k - h, k + h + 1)
    y = _wipe(xf, fs, f, n_ms * N)
    amp = np.sqrt([np.sum(np.abs(_prompts(y, fs, prn, f, t, n_c)) ** 2) for t in grid])
    el = amp[:-2 * h] - amp[2 * h:]             # early - late at grid[h:-h]
    mid = grid[h:-h]
    i = int(np.argmax(amp[h:-h]))
    cp_f = mid[i]
    up = np.nonzero((el[:-1] <= 0) & (el[1:] > 0))[0]     # early - late crosses zero
    if up.size:
        j = int(up[np.argmin(np.abs(up - i))])
        cp_f = mid[j] + CODE_GRID_CHIPS * (-el[j]) / (el[j + 1] - el[j])
    cp_f = float(cp_f % CODE_LENGTH)
    # C/N0 at the early-late phase or at the grid's peak, whichever has more power: with a
    # sample rate commensurate with the chip rate the correlation is flat over a sample and
    # the early-late zero may sit anywhere on that flat top, or just off it
    cp_c = cp_f
    if np.sum(np.abs(_prompts(y, fs, prn, f, cp_f, n_c)) ** 2) < amp[h + i] ** 2:
        cp_c = float(mid[i] % CODE_LENGTH)
    p = _prompts(y, fs, prn, f, cp_c, n_ms, epochs=True)
    return f, cp_f, cn0_blocks(p)


def cn0_blocks(p, m: int = CN0_BLOCK_MS) -> float:
    """C/N0 (dB-Hz) of 1 ms prompts: :func:`dsp.gnss.cn0.cn0_m2m4` on blocks of ``m`` ms,
    averaged in linear units (a slow amplitude change, such as the code drifting across
    the sample grid, is not taken for noise); fewer than ``2 m`` prompts: one block."""
    k = max(1, p.size // m)
    blocks = p[:k * m].reshape(k, -1) if k > 1 else p[None, :]
    v = 10.0 ** (np.asarray(cn0_m2m4(blocks, CODE_PERIOD_S)) / 10.0)
    mean = float(np.mean(v))
    return 10.0 * math.log10(mean) if mean > 0 else -math.inf


def cancel(x, fs_hz: float, prn: int, doppler_hz: float, code_phase_chips: float) -> None:
    """Subtract a satellite from zero-IF samples ``x`` in place: per code period (blocks
    from code epoch to code epoch, so a data-bit edge never falls inside one), the replica
    (:func:`_replica`) times that period's complex amplitude (prompt / samples), which
    carries the data bit and the carrier phase."""
    N = int(round(fs_hz * CODE_PERIOD_S))
    rep = _replica(fs_hz, prn, doppler_hz, code_phase_chips, x.size)
    e = _epoch(fs_hz, doppler_hz, code_phase_chips) % N
    edges = np.unique(np.concatenate([[0], np.arange(e, x.size, N)]))
    edges = edges[edges < x.size]
    num = np.add.reduceat(x * np.conj(rep), edges)
    cnt = np.diff(np.append(edges, x.size))
    x -= np.repeat(num / cnt, cnt) * rep


def cross_correlation_suspects(dets, margin_db: float = XCORR_MARGIN_DB) -> dict:
    """Detections that may be another, stronger satellite's cross-correlation: Doppler
    within one of their bins of a stronger detection's plus a multiple of 1 kHz, and C/N0
    at least ``margin_db`` below it. Returns ``{prn: stronger prn}``."""
    out = {}
    for d in dets:
        for s in dets:
            if s.prn == d.prn or not s.cn0_dbhz - d.cn0_dbhz >= margin_db:
                continue
            off = (d.doppler_hz - s.doppler_hz + 500.0) % 1000.0 - 500.0
            if abs(off) <= d.bin_width_hz:
                out[d.prn] = s.prn
                break
    return out


def check_search_args(prns, pfa, max_doppler_hz, refine_ms, fs_hz) -> tuple:
    """The shared arguments checked (ValueError naming the option): ``(prns, samples/ms)``."""
    prns = [check_prn(p) for p in prns]
    if not prns:
        raise ValueError("prns must name at least one PRN")
    if not (isinstance(pfa, (int, float)) and 0 < pfa < 1):
        raise ValueError(f"--pfa must be in (0, 1), not {pfa!r}")
    if not (isinstance(max_doppler_hz, (int, float)) and 0 < max_doppler_hz <= 50e3):
        raise ValueError(f"--max-doppler-hz must be in (0, 50000] Hz, not {max_doppler_hz!r}")
    if isinstance(refine_ms, bool) or not isinstance(refine_ms, (int, np.integer)) \
            or refine_ms < 2:
        raise ValueError(f"refine_ms must be an integer >= 2 (ms), not {refine_ms!r}")
    N = int(round(fs_hz * CODE_PERIOD_S))
    if abs(N - fs_hz * CODE_PERIOD_S) > 1e-6 * N:
        raise ValueError(f"--fs-hz {fs_hz:g} gives no whole number of samples per 1 ms")
    return prns, N


def two_pass_search(prns, xf, fs_hz: float, need_ms: int, D: int, first, later, rej: list
                    ) -> list:
    """The two passes (module docstring) on full-rate zero-IF ``xf``: ``first(prn, xb)``
    for every PRN, then, the satellites found cancelled from ``xf`` in place, ``later(prn,
    xb)`` (None: no pass 2) for the rest; ``xb``: ``need_ms`` ms decimated by ``D``; each
    gives a :class:`Detection` or None. Cross-correlation suspects go to ``rej``; returns
    the other detections by PRN."""
    N = int(round(fs_hz * CODE_PERIOD_S))
    dets = []
    xb = to_baseband(xf[:need_ms * N], fs_hz, 0.0, False, D)
    for prn in prns:
        d = first(prn, xb)
        if d is not None:
            dets.append(d)
    rest = [p for p in prns if p not in {d.prn for d in dets}]
    if later is not None and rest:
        for d in dets:
            cancel(xf, fs_hz, d.prn, d.doppler_hz, d.code_phase_chips)
        xb = to_baseband(xf[:need_ms * N], fs_hz, 0.0, False, D)
        for prn in rest:
            d = later(prn, xb)
            if d is not None:
                dets.append(d)
    xc = cross_correlation_suspects(dets)
    for d in [d for d in dets if d.prn in xc]:
        dets.remove(d)
        rej.append({"prn": d.prn, "stage": d.stage, "doppler_hz": d.doppler_hz,
                    "code_phase_chips": d.code_phase_chips, "metric": d.metric,
                    "cn0_dbhz": d.cn0_dbhz, "cross_correlation_of": xc[d.prn]})
    dets.sort(key=lambda d: d.prn)
    return dets


def search_all(read, n_samples: int, fs_hz: float, if_hz: float, inverted: bool = False,
               prns=range(1, 33), pfa: float = 1e-3, max_doppler_hz: float = 5000.0,
               stages=DEFAULT_STAGES, min_rate_hz: float = MIN_RATE_HZ,
               refine_ms: int = 100, excise_db: float | None = EXCISE_DB,
               verify_pfa: float = VERIFY_PFA) -> SearchReport:
    """Search every PRN of ``prns`` on a recording (module docstring).

    Parameters
    ----------
    read : callable
        ``read(n0, n)`` -> samples ``n0 .. n0 + n - 1`` (float real at ``if_hz``, or complex);
        e.g. :meth:`cosim.gnss.files.SampleFile.read`. Only the windows the stages need and
        ``refine_ms`` ms are read.
    n_samples : int
        Samples in the recording.
    fs_hz, if_hz : float
    inverted : bool
        The Doppler sign is turned (a real recording with an inverted spectrum).
    prns : iterable of int
    pfa : float
        False-alarm probability of one PRN's first-dwell schedule (module docstring).
    max_doppler_hz : float
        Search +- this Doppler.
    stages : sequence of Stage
    min_rate_hz : float
        Lowest decimated rate.
    refine_ms : int
        Recording used for the refinement and C/N0 (ms, up to the recording's length).
    verify_pfa : float
        False-alarm probability of the verification dwell over its few cells.
    excise_db : float or None
        Threshold of the narrowband interference excision
        (:func:`dsp.gnss.search_frontend.excise`); None: off.
    """
    prns, N = check_search_args(prns, pfa, max_doppler_hz, refine_ms, fs_hz)
    stages = _check_stages(stages)
    if not (isinstance(verify_pfa, (int, float)) and 0 < verify_pfa < 1):
        raise ValueError(f"verify_pfa must be in (0, 1), not {verify_pfa!r}")
    n_ms = n_samples // N
    run = [s for s in stages if 2 * s.span_ms <= n_ms]
    skipped = [str(s) for s in stages if 2 * s.span_ms > n_ms]
    if not run:
        raise ValueError(f"the recording ({n_ms} ms) is too short for any stage: the first "
                         f"needs 2 x {stages[0].span_ms} ms (dwell and verification)")
    D = decimation(fs_hz, min_rate_hz)
    fs_d = fs_hz / D
    Nd = N // D
    need_ms = 2 * max(s.span_ms for s in run)
    rf_ms = max(2, min(int(refine_ms), n_ms))
    xf, periodic, excised = front_end(read, max(need_ms, rf_ms) * N, fs_hz, if_hz, inverted,
                                      excise_db)
    n_alarms = sum(len(s.alignments_ms) for s in run)
    pfa_each = pfa / n_alarms
    rej = []

    def one(prn, si, st, xb):
        r1, a1 = _dwell(xb[:st.span_ms * Nd], fs_d, prn, st, pfa_each, max_doppler_hz)
        if not r1.detected:
            return None
        drift = r1.doppler_hz * st.span_ms * CODE_PERIOD_S / (L1_HZ / CHIP_RATE_HZ)
        ok, m2, f2, c2 = _verify(xb[st.span_ms * Nd:2 * st.span_ms * Nd], fs_d, prn, st,
                                 r1.doppler_hz, (r1.code_phase_chips + drift) % CODE_LENGTH,
                                 verify_pfa, max_doppler_hz)
        if not ok:
            rej.append({"prn": prn, "stage": si, "doppler_hz": r1.doppler_hz,
                        "code_phase_chips": r1.code_phase_chips,
                        "metric": r1.peak / r1.threshold, "verify_metric": m2})
            return None
        f, cp, cn0 = refine_detection(xf, fs_hz, prn, r1.doppler_hz, r1.code_phase_chips,
                                      CHIP_RATE_HZ / fs_d, rf_ms, st.bin_width_hz)
        return Detection(prn, float(f), cp, cn0, r1.peak / r1.threshold, si, str(st),
                         r1.doppler_hz, r1.code_phase_chips, r1.peak, r1.threshold,
                         m2, a1, st.bin_width_hz)

    def later(prn, xb):
        for si in range(1, len(run)):
            d = one(prn, si, run[si], xb)
            if d is not None:
                return d
        return None

    dets = two_pass_search(prns, xf, fs_hz, need_ms, D, lambda prn, xb: one(prn, 0, run[0], xb),
                           later if len(run) > 1 else None, rej)
    return SearchReport(dets, rej, [str(s) for s in run], skipped, float(fs_hz), D, float(pfa),
                        float(max_doppler_hz), prns, int(n_samples), excised,
                        periodic if periodic > PERIODIC_RATIO else None)
