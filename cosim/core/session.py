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

Conventions (those of :func:`cosim.backends.pysim.run_stream`): cycles are counted from reset; input
words are offered one per cycle, in order, while any are queued (an always-ready input such
as the ADC takes one per cycle, so sample ``k`` is offered at cycle ``k``); a write
``(cycle, port, value)`` sets ``port`` before the clock edge of ``cycle``; output words are
the packed ``o`` payloads of the cycles where ``o.valid and o.ready``.

``ready`` (the DSP's ``o.ready``) is given per step as a bool array (one entry per cycle of
the step; cycles past its end are ready), ``None`` (always ready), or a
:class:`~cosim.core.link.DspServiceConfig` / :class:`~hdl.model.fifo.ReadySchedule`, a pattern in
cycles from reset (the bit-exact model then steps event by event, without per-cycle arrays).

Backends: a receiver's bit-exact model session (a :class:`FrontendSession` subclass in its
own package, ``cosim/<receiver>/session.py``; :class:`BusModelSession` gives a model with a
register bus its bus ports), :class:`cosim.backends.pysim.PysimSession` (one
``amaranth.sim`` simulator kept running; any stream component),
:class:`cosim.backends.verilator.VerilatorSession` (the compiled model kept alive; any stream
component). :func:`cosim.backends.factory.open_frontend` opens the right one for a front
end's parameters, looked up in the receiver registry (``Receiver.frontend``, a
:class:`cosim.core.receivers.Frontend`). This module holds the interface every backend
implements and imports none of them.
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass

import numpy as np

from dsp.fixed import check_int as _int
from hdl.model.fifo import ReadySchedule

__all__ = ["StepResult", "FrontendSession", "RegisterSession", "BusModelSession", "BUS_PORTS",
           "write_register", "ready_window", "fifo_step"]


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
    ready after its end), a :class:`~cosim.core.link.DspServiceConfig` (its stalls applied) or a
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
        if cycle is None:
            c = self.cycle
        else:   # (a plain int needs no more checks than its sign)
            c = cycle if type(cycle) is int and cycle >= 0 else _int("write cycle", cycle, 0)
        if c < self.cycle:
            raise ValueError(f"a write cannot take effect in the past: cycle {c} < the "
                             f"session's cycle {self.cycle}")
        if type(value) is not int and (isinstance(value, bool)
                                       or not isinstance(value, (int, np.integer))):
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


# -- register-level writes ----------------------------------------------------------------------
class RegisterSession(FrontendSession):
    """Register-level writes on a front end with a ``reg_we``, ``reg_addr``, ``reg_data``
    bus (any backend): a write of register ``name`` taking effect at cycle ``e`` is the bus
    pulse ``reg_we = 1`` with its address and data at bus cycle ``b = max(e, previous b +
    1)`` and ``reg_we = 0`` at ``b + 1`` (the bus takes one write per cycle, so two
    registers written for the same cycle go out on consecutive cycles, in the order
    written). Each value is checked by the register map's
    :meth:`~dsp.register_map.RegisterMap.check_write` when written.

    Parameters
    ----------
    inner : FrontendSession
        A fresh session of the front end (model, pysim or verilator); this session owns it
        (closing this closes it).
    registers : dsp.register_map.RegisterMap
        The front end's register map (its params' ``registers``): names, bus addresses,
        write checks and its name in error messages.
    """

    def __init__(self, inner: FrontendSession, registers):
        if not isinstance(inner, FrontendSession):
            raise ValueError(f"inner must be a FrontendSession, not {type(inner).__name__}")
        if inner.cycle != 0:
            raise ValueError(f"the inner session must be fresh (at cycle 0), not at "
                             f"{inner.cycle}")
        super().__init__()
        self.inner = inner
        self.registers = registers
        self.what = registers.what
        self.backend = inner.backend
        self._next_bus = 0
        #: Bus writes ``(bus cycle, address, value)`` made, in order.
        self.bus_writes: list[tuple[int, int, int]] = []

    def _check_port(self, port) -> None:
        self.registers.address(port)   # KeyError naming the registers

    def write(self, port: str, value: int, cycle: int | None = None) -> int:
        self._check_port(port)
        self.registers.check_write(self.registers.address(port), value)
        return super().write(port, value, cycle)

    def _bus_write(self, b: int, a: int, v: int) -> None:
        """Register write ``a = v`` on the inner session's bus at cycle ``b``: its port
        writes (a subclass may hand the inner session the write whole)."""
        write_register(self.inner, a, v, b)

    def _step(self, queue, ready, n, writes):
        for c, reg, v in writes:
            b = max(int(c), self._next_bus)
            a = self.registers.address(reg)
            self._bus_write(b, a, int(v))
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


