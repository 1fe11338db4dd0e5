"""``python -m cosim gnss-track``: every satellite of a recording tracked at once.

The recording (the options of ``gnss-acquire``, :func:`cosim.gnss.acquire_cli.add_file_options`,
all checked before any work) is searched for every PRN of ``--prns``
(:func:`dsp.gnss.search.search_all`, verification dwell included), then the satellites found,
strongest first, are tracked on ``--channels`` channels of the FPGA array, closed loop
(:func:`cosim.gnss.multichannel.track_file`: ``--backend`` model or verilator, ``--tracker``
in ``--dsp`` arithmetic), with re-allocation when a channel never locks or loses lock.
Prints the per-PRN table (:func:`cosim.gnss.track_report.table`) or, with ``--json``, one
JSON object (:func:`cosim.gnss.track_report.summarise`); ``--plots DIR`` writes the Doppler,
C/N0 and prompt I/Q plots. Progress on stderr (tqdm) unless ``--json``.

A separate command, not ``gnss --file``: ``gnss`` is one PRN of the built-in generator scored
against its truth; a recording has no truth, many satellites and its own options.
"""
from __future__ import annotations

from ..core.validate import check_float, check_out_dir, dumps
from .acquire_cli import add_file_options, add_search_options, check_search_options, \
    open_file, search_file

__all__ = ["add_parser", "run", "DEFAULT_PLOTS"]

#: Where ``--plots`` without a directory writes.
DEFAULT_PLOTS = "build/gnss_track"
#: Backends with the channel array.
ARRAY_BACKENDS = ("model", "pysim", "verilator")


def add_parser(sub, make_parser) -> None:
    """Register ``gnss-track`` on the subparsers ``sub`` (as :mod:`cosim.cli` does)."""
    from dsp.gnss.trackers import tracker_names
    p = make_parser(sub, "gnss-track",
                    help="track every GPS L1 C/A satellite of a sample file at once on the "
                         "12-channel FPGA array, closed loop: Doppler, code phase, C/N0, locks "
                         "and bit transitions per PRN")
    add_file_options(p)
    add_search_options(p)
    p.add_argument("--channels", type=int, default=12,
                   help="channels of the array (1..12); more satellites than channels: the "
                        "strongest first, the rest when a channel frees")
    p.add_argument("--tracker", type=str.lower, default="pll3", choices=tracker_names(),
                   help="the DSP tracker of every channel (dsp.gnss.trackers)")
    p.add_argument("--dsp", type=str.lower, default="fixed", choices=("fixed", "float"),
                   help="arithmetic of the trackers")
    p.add_argument("--bn-hz", type=float, default=None,
                   help="carrier loop noise bandwidth of the PLL trackers (Hz; default 15)")
    p.add_argument("--backend", type=str.lower, default="model", choices=ARRAY_BACKENDS,
                   help="the array: model (bit-exact), verilator, pysim (slow: ms only)")
    p.add_argument("--duration-s", type=float, default=None,
                   help="track the first seconds only (default: the whole recording)")
    p.add_argument("--parallel", action="store_true",
                   help="the model's channels on numba's threads (NUMBA_NUM_THREADS; same "
                        "bits, faster on idle cores)")
    p.add_argument("--pull-in-ms", type=int, default=100,
                   help="a channel not locked this long after its hand-over drops its PRN")
    p.add_argument("--plots", nargs="?", const=DEFAULT_PLOTS, default=None, metavar="DIR",
                   help=f"write doppler.png, cn0.png, prompt_iq.png (default dir "
                        f"{DEFAULT_PLOTS})")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(a) -> int:
    import sys

    from .config import GnssRunConfig
    from .multichannel import Candidate, TrackConfig, channel_params_for, track_file
    from .multichannel_session import check_parallel
    from .acquire_cli import NOT_FOUND
    from .track_report import summarise, table, write_plots
    prns = check_search_options(a, tracker=a.tracker)
    cfg = TrackConfig(channels=a.channels, pull_in_ms=a.pull_in_ms, pfa=a.acq_pfa,
                      max_doppler_hz=a.max_doppler_hz, parallel=a.parallel)
    check_parallel(a.parallel, a.backend)
    run_cfg = GnssRunConfig(tracker=a.tracker, dsp=a.dsp, backend=a.backend, bn_hz=a.bn_hz)
    if a.plots is not None:
        check_out_dir(a.plots, "--plots")
    f = open_file(a)
    channel_params_for(f)             # a complex recording refused here, before work
    n = f.n_samples
    if a.duration_s is not None:
        check_float("--duration-s", a.duration_s, 0, f.duration_s, lo_open=True, unit="s")
        n = int(round(a.duration_s * f.fs_hz))
        if n < 2 * f.samples_per_ms:
            raise ValueError(f"--duration-s {a.duration_s:g} s is shorter than 2 ms")
    if a.backend == "pysim" and n > 200_000:
        raise ValueError(f"--backend pysim simulates ~2e3 cycles/s: {n} samples would take "
                         f"~{n / 2e3 / 3600:.1f} h; give --duration-s <= "
                         f"{200_000 / f.fs_hz:.4f}")
    rep = search_file(f, a, prns)
    cands = [Candidate.of(d) for d in rep.detections]
    if not cands:
        out = {"status": NOT_FOUND, "recording": f.describe(), "acquisition": rep.as_dict(),
               "assignments": [], "tracked": []}
        print(dumps(out) if a.json else f"{NOT_FOUND}: nothing to track")
        return 1
    m = track_file(f, cands, run_cfg, cfg, n_samples=n,
                   progress=not a.json and sys.stderr.isatty())
    s = summarise(m, f.describe(), {"detections": [d.as_dict() for d in rep.detections],
                                    "rejected": rep.rejected, "stages_run": rep.stages_run})
    if a.plots is not None:
        s["plots"] = write_plots(m, a.plots)
    if a.json:
        print(dumps(s))
        return 0
    print(table(s))
    if "plots" in s:
        print("plots: " + ", ".join(s["plots"]))
    return 0
