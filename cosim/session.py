"""Persistent front-end sessions: one stepping interface for every HDL backend.

A closed loop needs the front end to stay alive between DSP services: the DSP reads what the
FPGA produced up to some cycle, decides a register write, and the FPGA goes on from that
cycle with the new value. A *session* is a front end that is reset once, then advanced step
by step; its state (the bit-exact model's state, the running ``amaranth.sim`` simulator, the
Verilated model) is kept between steps. Stepping a record in N blocks gives the same words on
the same cycles as one step (tests/cosim/test_pipeline.py).

Interface (:class:`FrontendSession`)::

    with open_frontend("verilator", params) as fe:       # or "model", "pysim"
        r = fe.step(samples, ready=service)              # StepResult: words, cycles, ...
        fe.write("freq", word, cycle=fe.cycle + 40)      # applied before that cycle's edge
        fe.read("overflow_count")                        # port value after the last edge

Conventions (those of :func:`cosim.pysim.run_stream`): cycles are counted from reset; input
words are offered one per cycle, in order, while any are queued (an always-ready input such
as the ADC takes one per cycle, so sample ``k`` is offered at cycle ``k``); a write
``(cycle, port, value)`` sets ``port`` before the clock edge of ``cycle``; output words are
the packed ``o`` payloads of the cycles where ``o.valid and o.ready``.

``ready`` (the DSP's ``o.ready``) is given per step as a bool array (one entry per cycle of
the step; cycles past its end are ready), ``None`` (always ready), or a
:class:`~cosim.link.DspServiceConfig` / :class:`~hdl.model.fifo.ReadySchedule`, a pattern in
cycles from reset (the bit-exact model then steps event by event, without per-cycle arrays).

Backends: a receiver's bit-exact model session (a :class:`FrontendSession` subclass in its
own package, ``cosim/<receiver>/session.py``), :class:`PysimSession` (one
``amaranth.sim`` simulator kept running; any stream component),
:class:`cosim.verilator.VerilatorSession` (the compiled model kept alive; any stream
component). :func:`open_frontend` opens the right one for a front end's parameters, looked up
in the receiver registry (``Receiver.frontend``, a :class:`cosim.receivers.Frontend`).
"""
from __future__ import annotations

import bisect
import contextlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from amaranth.hdl import Value

from dsp.fixed import check_int as _int
from hdl.model.fifo import ReadySchedule

__all__ = ["StepResult", "FrontendSession", "PysimSession", "ready_window", "open_frontend", "open_stream_session", "RegisterSession", "FRONTEND_TYPES",
           "BACKENDS"]

BACKENDS = ("model", "pysim", "verilator")


@dataclass
class StepResult:
    """What one :meth:`FrontendSession.step` produced.

    Attributes
    ----------
    words : ndarray of int64
        Packed ``o`` payloads transferred in this step, in order.
    cycles : ndarray of int64
        Cycle (from reset) of each transfer.
    start : int
        First cycle of the step.
    n_cycles : int
        Cycles simulated.
    in_accepted : int
        Input words accepted in this step.
    """

    words: np.ndarray
    cycles: np.ndarray
    start: int
    n_cycles: int
    in_accepted: int

    @property
    def stop(self) -> int:
        return self.start + self.n_cycles


def ready_window(ready, start: int, n_cycles: int) -> np.ndarray | None:
    """``ready`` for the cycles ``start .. start + n_cycles - 1`` as a bool array (``None``
    stays ``None``: always ready). ``ready``: a bool array for exactly these cycles (shorter:
    ready after its end), a :class:`~cosim.link.DspServiceConfig` (its stalls applied) or a
    :class:`~hdl.model.fifo.ReadySchedule`."""
    from .link import DspServiceConfig
    if ready is None:
        return None
    if isinstance(ready, DspServiceConfig):
        m = ready.schedule.mask(n_cycles, start)
        for a, b in ready.stalls:
            lo, hi = max(a, start), min(b, start + n_cycles)
            if lo < hi:
                m[lo - start:hi - start] = False
        return m
    if isinstance(ready, ReadySchedule):
        return ready.mask(n_cycles, start)
    r = np.asarray(ready, dtype=bool).ravel()
    if r.size > n_cycles:
        raise ValueError(f"ready has {r.size} entries for a step of {n_cycles} cycles")
    if r.size < n_cycles:
        r = np.r_[r, np.ones(n_cycles - r.size, dtype=bool)]
    return r


