"""The TACAN front-end backends: what turns a record of ADC samples into the pulse peaks
the bearing DSP receives (:class:`FrontendOutput`).

``golden``     float64 model of the front end (:mod:`dsp.tacan.frontend`); no FIFO.
``model``      bit-exact numpy model of the HDL (:class:`hdl.tacan.model.TacanFrontendModel`)
               and of its FIFO, read by the DSP service model of :mod:`cosim.core.link`.
``pysim``      the Amaranth design in ``amaranth.sim`` (cycle-accurate, ~1k cycles/s: short
               scenarios only).
``verilator``  the exported Verilog compiled with Verilator (cycle-accurate, compiled speed).
``icarus``     the exported Verilog in Icarus Verilog, driven by cocotb (cycle-accurate,
               ~1e3 cycles/s: short scenarios only).

The four HDL backends produce the same FIFO words on the same cycles (the tests check it;
:func:`recheck_cycle_accurate` re-checks the start of a model run); on their DSP side
(:func:`dsp_receive`) the tagged FIFO words (data / gap markers) are decoded, the 32-bit
timestamps unwrapped and the amplitudes scaled to full scale. :data:`FRONTENDS` maps each
backend to its function ``(samples, run) -> FrontendOutput``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from dsp.tacan.frontend import run_golden_frontend
from dsp.tacan.fifo_rx import receive_words
from ..core.control import ControlPath
from .config import TacanRunConfig


@dataclass
class FrontendOutput:
    """What the DSP receives from a front-end backend (one record).

    ticks : int64 unwrapped ADC tick of each peak, golden convention (the tick that
        completes the envelope sample); amplitude_fs : float amplitudes (FS);
    amplitude_lsb : envelope LSBs (HDL backends) or None; words/cycles : FIFO words read by
    the DSP and their read cycles (HDL backends); fifo_dropped : FPGA overflow counter at
    the end; dropped_reported : sum of the gap markers the DSP read; source : with two
    searches (``FrontendConfig.pair_peak``) the search of each peak (int8,
    ``dsp.tacan.frontend.SOURCE_PULSE`` / ``SOURCE_PAIR``), else None.
    """

    ticks: np.ndarray
    amplitude_fs: np.ndarray
    amplitude_lsb: np.ndarray | None = None
    words: np.ndarray | None = None
    cycles: np.ndarray | None = None
    fifo_dropped: int = 0
    dropped_reported: int = 0
    n_cycles: int = 0
    scale_to_fs: float = 1.0
    extra: dict = field(default_factory=dict)
    source: np.ndarray | None = None   # with two searches: each peak's (dsp.tacan.frontend)


# ---------------------------------------------------------------------------------------
# Front-end backends
# ---------------------------------------------------------------------------------------
def golden_frontend(samples, run: TacanRunConfig) -> FrontendOutput:
    """The ``golden`` backend: the float64 front end of ``run`` on ``samples`` (no FIFO)."""
    pk = run_golden_frontend(samples, run.frontend, run.signal.adc_bits)
    return FrontendOutput(ticks=np.asarray(pk.timestamps, np.int64),
                          amplitude_fs=np.asarray(pk.amplitudes, np.float64), source=pk.source)


def _n_cycles(samples, params) -> int:
    """Cycles simulated: every ADC sample plus enough to flush the last peak out."""
    return int(len(samples) + params.latency + 4 * params.decimation + 64)


def _freq_segments(run: TacanRunConfig, params, n_cycles: int):
    ctl = ControlPath(run.control_latency_cycles, initial={"freq": params.nco_freq_word})
    for c, reg, v in run.control_writes:
        ctl.write(int(c), reg, int(v))
    return ctl


def dsp_receive(words, cycles, params, n_cycles, ovf_count) -> FrontendOutput:
    """The DSP side of the link: tagged words -> peaks (unwrapped ticks, amplitudes; with
    two searches their sources, each search's timestamps checked on their own)."""
    out = receive_words(words, width=params.fifo.width, amp_width=params.peak.amp_width,
                        ts_bits=params.peak.ts_bits, parity=params.fifo.parity,
                        source_bits=params.source_bits)
    ts, amp, rx = out[0], out[1], out[-1]
    ticks = ts + np.int64(params.decimation - 1)     # golden convention (see peaks_to_fs)
    return FrontendOutput(ticks=ticks, amplitude_fs=amp * params.scale_to_fs, amplitude_lsb=amp,
                          words=np.asarray(words, np.int64), cycles=np.asarray(cycles, np.int64),
                          fifo_dropped=int(ovf_count),
                          dropped_reported=int(rx.stats["dropped_reported"]),
                          n_cycles=int(n_cycles), scale_to_fs=params.scale_to_fs,
                          extra={"rx": dict(rx.stats)},
                          source=out[2] if params.source_bits else None)


def _session_frontend(samples, run: TacanRunConfig, backend: str,
                      envelope_memo=None) -> FrontendOutput:
    """An HDL backend's output for one record, on the streaming pipeline: a front-end
    session (:func:`cosim.backends.factory.open_frontend`) fed the record and ``_n_cycles - len``
    idle cycles to flush the last peak, the DSP reading with ``run.service``, the
    ``control_writes`` scheduled at their effect cycles (open loop: the DSP runs after).
    ``envelope_memo`` (model): the model's :class:`~hdl.tacan.envelope_memo.EnvelopeMemo`."""
    from ..core.pipeline import Pipeline
    from ..backends.factory import open_frontend
    p = run.hdl_params
    n_cycles = _n_cycles(samples, p)
    ctl = _freq_segments(run, p, n_cycles)
    # One ADC sample per cycle from reset: a write taking effect at cycle c changes the NCO
    # word from ADC sample c on, on every backend.
    writes = [(c, "freq", v) for c, _, v in ctl.writes()]
    with open_frontend(backend, p, log_ranges=backend == "model",
                       vcd=run.trace if backend == "pysim" else None) as fe:
        if envelope_memo is not None:
            fe.model.envelope_memo = envelope_memo
        pipe = Pipeline(fe, run.service)
        pipe.schedule(writes)
        pipe.feed(samples)
        pipe.idle(n_cycles - len(samples))
        res = pipe.result()
        fo = dsp_receive(res.words, res.cycles, p, n_cycles, res.overflow_count)
        if backend == "model":
            fo.extra["ranges"] = fe.ranges()
            fo.extra["fifo_max_level"] = int(fe.fifo_state.max_level)
    return fo


def model_frontend(samples, run: TacanRunConfig, envelope_memo=None) -> FrontendOutput:
    """The ``model`` backend: the bit-exact HDL model and its FIFO, with the range log.
    ``envelope_memo``: an :class:`~hdl.tacan.envelope_memo.EnvelopeMemo` shared by the runs
    of one record whose front ends differ in their peak searches only (the envelope chain
    computed once, the same bits)."""
    return _session_frontend(samples, run, "model", envelope_memo)


def _hdl_sim(samples, run: TacanRunConfig, kind: str) -> FrontendOutput:
    if kind == "pysim" or run.trace is None:
        return _session_frontend(samples, run, kind)
    # A Verilator waveform needs the one-shot run (a session's time base is per step).
    from hdl.tacan.frontend import TacanFrontEnd
    from ..backends.verilator import VerilatorStreamSim
    p = run.hdl_params
    n_cycles = _n_cycles(samples, p)
    ctl = _freq_segments(run, p, n_cycles)
    ready = run.service.ready_mask(n_cycles)
    writes = [(c, "freq", v) for c, _, v in ctl.writes()]
    sim = VerilatorStreamSim(TacanFrontEnd(p), name="tacan_frontend")
    res = sim.run(samples, out_ready=ready, n_cycles=n_cycles,
                  inputs={"freq": p.nco_freq_word}, writes=writes,
                  final={"overflow_count": "overflow_count"},
                  trace=run.trace, trace_window=run.trace_window)
    return dsp_receive(res.words, res.cycles, p, n_cycles, res.final["overflow_count"])


FRONTENDS = {"golden": golden_frontend, "model": model_frontend,
             "pysim": lambda s, r: _hdl_sim(s, r, "pysim"),
             "verilator": lambda s, r: _hdl_sim(s, r, "verilator"),
             "icarus": lambda s, r: _session_frontend(s, r, "icarus")}


def frontend_key(run: TacanRunConfig) -> tuple:
    """What a front end's output depends on: runs with equal keys on the same samples get
    the same :class:`FrontendOutput` (the DSP side may differ)."""
    return (run.backend, run.signal, run.noise_floor, run.amplitude, run.frontend_changes,
            run.hdl_changes, run.service,
            run.control_writes, run.control_latency_cycles)


def recheck_cycle_accurate(run: TacanRunConfig, samples, backend: str = "auto",
                           n: int | None = None) -> dict:
    """Re-run the first ``n`` ADC samples of a model run on a cycle-accurate backend and
    compare the FIFO words and their cycles (and the overflow count) bit for bit.

    ``backend``: ``"verilator"``, ``"pysim"``, ``"icarus"`` or ``"auto"`` (Verilator when
    installed); ``n`` defaults to 1,000,000 samples (50 ms) with Verilator and 40,000 with
    pysim and Icarus.
    """
    from ..backends.verilator_harness import verilator_available
    if backend == "auto":
        backend = "verilator" if verilator_available() else "pysim"
    if backend not in ("pysim", "verilator", "icarus"):
        raise ValueError(f"recheck backend must be auto, pysim, verilator or icarus, not "
                         f"{backend!r}")
    n = int(n or (1_000_000 if backend == "verilator" else 40_000))
    x = np.asarray(samples)[:n]
    t0 = time.perf_counter()
    ref_run = replace(run, backend="model", trace=None, compare=None, recheck=None)
    a = model_frontend(x, ref_run)
    b = FRONTENDS[backend](x, replace(ref_run, backend=backend))
    same = (np.array_equal(a.words, b.words) and np.array_equal(a.cycles, b.cycles)
            and a.fifo_dropped == b.fifo_dropped)
    return {"backend": backend, "samples": int(x.size), "words": int(a.words.size),
            "same_bits": bool(same), "seconds": time.perf_counter() - t0}