# -- register bus -------------------------------------------------------------------------------
#: The register bus ports of a front end with a register bus (the only writable ports of its
#: bit-exact model).
BUS_PORTS = ("reg_we", "reg_addr", "reg_data")


def write_register(fe: FrontendSession, reg: int, value: int, cycle: int | None = None) -> int:
    """One bus write on any backend's session: ``reg_we`` high in ``cycle`` (default the
    session's next cycle) with ``reg_addr = reg``, ``reg_data = value``, low again the cycle
    after. Returns the cycle."""
    c = fe.write("reg_addr", reg, cycle)
    fe.write("reg_data", value, c)
    fe.write("reg_we", 1, c)
    fe.write("reg_we", 0, c + 1)
    return c


class BusModelSession(FrontendSession):
    """The port side of a bit-exact model session whose front end has a register bus
    (:data:`BUS_PORTS`) and a record FIFO: writes go to the bus ports only; reads are
    ``overflow_count`` (records the FIFO dropped) and the bus ports' current values.

    A subclass sets :attr:`what` (its name in error messages), calls ``super().__init__()``
    and implements :meth:`_step`; it keeps its FIFO state in ``_fifo_state`` (a
    :class:`hdl.model.fifo.FifoState`, exposed as :attr:`fifo_state`) and the bus values in
    ``_bus`` (set up here, all zero).
    """

    #: The model's name in error messages.
    what = "front-end model"

    def __init__(self):
        from hdl.model.fifo import FifoState
        super().__init__()
        self._fifo_state = FifoState()
        self._bus = {port: 0 for port in BUS_PORTS}
        #: The bus ports' widths (bits), set by a subclass that uses :meth:`_bus_cycles`.
        self._widths: dict[str, int] = {}

    def _bus_cycles(self, writes, start, stop):
        """The register writes ``(cycle, reg, value)`` the bus ports make in the cycles
        ``start .. stop - 1`` (a write on every cycle ``reg_we`` is high), from the port writes
        ``(cycle, port, value)`` of a step (sorted by cycle); a value wider than its port is
        refused."""
        out = []
        c, k = start, 0
        while c < stop:
            while k < len(writes) and writes[k][0] <= c:
                _, port, v = writes[k]
                if not 0 <= v < 1 << self._widths[port]:
                    raise ValueError(f"{port} takes unsigned {self._widths[port]}-bit values, "
                                     f"not {v}")
                self._bus[port] = v
                k += 1
            nxt = writes[k][0] if k < len(writes) else stop
            if self._bus["reg_we"]:
                out += [(cc, self._bus["reg_addr"], self._bus["reg_data"])
                        for cc in range(c, nxt)]
            c = nxt
        return out

    @property
    def fifo_state(self):
        return self._fifo_state

    def _check_port(self, port) -> None:
        if port not in BUS_PORTS:
            raise KeyError(f"the {self.what}'s writable ports are "
                           f"{', '.join(BUS_PORTS)}, not {port!r}")

    def _read(self, port):
        if port == "overflow_count":
            return self._fifo_state.overflow
        if port in self._bus:
            return self._bus[port]
        raise KeyError(f"the {self.what} reads overflow_count and "
                       f"{', '.join(BUS_PORTS)}, not {port!r}")