def fifo_step(wc, w, ready, n: int, start: int, fifo_params, state):
    """The record FIFO model (:func:`hdl.model.fifo.fifo_model_events`, its ``state``
    carried) over cycles ``start .. start + n - 1``, for a model session's ``_step``:
    records ``w`` written at cycles ``wc`` (all ``< start + n``), read with the session's
    ``ready`` (``None``, bool array, :class:`ReadySchedule` or a ``DspServiceConfig``,
    whose service segments are run one by one). Returns ``(words, cycles, state)``."""
    from hdl.model.fifo import fifo_model_events
    from .link import DspServiceConfig
    if isinstance(ready, DspServiceConfig):
        out_w, out_c = [], []
        for a, b, sched in ready.segments(n, start):
            i0, i1 = np.searchsorted(wc, [a, b])
            res = fifo_model_events(wc[i0:i1], w[i0:i1], b - a, sched, fifo_params, state=state)
            state = res.state
            out_w.append(res.words)
            out_c.append(res.cycles)
        return np.concatenate(out_w), np.concatenate(out_c), state
    rdy = ReadySchedule(period=1) if ready is None else (
        ready if isinstance(ready, ReadySchedule) else ready_window(ready, start, n))
    res = fifo_model_events(wc, w, n, rdy, fifo_params, state=state)
    return res.words, res.cycles, res.state


class FrontendSession:
    """A front end reset once and advanced step by step (see the module doc).

    Subclasses implement :meth:`_step`, :meth:`_read` and :meth:`_close`; this base keeps
    the cycle count, the queue of input words not yet accepted and the pending writes.
    """

    backend = ""

    def __init__(self):
        self.cycle = 0
        self._queue = np.zeros(0, np.int64)
        self._pending: list[tuple[int, int, str, int]] = []   # (cycle, seq, port, value)
        self._seq = 0
        #: Every write applied, ``(cycle, port, value)`` in the order applied.
        self.writes_applied: list[tuple[int, str, int]] = []
        self.closed = False

    # -- public ---------------------------------------------------------------------------
    def step(self, in_words=None, ready=None, *, n_cycles: int | None = None) -> StepResult:
        """Advance ``n_cycles`` cycles (default: one per word in ``in_words``).

        Parameters
        ----------
        in_words : array of int, optional
            Input payloads appended to the queue of words still to be offered (a word the
            component does not accept in this step is offered again in the next).
        ready : bool array, DspServiceConfig, ReadySchedule or None
            ``o.ready`` for the cycles of this step (see the module doc).
        n_cycles : int, optional
            Cycles to simulate (>= 0); default ``len(in_words)``.
        """
        self._check_open()
        w = np.zeros(0, np.int64) if in_words is None else np.asarray(in_words)
        if w.size and w.dtype.kind not in "iuO":
            raise ValueError(f"input words must be integers, not dtype {w.dtype}")
        # int64, or Python ints in an object array for payloads wider than 63 bits
        w = (w if w.dtype == object else w.astype(np.int64)).ravel()
        n = w.size if n_cycles is None else _int("n_cycles", n_cycles, 0)
        queue = np.r_[self._queue, w] if self._queue.size else w
        start = self.cycle
        writes = self._take_writes(start + n)
        if n == 0:
            self._queue = queue
            return StepResult(np.zeros(0, np.int64), np.zeros(0, np.int64), start, 0, 0)
        words, cycles, accepted = self._step(queue, ready, n, writes)
        self._queue = queue[accepted:]
        self.cycle = start + n
        words = np.asarray(words)
        if words.dtype != object:
            words = words.astype(np.int64)
        return StepResult(words, np.asarray(cycles, np.int64), start, n, int(accepted))

    def write(self, port: str, value: int, cycle: int | None = None) -> int:
        """Schedule ``port = value`` before the clock edge of ``cycle`` (default: the next
        cycle to run, :attr:`cycle`; a write cannot go into the past). Returns ``cycle``.
        Two writes on one cycle are applied in the order made (the later wins)."""
        self._check_open()
        c = self.cycle if cycle is None else _int("write cycle", cycle, 0)
        if c < self.cycle:
            raise ValueError(f"a write cannot take effect in the past: cycle {c} < the "
                             f"session's cycle {self.cycle}")
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ValueError(f"value written to {port!r} must be an integer, not {value!r}")
        self._check_port(port)
        bisect.insort(self._pending, (c, self._seq, port, int(value)))
        self._seq += 1
        return c

    def read(self, port: str) -> int:
        """Value of the port ``port`` after the last clock edge run."""
        self._check_open()
        return int(self._read(port))

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __del__(self):
        try:
            self.close()
        except Exception:   # interpreter shutdown
            pass

    # -- for subclasses --------------------------------------------------------------------
    def _take_writes(self, stop: int) -> list[tuple[int, str, int]]:
        """Pending writes with ``cycle < stop`` (removed from the queue, recorded)."""
        k = 0
        while k < len(self._pending) and self._pending[k][0] < stop:
            k += 1
        out = [(c, p, v) for c, _, p, v in self._pending[:k]]
        del self._pending[:k]
        self.writes_applied.extend(out)
        return out

    def _check_open(self):
        if self.closed:
            raise RuntimeError(f"the {self.backend} session is closed")

    def _check_port(self, port) -> None:
        pass

    def _step(self, queue, ready, n, writes):   # -> (words, cycles, accepted)
        raise NotImplementedError

    def _read(self, port):
        raise NotImplementedError

    def _close(self):
        pass


