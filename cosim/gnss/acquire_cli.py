"""``python -m cosim gnss-acquire``: every GPS L1 C/A satellite in a sample file.

Opens the recording (:class:`cosim.gnss.files.SampleFile`: format, rate, IF, spectrum,
ADC map, all checked before any work; a sample rate commensurate with the chip rate is
warned about, :func:`cosim.gnss.config.frequency_plan_warning`), searches it and prints the
satellites found (PRN, Doppler, code phase, C/N0, metric = deciding peak / threshold), the
detections refused, and the search's settings; ``--json`` prints the same as one JSON
object.

``--search sequential`` (the default) is the search of ``gnss`` and ``ins``: each PRN's dwell
extends until it is detected or ``--acq-limit-ms`` of signal is used
(:func:`dsp.gnss.search_sequential.sequential_search_all`; ``--coherent-ms`` /
``--noncoherent``: one fixed dwell instead). ``--search verified`` is the fixed stages of
``--stages``, every first-dwell detection checked by a second dwell
(:func:`dsp.gnss.search.search_all`, the search ``gnss-track`` and ``gps`` run first).
"""
from __future__ import annotations

import time

from dataclasses import replace

from ..core.validate import check_float, check_int, dumps
from .acq_options import ACQ_OPTIONS, add_dwell_arguments
from .config import GnssRunConfig
from .files import DEFAULT_ADC_MAP, FORMATS, SampleFile


def _prns(text: str) -> list[int]:
    out = []
    try:
        for part in text.split(","):
            a, _, b = part.partition("-")
            lo, hi = int(a), int(b) if b else int(a)
            out.extend(range(lo, hi + 1))
    except ValueError:
        raise ValueError(f"--prns must be a list such as 1-32 or 3,7,10-12, not {text!r}") \
            from None
    if not out or any(not 1 <= p <= 32 for p in out):
        raise ValueError(f"--prns must name PRNs in 1-32, not {text!r}")
    return sorted(set(out))


def add_file_options(p) -> None:
    """The recording's options (``--file --format --fs-hz --if-hz --invert-spectrum
    --adc-map``), shared by ``gnss-acquire`` and ``gnss-track``; :func:`open_file` opens it."""
    p.add_argument("--file", required=True, help="the recording (raw samples, no header)")
    p.add_argument("--format", required=True, choices=list(FORMATS),
                   help="int8 real; int8-iq / int16-iq interleaved I, Q; cf32 complex float32")
    p.add_argument("--fs-hz", type=float, required=True,
                   help="sample rate (S/s); a whole number of samples per 1 ms")
    p.add_argument("--if-hz", type=float, default=0.0,
                   help="IF (Hz): real [0, fs/2), complex (-fs/2, fs/2)")
    p.add_argument("--invert-spectrum", action="store_true",
                   help="the front end inverts the spectrum (complex: read as I - jQ)")
    p.add_argument("--adc-map", default=None,
                   help="odd:B, int:B, float or float:B (default by format: " +
                        ", ".join(f"{k} {v}" for k, v in DEFAULT_ADC_MAP.items()) + ")")


def add_search_options(p) -> None:
    """The search's options (``--prns --pfa --max-doppler-hz``), shared by ``gnss-acquire``
    and ``gnss-track``."""
    p.add_argument("--prns", default="1-32", help="PRNs to search, e.g. 1-32 or 3,7,10-12")
    add_dwell_arguments(p)
    p.add_argument("--max-doppler-hz", type=float, default=5000.0, help="search +- Doppler (Hz)")


def open_file(a) -> SampleFile:
    """The recording of parsed :func:`add_file_options` (every check before any work); a
    sample rate that leaves the code loop a dead zone is warned about
    (:func:`cosim.gnss.config.frequency_plan_warning`)."""
    from ..core.validate import warn
    from .config import frequency_plan_warning
    f = SampleFile(a.file, a.format, a.fs_hz, a.if_hz, a.invert_spectrum, a.adc_map)
    if (msg := frequency_plan_warning(f.fs_hz)) is not None:
        warn(msg)
    return f


def parse_prns(text: str) -> list[int]:
    """``--prns`` text (``1-32``, ``3,7,10-12``) -> sorted PRNs."""
    return _prns(text)


