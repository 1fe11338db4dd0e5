"""Closed-loop equivalence of the GNSS channel array on a window of the generated
multi-satellite scenario (``python -m cosim check-equivalence --top gnss --scenario gps``).

The window: the first ``samples`` samples of the scenario of ``python -m cosim gps``
(:func:`cosim.gnss.gps_scenario.write_scenario` with its defaults: a static receiver under
the nominal constellation, 8 satellites in view at 45 dB-Hz, 5 MS/s real IF 1.25 MHz, int8
with 2-bit odd-level words), written to a temporary directory. Acquisition runs once on it
(:func:`dsp.gnss.search.search_all`, the search of ``gnss-acquire`` / ``gps`` with its default
dwells, ``prns`` searched); the satellites found are then tracked over the same window, closed
loop, by :func:`cosim.gnss.multichannel.track_file` (the ``gps`` and ``gnss-track`` path: the
default ``pll3`` tracker in fixed point, its DSP service and control latency) on ``channels``
channels of the array, once per backend. The bit-exact model is the reference; each other
backend (Verilator; the Amaranth simulation and Icarus only for windows they can run,
:func:`cosim.tools.equivalence.skip_reason`) must give, compared by
:func:`cosim.tools.equivalence.compare_backends`:

* every FIFO word the DSP read, and the cycle it read it on, and the overflow counter;
* every bus write ``(cycle, address, value)`` that reached the array (the hand-overs and each
  tracker's carrier and code words, written back on the cycles the loop decided);
* the writes the DSP issued ``(effect cycle, register, value)``;
* the digest of the trackers' outputs (:func:`tracker_digest`: per assignment its PRN,
  channel, status, the Doppler, code phase and prompt of every record and the lock windows;
  the re-acquisitions).

A closed loop diverges after the first differing bit (a record's difference changes the
tracker's next write, which changes every later record), so zero mismatches over a window
says the backends ran the same receiver.
"""
from __future__ import annotations

import hashlib
import sys
import tempfile
import time
from dataclasses import dataclass

import numpy as np

from ..core.validate import check_int
from ..tools.equivalence import BACKENDS, compare_backends, simulators_line

__all__ = ["check_array_equivalence", "prepare_window", "compare_window", "Window",
           "tracker_digest", "scenario_window", "acquire_window", "SCENARIOS",
           "WINDOW_SAMPLES", "MIN_WINDOW_MS"]

#: The scenarios of ``check-equivalence --scenario``.
SCENARIOS = ("gps",)
#: Default window: 100 ms of the 5 MS/s scenario.
WINDOW_SAMPLES = 500_000
#: Shortest window: the acquisition's first dwell (10 x 1 ms) and its verification.
MIN_WINDOW_MS = 20