# -- Amaranth simulation ------------------------------------------------------------------------
class RegisterSession(FrontendSession):
    """Register-level writes on a front end with a ``reg_we``, ``reg_addr``, ``reg_data``
    bus (any backend): a write of register ``name`` taking effect at cycle ``e`` is the bus
    pulse ``reg_we = 1`` with its address and data at bus cycle ``b = max(e, previous b +
    1)`` and ``reg_we = 0`` at ``b + 1`` (the bus takes one write per cycle, so two
    registers written for the same cycle go out on consecutive cycles, in the order
    written). Each value is checked by ``params.check_write(address, value)`` when written.

    Parameters
    ----------
    inner : FrontendSession
        A fresh session of the front end (model, pysim or verilator); this session owns it
        (closing this closes it).
    params
        The front end's parameters (its ``check_write``).
    names : dict
        Register name -> bus address.
    what : str
        The front end's name in error messages.
    """

    def __init__(self, inner: FrontendSession, params, names: dict, what: str = "front-end"):
        if not isinstance(inner, FrontendSession):
            raise ValueError(f"inner must be a FrontendSession, not {type(inner).__name__}")
        if inner.cycle != 0:
            raise ValueError(f"the inner session must be fresh (at cycle 0), not at "
                             f"{inner.cycle}")
        super().__init__()
        self.inner = inner
        self.params = params
        self.names = dict(names)
        self.what = what
        self.backend = inner.backend
        self._next_bus = 0
        #: Bus writes ``(bus cycle, address, value)`` made, in order.
        self.bus_writes: list[tuple[int, int, int]] = []

    def _check_port(self, port) -> None:
        if port not in self.names:
            raise KeyError(f"{self.what} registers are {', '.join(self.names)}, not {port!r}")

    def write(self, port: str, value: int, cycle: int | None = None) -> int:
        self._check_port(port)
        self.params.check_write(self.names[port], int(value))
        return super().write(port, value, cycle)

    def _step(self, queue, ready, n, writes):
        for c, reg, v in writes:
            b = max(int(c), self._next_bus)
            a = self.names[reg]
            self.inner.write("reg_addr", a, cycle=b)
            self.inner.write("reg_data", int(v), cycle=b)
            self.inner.write("reg_we", 1, cycle=b)
            self.inner.write("reg_we", 0, cycle=b + 1)
            self.bus_writes.append((b, a, int(v)))
            self._next_bus = b + 1
        x = queue[:n]
        r = self.inner.step(x, ready, n_cycles=n)
        if r.in_accepted != x.size:
            raise RuntimeError(f"internal: the {self.what} always-ready input took "
                               f"{r.in_accepted} of {x.size} samples")
        return r.words, r.cycles, r.in_accepted

    def _read(self, port):
        return self.inner.read(port)

    def _close(self):
        self.inner.close()


