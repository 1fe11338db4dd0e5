"""Every GPS L1 C/A PRN of a recording by the sequential search: the dwell of each PRN
extends (:func:`dsp.gnss.dwell.sequential_search`, the schedule of
:data:`dsp.gnss.dwell.DEFAULT_SCHEDULE`) until the PRN is detected or the stated limit of
signal (``limit_ms``, at most the recording) is used up, at a stated false-alarm probability
``pfa`` of the whole search: the probability that it reports any absent PRN is at most
``pfa`` (each of the ``P`` PRNs' searches gets ``pfa / P``, union bound; on the 70 ms
PocketSDR window ``pfa / 1`` per PRN let through three of the strong satellites'
cross-correlations and one more detection that does not track).

It shares the front end of :func:`dsp.gnss.search.search_all` (1 ms periodic interference
removed, mixed to zero IF, narrowband interference excised, low-pass and decimated to at
least ``min_rate_hz``) and its refinement and C/N0 (:func:`dsp.gnss.search.refine_detection`
at the full rate, over the recording's first ``refine_ms`` ms); what differs is the
detection: no fixed stages checked by a second dwell, but the sequential schedule whose
threshold holds the whole search of one absent PRN to ``pfa`` (union bound over its tests,
:mod:`dsp.gnss.dwell`).

Passes
------
1. Every PRN's first dwell (1 ms x 5/10 by default).
2. The satellites found are subtracted from the samples (:func:`dsp.gnss.search.cancel`, at
   their refined Doppler and code phase), then the PRNs not found run the later, longer
   dwells (at their places in the stream, with the threshold of the whole schedule:
   ``first=1``), whose sensitivity would otherwise reach the found satellites'
   cross-correlation.

A detection at a stronger one's Doppler plus a multiple of 1 kHz and
:data:`dsp.gnss.search.XCORR_MARGIN_DB` below it is refused as its cross-correlation
(:func:`dsp.gnss.search.cross_correlation_suspects`). The detecting dwell's Doppler and code
phase (at the dwell's start, ``start_ms`` into the recording) are taken back to the
recording's first sample by the code Doppler (``f / 1540`` chips/s) before the refinement.
"""
from __future__ import annotations


from .ca_code import CHIP_RATE_HZ, CODE_LENGTH, CODE_PERIOD_S, L1_HZ
from .dwell import DEFAULT_LIMIT_MS, DEFAULT_SCHEDULE, schedule_within, sequential_search
from .search import Detection, SearchReport, check_search_args, refine_detection, two_pass_search
from .search_frontend import EXCISE_DB, MIN_RATE_HZ, PERIODIC_RATIO, decimation, front_end

__all__ = ["sequential_search_all"]


def sequential_search_all(read, n_samples: int, fs_hz: float, if_hz: float,
                          inverted: bool = False, prns=range(1, 33), pfa: float = 1e-3,
                          max_doppler_hz: float = 5000.0, schedule=DEFAULT_SCHEDULE,
                          limit_ms: int = DEFAULT_LIMIT_MS, min_rate_hz: float = MIN_RATE_HZ,
                          refine_ms: int = 100, excise_db: float | None = EXCISE_DB
                          ) -> SearchReport:
    """Search every PRN of ``prns`` on a recording (module docstring); the arguments as
    :func:`dsp.gnss.search.search_all`'s, with ``schedule`` (sequence of
    :class:`dsp.gnss.dwell.Dwell`) and ``limit_ms`` (signal a PRN's search may use, ms; the
    recording's length if shorter) instead of the stages. ``pfa``: false-alarm probability
    of the whole search (an absent PRN reported; ``pfa / len(prns)`` per PRN, the
    report's ``pfa``). The report's ``stages_run`` are the dwells within the
    limit, ``stages_skipped`` those beyond it."""
    prns, N = check_search_args(prns, pfa, max_doppler_hz, refine_ms, fs_hz)
    sched_all = tuple(schedule)
    n_ms = int(n_samples) // N
    if sched_all and n_ms < sched_all[0].span_ms():
        raise ValueError(f"the recording ({n_ms} ms) is too short for the search's first "
                         f"dwell ({sched_all[0]}: {sched_all[0].span_ms()} ms of signal)")
    limit = min(int(limit_ms), n_ms)
    sched = schedule_within(sched_all, limit)
    skipped = [str(d) for d in sched_all[len(sched):]]
    need_ms = sum(d.span_ms() for d in sched)
    rf_ms = max(2, min(int(refine_ms), n_ms))
    D = decimation(fs_hz, min_rate_hz)
    fs_d = fs_hz / D
    Nd = N // D
    xf, periodic, excised = front_end(read, max(need_ms, rf_ms) * N, fs_hz, if_hz, inverted,
                                      excise_db)
    rej = []
    pfa_prn = pfa / len(prns)

    def one(prn, xb, first):
        r = sequential_search(lambda k0, k1: xb[k0 * Nd:k1 * Nd], fs_d, prn, sched, limit,
                              pfa_prn, max_doppler_hz, first=first,
                              last=1 if first == 0 else None)
        if not r.detected:
            return None
        # the dwell's code phase at its start, taken back to the recording's first sample
        cp0 = (r.code_phase_chips - r.doppler_hz * CHIP_RATE_HZ / L1_HZ
               * r.start_ms * CODE_PERIOD_S) % CODE_LENGTH
        f, cp, cn0 = refine_detection(xf, fs_hz, prn, r.doppler_hz, cp0, CHIP_RATE_HZ / fs_d,
                                      rf_ms, r.bin_width_hz)
        return Detection(prn, float(f), cp, cn0, r.metric, r.stage,
                         f"{r.coherent_ms} ms x {r.noncoherent} at {r.t_detect_ms} ms",
                         r.doppler_hz, r.code_phase_chips, r.peak, r.threshold, None,
                         r.alignment_ms, r.bin_width_hz)

    dets = two_pass_search(prns, xf, fs_hz, need_ms, D, lambda prn, xb: one(prn, xb, 0),
                           (lambda prn, xb: one(prn, xb, 1)) if len(sched) > 1 else None, rej)
    return SearchReport(dets, rej, [str(d) for d in sched], skipped, float(fs_hz), D,
                        float(pfa_prn), float(max_doppler_hz), prns, int(n_samples), excised,
                        periodic if periodic > PERIODIC_RATIO else None)
