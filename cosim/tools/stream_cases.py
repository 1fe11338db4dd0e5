"""The exported designs and, for each, a seeded stimulus with the bit-exact model's answer.

:func:`exported_designs` is the registry of what ``python -m cosim verilog`` exports: every
HDL block of the TACAN front end (with the parameters the front end uses) and every
registered receiver's tops. :func:`stream_case` gives, for one of them, a
:class:`StreamCase`: input words, ``valid`` and ``ready`` per cycle, constant inputs and
register writes, and the output words and their cycles the bit-exact model predicts. The
cocotb tests run every case on Icarus Verilog (``tests/cosim/test_cocotb_blocks.py``,
parametrised over :data:`BLOCK_CASES` and :func:`top_case_names`), and
``python -m cosim verilog --cocotb`` writes a case's files beside the Verilog
(:mod:`cosim.tools.cocotb_export`).

Block stimulus: seeded random words with a share at full scale of either sign, gaps in
``valid``, run-time writes (NCO and DDC frequency), an input at the guaranteed cadence (the
time-shared FIR), a long carrier the peak search must cut, and for the FIFO bursts of reads
and writes with a stall long enough to overflow it (records dropped and counted). The
expected cycles follow each block's timing rule (a fixed latency after the input that
completes an output; the FIFO's cycle model gives its own).

Top stimulus (:mod:`cosim.tools.top_cases`): each top's equivalence-check record (a TACAN
IF record, a GPS L1 C/A record, random monopulse ADC codes) with the register writes the
closed loop makes (NCO word; carrier and code words, PRN, slew on every GNSS channel;
monopulse coefficients and steering), seeded stalls, run from reset on the bit-exact model;
``short=True`` the same HDL at reduced parameters on a record of a few thousand cycles (the
check ``make test`` runs on Icarus).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

__all__ = ["StreamCase", "BLOCK_CASES", "exported_designs", "stream_case", "top_case_names"]


@dataclass(frozen=True)
class StreamCase:
    """One design's stimulus and the bit-exact model's output.

    Attributes
    ----------
    name : str
        Verilog module name (a key of :func:`exported_designs`).
    make : callable
        ``make()`` -> the Amaranth component.
    in_words : ndarray or None
        Input payloads (packed; signed payloads as signed ints), None without an input stream.
    in_valid, out_ready : ndarray of bool or None
        Per cycle from reset (``valid`` after its end; ``ready`` after its end).
    n_cycles : int
        Cycles to run.
    inputs : dict
        Constant input ports (Verilog name -> value).
    writes : tuple
        ``(cycle, port, value)`` set before that cycle's edge, in cycle order.
    words, cycles : ndarray
        The model's output words (packed, as the port reads them) and their cycles.
    """

    name: str
    make: Callable
    in_words: np.ndarray | None
    in_valid: np.ndarray | None
    out_ready: np.ndarray | None
    n_cycles: int
    words: np.ndarray
    cycles: np.ndarray
    inputs: dict = field(default_factory=dict)
    writes: tuple = ()


def _tacan():
    from hdl.tacan.params import TacanFrontendParams
    return TacanFrontendParams()


def exported_designs() -> dict:
    """Every exported design by Verilog module name: the HDL blocks (the TACAN front end's
    parameters) and every receiver's tops (its registry entry's ``tops``); values make the
    component."""
    from hdl.cic import Cic
    from hdl.ddc import Ddc
    from hdl.envelope import Envelope
    from hdl.fifo import DspFifo
    from hdl.fir import Fir
    from hdl.mixer import Mixer
    from hdl.nco import Nco
    from hdl.tacan.peak import PeakSearch
    from ..core.receivers import receivers
    p = _tacan()
    designs = {
        "nco": lambda: Nco(p.ddc.nco),
        "mixer": lambda: Mixer(p.ddc.mixer),
        "ddc": lambda: Ddc(p.ddc),
        "cic": lambda: Cic(p.cic),
        "fir": lambda: Fir(p.fir),
        "envelope": lambda: Envelope(p.envelope),
        "peak": lambda: PeakSearch(p.peak),
        "fifo": lambda: DspFifo(p.fifo),
    }
    for r in receivers():
        designs.update(r.tops)
    return designs


# -- stimulus helpers --------------------------------------------------------------------------
def _signed(rng, width: int, n: int, full_scale: float = 0.1, shape=()) -> np.ndarray:
    """Uniform signed ``width``-bit ints, a share ``full_scale`` at either full scale."""
    lo, hi = -(1 << (width - 1)), (1 << (width - 1)) - 1
    v = rng.integers(lo, hi + 1, (n, *shape))
    fs = rng.random(v.shape) < full_scale
    v[fs] = rng.choice([lo, hi], int(np.count_nonzero(fs)))
    return v


def _gaps(rng, n: int, p_valid: float = 0.8) -> np.ndarray:
    """``valid`` with random gaps and one long gap (enough cycles for ``n`` words)."""
    v = rng.random(int(n / p_valid) + 200) < p_valid
    v[len(v) // 3:len(v) // 3 + 40] = False
    return v


def _taken(n: int, valid) -> np.ndarray:
    """The cycle each of ``n`` words is taken by an always-ready input under ``valid``
    (offered every cycle after its end)."""
    cyc = np.flatnonzero(np.asarray(valid, bool))[:n]
    return np.r_[cyc, len(valid) + np.arange(n - len(cyc))]


def _at(cycles, writes, port, default=0) -> np.ndarray:
    """The value of ``port`` in each of ``cycles`` after ``writes``."""
    out = np.full(len(cycles), default, np.int64)
    for c, pt, v in sorted(w for w in writes if w[1] == port):
        out[cycles >= c] = v
    return out


def _freq_writes(rng, n: int, bits: int, k: int = 6) -> list:
    writes = [(0, "freq", int(rng.integers(0, 1 << bits)))]
    writes += [(int(c), "freq", int(rng.integers(0, 1 << bits)))
               for c in np.sort(rng.choice(np.arange(1, n), k, replace=False))]
    return writes


def _iq(i, q, width):
    from ..backends.pysim import pack_fields
    return pack_fields({"i": i, "q": q}, [("i", width, True), ("q", width, True)])


# -- the blocks --------------------------------------------------------------------------------
def _nco(rng, n):
    from hdl.model.nco import NcoModel
    p = _tacan().ddc.nco
    valid = _gaps(rng, n)
    writes = _freq_writes(rng, len(valid), p.phase_bits)
    taken = _taken(n, valid)
    cos, sin, _ = NcoModel(p).run(n, _at(taken, writes, "freq"))
    from ..backends.pysim import pack_fields
    words = pack_fields({"cos": cos, "sin": sin}, [("cos", p.amp_bits, True),
                                                   ("sin", p.amp_bits, True)])
    return dict(in_words=np.zeros(n, np.int64), in_valid=valid, words=words,
                cycles=taken + p.latency, writes=writes, n_cycles=len(valid) + p.latency + 4)


def _mixer(rng, n):
    from hdl.model.mixer import MixerModel
    from ..backends.pysim import pack_fields
    p = _tacan().ddc.mixer
    f = {"x": _signed(rng, p.in_width, n), "cos": _signed(rng, p.lo_width, n),
         "sin": _signed(rng, p.lo_width, n)}
    x = pack_fields(f, [("x", p.in_width, True), ("cos", p.lo_width, True),
                        ("sin", p.lo_width, True)])
    valid = _gaps(rng, n)
    i, q = MixerModel(p).run(f["x"], f["cos"], f["sin"])
    return dict(in_words=x, in_valid=valid, words=_iq(i, q, p.out_width),
                cycles=_taken(n, valid) + p.latency, n_cycles=len(valid) + p.latency + 4)


def _ddc(rng, n):
    from hdl.model.ddc import DdcModel
    p = _tacan().ddc
    x = _signed(rng, p.adc_width, n)
    valid = _gaps(rng, n)
    writes = _freq_writes(rng, len(valid), p.freq_width)
    taken = _taken(n, valid)
    i, q, _ = DdcModel(p).run(x, _at(taken, writes, "freq"))
    latency = p.latency
    return dict(in_words=x, in_valid=valid, words=_iq(i, q, p.out_width),
                cycles=taken + latency, writes=writes, n_cycles=len(valid) + latency + 4)


def _decimator(p, model, rng, n, valid):
    """A CIC or FIR (``p.channels`` real or complex samples): ``model(p, x)``'s words, each
    ``p.latency`` cycles after the input that completes it (one per decimation)."""
    x = _signed(rng, p.in_width, n, shape=(2,))
    if p.channels == 1:
        x = x[:, 0]
        y, _ = model(p, x)
        xin, words = x, np.asarray(y, np.int64)
    else:
        y, _ = model(p, x)
        xin, words = _iq(x[:, 0], x[:, 1], p.in_width), _iq(y[:, 0], y[:, 1], p.out_width)
    d = getattr(p, "rate", None) or p.decimation
    return dict(in_words=xin, in_valid=valid, words=words,
                cycles=_taken(n, valid)[d - 1::d] + p.latency,
                n_cycles=len(valid) + p.latency + 4)


def _cic(rng, n):
    from hdl.model.cic import cic_model
    return _decimator(_tacan().cic, cic_model, rng, n, _gaps(rng, n))


def _fir(rng, n):
    from hdl.model.fir import fir_model
    p = _tacan().fir
    # the time-shared multipliers take one input per input_spacing cycles, sometimes fewer
    gaps = p.input_spacing + rng.integers(0, 4, n) * (rng.random(n) < 0.3)
    idx = np.cumsum(gaps)
    valid = np.zeros(idx[-1] + 1, bool)
    valid[idx] = True
    return _decimator(p, fir_model, rng, n, valid)


def _envelope(rng, n):
    from hdl.model.envelope import envelope_model
    p = _tacan().envelope
    i, q = _signed(rng, p.in_width, n, 0.2), _signed(rng, p.in_width, n, 0.2)
    valid = _gaps(rng, n)
    return dict(in_words=_iq(i, q, p.in_width), in_valid=valid,
                words=np.asarray(envelope_model(i, q, p), np.int64),
                cycles=_taken(n, valid) + p.latency, n_cycles=len(valid) + p.latency + 4)


def _peak(rng, n):
    from hdl.tacan.peak_model import peak_search
    from ..backends.pysim import pack_fields
    p = _tacan().peak
    noise = 200.0
    e = rng.rayleigh(noise / np.sqrt(np.pi / 2), n)        # Rayleigh noise, mean `noise`
    centres = np.cumsum(rng.integers(21, 150, n // 21 + 1))
    centres = centres[centres < n]
    k = np.arange(-20, 21)
    pulse = np.exp(-0.5 * (k / 4.25) ** 2)                 # 10 samples FWHM
    for c, a in zip(centres, rng.uniform(2.0, 20.0, centres.size) * noise):
        lo, hi = max(c - 20, 0), min(c + 21, n)
        e[lo:hi] += a * pulse[lo - c + 20:hi - c + 20]
    e[n // 2:n // 2 + 700] = 2500                          # a carrier: cut at max_len
    e = np.minimum(np.round(e), (1 << p.amp_width) - 1).astype(np.int64)
    valid = _gaps(rng, n, 0.7)
    ref, _ = peak_search(e, p)
    words = pack_fields({name: getattr(ref, name) for name, _, _ in p.out_layout}, p.out_layout)
    return dict(in_words=e, in_valid=valid, words=words,
                cycles=_taken(n, valid)[ref.end_index] + p.latency,
                n_cycles=len(valid) + p.latency + 4)


def _fifo(rng, n_cycles):
    from hdl.model.fifo import fifo_model
    p = _tacan().fifo

    def bursts(mean, p_on, p_fine):
        on = np.repeat(rng.random(n_cycles // mean + 1) < p_on, mean)[:n_cycles]
        return on & (rng.random(n_cycles) < p_fine)
    valid, ready = bursts(20, 0.6, 0.8), bursts(15, 0.6, 0.8)
    ready[n_cycles // 4:n_cycles // 4 + p.depth * 3] = False   # a stall: the FIFO overflows
    words = rng.integers(0, 1 << p.width, int(valid.sum()))
    ref = fifo_model(words, valid, ready, p)
    return dict(in_words=words, in_valid=valid, out_ready=ready, words=ref.words,
                cycles=ref.cycles, n_cycles=n_cycles)


#: Each block's case: ``(make_case(rng, size), default size)`` (size: input words, or
#: cycles for the FIFO).
BLOCK_CASES: dict[str, tuple[Callable, int]] = {
    "nco": (_nco, 1000), "mixer": (_mixer, 1000), "ddc": (_ddc, 1000), "cic": (_cic, 1200),
    "fir": (_fir, 300), "envelope": (_envelope, 1000), "peak": (_peak, 5000),
    "fifo": (_fifo, 3000),
}


# -- the tops ---------------------------------------------------------------------------------
def top_case_names() -> tuple:
    """The tops :func:`stream_case` has a case for (the receivers' ``stream_cases``,
    :func:`cosim.tools.top_cases.top_cases`)."""
    from .top_cases import top_cases
    return tuple(top_cases())


def stream_case(name: str, *, seed: int = 1, size: int | None = None,
                short: bool = False) -> StreamCase:
    """The case of design ``name`` (a key of :data:`BLOCK_CASES` or :func:`top_case_names`):
    seeded stimulus and the bit-exact model's words and cycles. ``size``: input words (the
    FIFO: cycles; a top: ADC samples); default the design's own. ``short`` (tops only): the
    top's HDL at the reduced parameters of its equivalence check on a short record, the
    check ``make test`` runs (:mod:`cosim.tools.top_cases`); default the registered top as
    exported."""
    designs = exported_designs()
    tops = top_case_names()
    if name not in BLOCK_CASES and name not in tops:
        have = ", ".join([*BLOCK_CASES, *tops])
        raise ValueError(f"no stream case for {name!r}; cases: {have}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, not {seed!r}")
    if size is not None and (isinstance(size, bool) or not isinstance(size, (int, np.integer))
                             or size < 1):
        raise ValueError(f"size must be an integer >= 1, not {size!r}")
    def rng():
        return np.random.default_rng([int(seed), sum(map(ord, name))])
    if name in BLOCK_CASES:
        if short:
            raise ValueError(f"short is for the tops, not the block {name!r}")
        make_case, default = BLOCK_CASES[name]
        d = make_case(rng(), int(size or default))
    else:
        from .top_cases import top_case
        d = top_case(name, designs[name], int(seed), size, short)
    return StreamCase(name=name, make=d.get("make", designs[name]), in_words=d["in_words"],
                      in_valid=d.get("in_valid"), out_ready=d.get("out_ready"),
                      n_cycles=int(d["n_cycles"]), words=np.asarray(d["words"]),
                      cycles=np.asarray(d["cycles"], np.int64), inputs=d.get("inputs", {}),
                      writes=tuple(d.get("writes", ())))