class PysimSession(FrontendSession):
    """A stream component in one ``amaranth.sim`` simulator, kept running across steps.

    The testbench is the per-cycle loop of :func:`cosim.pysim.run_stream` (same sampling,
    same results), fed from the session: when it reaches the last cycle of a step it waits,
    in simulated time, a quarter period after the clock edge, and :meth:`step` runs the
    simulator (``run_until``) to an eighth of a period after the edge of the step's last
    cycle, i.e. before that wait ends. The next step hands the testbench its stimulus and
    runs on; the waiting only moves when the testbench drives the next cycle's inputs
    within the cycle (before the next edge either way), so the bits are those of one run.

    Parameters
    ----------
    dut : wiring.Component
        Output stream ``o``, optionally an input stream ``i`` (``run_stream``'s convention).
    inputs : dict of port name -> int, optional
        Values set once at reset.
    clk_hz : float
    vcd : path, optional
        Waveform of the whole session (opt-in; written when the session is closed).
    """

    backend = "pysim"

    def __init__(self, dut, *, inputs: dict | None = None, clk_hz: float = 20e6,
                 vcd: str | Path | None = None):
        from amaranth.sim import Simulator
        from .pysim import _items, resolve_port
        super().__init__()
        self.dut = dut
        self._resolve = lambda p: resolve_port(dut, p)
        self._inputs = [(resolve_port(dut, p), int(v)) for p, v in _items(inputs)]
        self._has_in = hasattr(dut, "i")
        self._i_payload = Value.cast(dut.i.payload) if self._has_in else None
        self._o_payload = Value.cast(dut.o.payload)
        self._o_ready_const = not hasattr(dut.o, "ready") or isinstance(dut.o.ready, int) or \
            getattr(dut.o.signature, "always_ready", False)
        self._i_has_ready = self._has_in and not getattr(dut.i.signature, "always_ready", False)
        # Per-step feed, read by the testbench.
        self._feed = {"stop": 0, "queue": np.zeros(0, np.int64), "ready": None, "start": 0,
                      "writes": [], "accepted": 0, "words": [], "cycles": []}
        self._ctx = None
        self._period = 1.0 / clk_hz
        self._sim = Simulator(dut)
        self._sim.add_clock(self._period)
        self._sim.add_testbench(self._testbench, background=True)
        # Rising edge of cycle k, as the simulator's clock computes it (integer femtoseconds).
        period_fs = int(self._period * 1e15)
        self._phase_fs, self._half_fs = int(self._period / 2 * 1e15), period_fs // 2
        self._stack = contextlib.ExitStack()
        if vcd is not None:
            Path(vcd).parent.mkdir(parents=True, exist_ok=True)
            self._stack.enter_context(self._sim.write_vcd(str(vcd)))

    def _edge_s(self, k: int) -> float:
        return (self._phase_fs + 2 * k * self._half_fs) / 1e15

    async def _testbench(self, ctx):
        self._ctx = ctx
        f = self._feed
        dut = self.dut
        for port, value in self._inputs:
            ctx.set(port, value)
        cyc = 0
        wait = self._period / 4
        while True:
            while cyc >= f["stop"]:           # end of the step: wait for the next one
                await ctx.delay(wait)
            writes = f["writes"]
            while writes and writes[0][0] <= cyc:
                _, port, value = writes.pop(0)
                ctx.set(port, value)
            offer = False
            if self._has_in:
                k = f["accepted"]
                offer = k < len(f["queue"])
                ctx.set(dut.i.valid, 1 if offer else 0)
                if offer:
                    ctx.set(self._i_payload, int(f["queue"][k]))
            if not self._o_ready_const:
                r = f["ready"]
                rdy = True if r is None else bool(r[cyc - f["start"]])
                ctx.set(dut.o.ready, 1 if rdy else 0)
            sampled = [dut.o.valid, self._o_payload]
            if not self._o_ready_const:
                sampled.append(dut.o.ready)
            if self._i_has_ready:
                sampled.append(dut.i.ready)
            res = await ctx.tick().sample(*sampled)
            vals = list(res[-len(sampled):])
            o_valid, o_pay = vals[0], vals[1]
            idx = 2
            o_rdy = 1
            if not self._o_ready_const:
                o_rdy = vals[idx]
                idx += 1
            i_rdy = vals[idx] if self._i_has_ready else 1
            if o_valid and o_rdy:
                f["words"].append(int(o_pay))
                f["cycles"].append(cyc)
            if offer and i_rdy:
                f["accepted"] += 1
            cyc += 1

    def _check_port(self, port) -> None:
        self._resolve(port)

    def _step(self, queue, ready, n, writes):
        f = self._feed
        start = self.cycle
        f.update(stop=start + n, queue=queue, ready=ready_window(ready, start, n), start=start,
                 writes=[(c, self._resolve(p), v) for c, p, v in writes], accepted=0,
                 words=[], cycles=[])
        self._sim.run_until(self._edge_s(start + n - 1) + self._period / 8)
        if f["writes"]:
            raise RuntimeError("internal: writes left over after a pysim step")
        wide = len(self._o_payload) > 63
        words = np.array(f["words"], dtype=object if wide else np.int64)
        return words, f["cycles"], f["accepted"]

    def _read(self, port):
        if self._ctx is None:       # nothing simulated yet: the reset value
            sig = self._resolve(port)
            return getattr(sig, "init", 0)
        return self._ctx.get(self._resolve(port))

    def _close(self):
        self._stack.close()