def add_parser(sub, make_parser) -> None:
    """Register ``gnss-acquire`` on the subparsers ``sub`` (``make_parser(sub, name, **kw)``
    adds the common options, as in :mod:`cosim.cli`)."""
    p = make_parser(sub, "gnss-acquire",
                    help="acquire every GPS L1 C/A PRN in a sample file (int8, int8-iq, "
                         "int16-iq, cf32): the satellites found with Doppler, code phase, "
                         "C/N0")
    from dsp.gnss.dwell import DEFAULT_SCHEDULE
    add_file_options(p)
    add_search_options(p)
    p.add_argument("--search", type=str.lower, default="sequential", choices=SEARCHES,
                   help="sequential (default; the search of gnss and ins): each PRN's dwell "
                        "extends (" + "; ".join(str(d) for d in DEFAULT_SCHEDULE) +
                        ") until detected or --acq-limit-ms is used (--coherent-ms T "
                        "--noncoherent K: that one dwell); verified: the fixed --stages, "
                        "each detection checked by a second dwell (the first search of "
                        "gnss-track and gps)")
    flags, kw = replace(ACQ_OPTIONS[-1], default=None).argparse_kwargs()
    kw["help"] = (f"--search sequential: signal a PRN's search may use (ms; default "
                  f"{GnssRunConfig.acq_limit_ms}, at most the recording)")
    p.add_argument(*flags, **kw)
    p.add_argument("--stages", default=None,
                   help="--search verified: dwell schedule, comma-separated TxK[@a/b] "
                        "(coherent ms x sums @ offsets ms), e.g. 1x10,5x6@0/2,10x4@0/3/6 "
                        "(default: 1x10,5x6@0/2; --coherent-ms T --noncoherent K: the one "
                        "stage TxK at the bit-edge offsets of dsp.gnss.dwell.Dwell)")
    p.add_argument("--min-rate-hz", type=float, default=2.046e6,
                   help="lowest decimated complex rate of the search (S/s)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _fixed_dwell(a) -> tuple:
    """``(--coherent-ms, --noncoherent)``, both given or both None."""
    t, k = a.acq_coherent_ms, a.acq_noncoherent
    if (t is None) != (k is None):
        raise ValueError("--coherent-ms and --noncoherent go together (a fixed dwell of "
                         "T ms x K sums): give both, or neither")
    return t, k


def stages_of(a) -> tuple:
    """The dwell schedule of the parsed options: ``--stages``, or the one stage of
    ``--coherent-ms`` x ``--noncoherent`` (its bit-edge offsets those of
    :class:`dsp.gnss.dwell.Dwell`), or the default; ValueError naming the option."""
    from dsp.gnss.dwell import Dwell
    from dsp.gnss.search import DEFAULT_STAGES, Stage
    t, k = _fixed_dwell(a)
    if t is not None:
        if getattr(a, "stages", None) is not None:
            raise ValueError("give --stages or --coherent-ms / --noncoherent, not both")
        d = Dwell(t, (k,))
        return (Stage(t, k, d.alignments()),)
    stages = getattr(a, "stages", None)      # gnss-acquire's own option
    return DEFAULT_STAGES if stages is None else \
        tuple(Stage.parse(v) for v in stages.split(","))


def check_search_options(a, *, tracker: str | None = None) -> list[int]:
    """The PRNs of parsed :func:`add_search_options`, their ``--pfa`` and
    ``--max-doppler-hz`` checked (ValueError naming the option); with ``tracker``, also that
    the tracker runs on a recording (no INS aiding source there)."""
    prns = _prns(a.prns)
    check_float("--pfa", a.acq_pfa, 0, 1, lo_open=True, hi_open=True)
    check_float("--max-doppler-hz", a.max_doppler_hz, 0, 50e3, lo_open=True, unit="Hz")
    if tracker is not None:
        from dsp.gnss.trackers import needs_aiding
        if needs_aiding(tracker):
            raise ValueError(f"--tracker {tracker} needs an INS aiding source; a recording "
                             f"has none")
    return prns


def search_file(f: SampleFile, a, prns, **kw):
    """:func:`dsp.gnss.search.search_all` over the recording ``f`` with the parsed search
    options (``--pfa``, ``--max-doppler-hz``, the dwell schedule of :func:`stages_of`);
    ``kw`` passes further search arguments (``min_rate_hz``)."""
    from dsp.gnss.search import search_all
    return search_all(f.read, f.n_samples, f.fs_hz, f.if_hz, f.doppler_sign_inverted, prns,
                      a.acq_pfa, a.max_doppler_hz, stages_of(a), **kw)


#: ``gnss-acquire --search`` choices (module docstring).
SEARCHES = ("sequential", "verified")


def check_acquire_search(a):
    """The sequential search's schedule and limit of parsed ``gnss-acquire`` options
    (``None`` for ``--search verified``); an option of the other search is refused
    (ValueError naming it)."""
    from dsp.gnss.dwell import DEFAULT_SCHEDULE, fixed_schedule
    if a.search == "verified":
        if a.acq_limit_ms is not None:
            raise ValueError("--acq-limit-ms limits the sequential search: --search "
                             "verified reads what its --stages need")
        stages_of(a)
        return None
    if a.stages is not None:
        raise ValueError("--stages is the schedule of --search verified; the sequential "
                         "search takes --coherent-ms / --noncoherent or extends its own")
    limit = GnssRunConfig.acq_limit_ms if a.acq_limit_ms is None else a.acq_limit_ms
    check_int("--acq-limit-ms", limit, 1)
    t, k = _fixed_dwell(a)
    sched = DEFAULT_SCHEDULE if t is None else fixed_schedule(t, k)
    if sched[0].span_ms() > limit:
        raise ValueError(f"--acq-limit-ms {limit} is shorter than the first dwell "
                         f"({sched[0]}: {sched[0].span_ms()} ms of signal)")
    return sched, limit


#: ``status`` of a search that found no satellite: a result (exit 1), not bad input.
NOT_FOUND = "no satellite found"


def search_status(rep) -> str:
    """``status`` of a recording's search for the JSON: ``found`` or :data:`NOT_FOUND`
    (``gnss-acquire``, ``gnss-track`` and ``gps`` exit 1 on the latter)."""
    return "found" if rep.detections else NOT_FOUND


def run(a) -> int:
    """``gnss-acquire``: exit 0 with a satellite found, 1 with none (a weak or absent
    signal is a result), 2 for bad input (before any work)."""
    prns = check_search_options(a)
    check_float("--min-rate-hz", a.min_rate_hz, 0, lo_open=True, unit="S/s")
    seq = check_acquire_search(a)       # the dwell options checked before the file opens
    f = open_file(a)
    t0 = time.time()
    if seq is None:
        rep = search_file(f, a, prns, min_rate_hz=a.min_rate_hz)
    else:
        from dsp.gnss.search_sequential import sequential_search_all
        rep = sequential_search_all(f.read, f.n_samples, f.fs_hz, f.if_hz,
                                    f.doppler_sign_inverted, prns, a.acq_pfa,
                                    a.max_doppler_hz, seq[0], seq[1],
                                    min_rate_hz=a.min_rate_hz)
    out = {"status": search_status(rep), "recording": f.describe(), "search": a.search,
           **rep.as_dict(), "wall_s": round(time.time() - t0, 1)}
    rc = 0 if rep.detections else 1
    if a.json:
        print(dumps(out))
        return rc
    d = f.describe()
    print(f"{d['file']}: {d['format']}, {d['fs_hz'] / 1e6:g} MS/s, IF {d['if_hz'] / 1e6:g} MHz"
          f"{', spectrum inverted' if f.inverted else ''}, ADC map {d['adc_map']}, "
          f"{d['duration_s'] * 1e3:.1f} ms")
    what = ("per PRN's search (--pfa over all PRNs); dwells within the limit"
            if seq is not None else "per PRN before verification; stages run")
    print(f"{a.search} search at {rep.fs_hz / rep.decimation / 1e6:g} MS/s (decimation "
          f"{rep.decimation}), Doppler +-{rep.max_doppler_hz:g} Hz, pfa {rep.pfa:g} {what}: "
          f"{'; '.join(rep.stages_run)}"
          + (f"; not run (beyond the limit or the recording): "
             f"{'; '.join(rep.stages_skipped)}" if rep.stages_skipped else ""))
    print(f"{'PRN':>4} {'Doppler Hz':>11} {'code chips':>11} {'C/N0 dB-Hz':>11} "
          f"{'metric':>7}  stage")
    for x in rep.detections:
        print(f"{x.prn:>4} {x.doppler_hz:>11.1f} {x.code_phase_chips:>11.3f} "
              f"{x.cn0_dbhz:>11.1f} {x.metric:>7.2f}  {x.stage_text}")
    print(f"{len(rep.detections)} satellites found in {out['wall_s']} s; "
          f"{len(rep.rejected)} first-dwell detections refused"
          + (": " + ", ".join(f"PRN {r['prn']}" + (f" (cross-correlation of PRN "
                                                    f"{r['cross_correlation_of']})"
                                                    if "cross_correlation_of" in r else
                                                    " (not re-detected)")
                             for r in rep.rejected) if rep.rejected else ""))
    return rc