def scenario_window(samples: int, seed: int, out_dir):
    """``(SampleFile, truth)``: the first ``samples`` samples (and the rest of that
    millisecond) of the ``gps`` command's generated scenario with seed ``seed``, written
    to ``out_dir``, opened as ``gps`` opens it; ``truth``: the scenario's ``truth.json``
    content (its PRNs among it)."""
    from .files import SampleFile
    from .gps_scenario import ScenarioSpec, write_scenario
    spec = ScenarioSpec(seed=seed)
    n_ms = int(round(spec.fs_hz / 1e3))
    ms = -(-samples // n_ms)
    sc = write_scenario(ScenarioSpec(seed=seed, duration_s=ms / 1e3), out_dir)
    f = SampleFile(sc["file"], sc["format"], sc["fs_hz"], sc["if_hz"])
    if f.n_samples < samples:
        raise RuntimeError(f"internal: the scenario has {f.n_samples} samples, "
                           f"{samples} were asked")
    return f, sc["truth"]


def acquire_window(f, samples: int, prns):
    """The candidates (strongest first) that the default search of ``gnss-acquire`` finds
    for ``prns`` in the first ``samples`` samples of ``f``."""
    from dsp.gnss.search import search_all
    from .multichannel import Candidate
    rep = search_all(f.read, samples, f.fs_hz, f.if_hz, f.doppler_sign_inverted, prns)
    return sorted((Candidate.of(d) for d in rep.detections), key=lambda c: -c.cn0_dbhz)


def tracker_digest(m) -> str:
    """16 hex digits of SHA-256 over a multi-channel run's tracker outputs
    (:class:`cosim.gnss.multichannel.MultiTrack`): every assignment's PRN, channel, status,
    end reason, start/lock/end samples, its per-record times, Doppler, code phase and prompt
    I/Q, its lock windows (PLI, C/N0, the two locks), the re-acquisitions (PRN, channel,
    time, found) and the record receiver's counters."""
    h = hashlib.sha256()
    for a in m.assignments:
        h.update(repr((a.prn, a.channel, a.status, a.end_reason, a.start_sample,
                       a.lock_sample, a.end_sample)).encode())
        for k in ("t", "doppler", "code_phase", "ip", "qp", "win_t", "win_pli", "win_cn0"):
            h.update(np.asarray(getattr(a, k), np.float64).tobytes())
        for k in ("win_phase_lock", "win_cn0_lock"):
            h.update(np.asarray(getattr(a, k), bool).tobytes())
    for r in m.reacquisitions:
        h.update(repr((r["prn"], r["channel"], r["t_s"], r["found"])).encode())
    h.update(repr(sorted(m.rx_stats.items())).encode())
    return h.hexdigest()[:16]


@dataclass(frozen=True)
class Window:
    """A window of a scenario and what the acquisition found in it."""

    scenario: str
    file: object            #: the recording (:class:`cosim.gnss.files.SampleFile`)
    samples: int            #: the window: the file's first ``samples`` samples
    seed: int
    truth: dict             #: the scenario's ``truth.json`` (its ``prns`` among it)
    candidates: tuple       #: :class:`cosim.gnss.multichannel.Candidate`, strongest first


def prepare_window(samples: int = WINDOW_SAMPLES, out_dir=None, *, scenario: str = "gps",
                   seed: int = 1, prns=range(1, 33)) -> Window:
    """Write the first ``samples`` samples of ``scenario`` (seed ``seed``) to ``out_dir``
    and acquire ``prns`` on them once (module doc; None: the scenario's own PRNs, a shorter
    search); refuses a bad option (ValueError naming it) before any work, and a window in
    which no satellite is found (RuntimeError)."""
    if scenario not in SCENARIOS:
        raise ValueError(f"--scenario must be one of {', '.join(SCENARIOS)}, not {scenario!r}")
    samples = check_int("--samples", samples, 1)
    seed = check_int("--seed", seed, 0)
    if prns is not None:
        from dsp.gnss.ca_code import check_prn
        prns = [check_prn(x) for x in prns]
    from .gps_scenario import ScenarioSpec
    n_ms = int(round(ScenarioSpec().fs_hz / 1e3))
    if samples < MIN_WINDOW_MS * n_ms:
        raise ValueError(f"--samples {samples} is shorter than the acquisition needs: "
                         f"at least {MIN_WINDOW_MS * n_ms} ({MIN_WINDOW_MS} ms at "
                         f"{n_ms / 1e3:g} MS/s)")
    f, truth = scenario_window(samples, seed, out_dir)
    if prns is None:
        prns = list(truth["prns"])
    cands = acquire_window(f, samples, prns)
    if not cands:
        raise RuntimeError(f"the acquisition found none of PRNs {prns} in the "
                           f"{samples}-sample window (scenario PRNs {truth['prns']})")
    return Window(scenario, f, samples, seed, truth, tuple(cands))


def compare_window(w: Window, *, channels: int = 8, backends=("model", "verilator"),
                   progress: bool = False) -> dict:
    """Track window ``w`` closed loop on ``channels`` channels of the array on each of
    ``backends`` and compare them with the model (module doc): the keys of
    :func:`cosim.tools.equivalence.compare_backends` (``peaks``: the model's records;
    ``words``: its FIFO words; ``per_backend[b]["outputs"]``: the bus writes, the DSP's
    writes and the tracker digest compared) and ``scenario``: its PRNs, the candidates
    acquired, the channels and the model's assignments (PRN, channel, status, records)."""
    from .config import GnssRunConfig
    from .multichannel import TrackConfig, channel_params_for, track_file
    from .multichannel_session import array_channel_params
    cfg = TrackConfig(channels=channels)             # refuses a bad --channels
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"backends must be among {BACKENDS}, not {unknown}")
    f = w.file
    p = array_channel_params(channel_params_for(f), cfg.channels)
    runs = {}

    def run(backend):
        t = time.perf_counter()
        m = track_file(f, w.candidates, GnssRunConfig(backend=backend), cfg,
                       n_samples=w.samples, keep_words=True,
                       progress=progress and sys.stderr.isatty())
        res = m.pipeline
        runs[backend] = m
        outputs = {"bus writes": np.asarray(m.bus_writes, np.int64).reshape(-1, 3),
                   "DSP writes": list(res.writes),
                   "tracker digest": tracker_digest(m)}
        return (np.asarray(res.words, np.int64), np.asarray(res.cycles, np.int64),
                int(res.overflow_count), time.perf_counter() - t, outputs)

    r = compare_backends("gnss-array", w.samples, backends, run, seed=w.seed, stall=False,
                         record_words=p.fifo.record_words,
                         empty_hint="a record per channel every 1 ms")
    ref = runs["model"]
    r["n_cycles"] = int(ref.pipeline.n_cycles)
    r["simulators"] = simulators_line(r["per_backend"], r["n_cycles"])
    r["scenario"] = {
        "name": w.scenario, "prns": list(w.truth["prns"]),
        "window_ms": w.samples * 1e3 / f.fs_hz, "channels": cfg.channels,
        "acquired": [{"prn": c.prn, "doppler_hz": round(c.doppler_hz, 1),
                      "code_phase_chips": round(c.code_phase_chips, 3),
                      "cn0_dbhz": round(c.cn0_dbhz, 1)} for c in w.candidates],
        "assignments": [{"prn": a.prn, "channel": a.channel, "status": a.status,
                         "records": len(a.t)} for a in ref.assignments]}
    return r


def check_array_equivalence(samples: int = WINDOW_SAMPLES, *, scenario: str = "gps",
                            channels: int = 8, backends=("model", "verilator"), seed: int = 1,
                            prns=range(1, 33), stall: bool = False,
                            progress: bool = False) -> dict:
    """:func:`prepare_window` in a temporary directory, then :func:`compare_window`
    (``check-equivalence --scenario``); every option is checked before any work."""
    from .multichannel import TrackConfig
    if stall:
        raise ValueError("--stall does not apply to --scenario: the closed loop reads the "
                         "FIFO with its DSP service's pattern")
    TrackConfig(channels=channels)
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"backends must be among {BACKENDS}, not {unknown}")
    with tempfile.TemporaryDirectory(prefix="cosim_scenario_") as tmp:
        w = prepare_window(samples, tmp, scenario=scenario, seed=seed, prns=prns)
        return compare_window(w, channels=channels, backends=backends, progress=progress)