# -- opening sessions ---------------------------------------------------------------------------
#: Front ends :func:`open_frontend` knows besides the registered receivers' (parameter
#: class -> :class:`cosim.receivers.Frontend`); a receiver declares its front end in its
#: registry entry (``Receiver.frontend``), which is looked up after this dict.
FRONTEND_TYPES: dict = {}


def _frontend_entry(params):
    for cls, entry in FRONTEND_TYPES.items():
        if isinstance(params, cls):
            return entry
    from .receivers import frontend_for
    return frontend_for(params)


def open_stream_session(backend: str, dut, *, name: str = "dut", inputs: dict | None = None,
                        vcd: str | Path | None = None, **kw) -> FrontendSession:
    """A session of any stream component on ``"pysim"`` or ``"verilator"``."""
    if backend == "pysim":
        return PysimSession(dut, inputs=inputs, vcd=vcd, **kw)
    if backend == "verilator":
        if vcd is not None:
            raise NotImplementedError("waveforms of a Verilator session: use "
                                      "VerilatorStreamSim.run(trace=...) for one run")
        from .verilator import VerilatorStreamSim
        return VerilatorStreamSim(dut, name=name, **kw).open(inputs=inputs)
    raise ValueError(f"backend must be pysim or verilator for a component, not {backend!r}")


def open_frontend(backend: str, params, *, log_ranges: bool = False,
                  vcd: str | Path | None = None) -> FrontendSession:
    """A front-end session for ``params`` (an instance of a registered front end's parameter
    class, :class:`cosim.receivers.Frontend`) on ``backend`` (``"model"``, ``"pysim"`` or
    ``"verilator"``), reset, with its control ports at their reset values
    (``Frontend.inputs``)."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, not {backend!r}")
    entry = _frontend_entry(params)
    if backend == "model":
        if vcd is not None:
            raise ValueError("the bit-exact model has no waveform; use pysim or verilator")
        return entry.model(params, log_ranges=log_ranges)
    return open_stream_session(backend, entry.component(params), name=entry.verilog_name,
                               inputs=entry.reset_inputs(params), vcd=vcd)
