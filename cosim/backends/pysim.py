"""Cycle-accurate simulation of a stream component with Amaranth's Python simulator.

Convention for every block and top that the simulation backends run: a component with an
input stream port ``i`` and an output stream port ``o`` (``amaranth.lib.stream``). Payloads
travel as packed integers (the bits of ``Value.cast(payload)``, LSB first, as
``amaranth.lib.data`` lays out a struct), so the same numpy arrays drive this backend, the
Verilator backend and the bit-exact models. Other input ports can be held at constant values
(``inputs``) or changed at given cycles (``writes``: register writes from the DSP side).

This backend steps Python once per clock. It is the reference for the compiled backend and
for short runs only (about 1e4..1e5 cycles/s). :func:`run_stream` runs one record;
:class:`PysimSession` keeps one simulator running across steps
(:class:`cosim.core.session.FrontendSession`).
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from amaranth.hdl import Value, ValueCastable
from amaranth.sim import Simulator

from ..core.session import FrontendSession, ready_window


@dataclass
class StreamResult:
    """What came out of the ``o`` stream.

    Attributes
    ----------
    words : ndarray of int64 (or object for payloads wider than 63 bits)
        Packed payload of each output transfer, in order.
    cycles : ndarray of int64
        Clock cycle (0-based) at which each output transfer happened.
    n_cycles : int
        Cycles simulated.
    in_accepted : int
        Input words the component accepted.
    probes : dict of str to ndarray
        Per-cycle values of signals asked for with ``probe``.
    final : dict of str to int
        Values of the signals asked for with ``final``, after the last clock edge (e.g. a
        status counter, without recording it every cycle).
    """

    words: np.ndarray
    cycles: np.ndarray
    n_cycles: int
    in_accepted: int
    probes: dict = field(default_factory=dict)
    final: dict = field(default_factory=dict)


def unpack_fields(words: np.ndarray, layout: list[tuple[str, int, bool]]) -> dict[str, np.ndarray]:
    """Split packed payload words into named integer fields.

    ``layout`` lists ``(name, width, signed)`` from the LSB up, as ``data.StructLayout``
    places its fields in declaration order.
    """
    words = np.asarray(words)
    out = {}
    offset = 0
    for name, width, signed in layout:
        if words.dtype == object:
            vals = np.array([(int(w) >> offset) & ((1 << width) - 1) for w in words], dtype=np.int64)
        else:
            vals = (words.astype(np.int64) >> np.int64(offset)) & np.int64((1 << width) - 1)
        if signed:
            vals = np.where(vals >= (1 << (width - 1)), vals - (1 << width), vals)
        out[name] = vals.astype(np.int64)
        offset += width
    return out


def pack_fields(fields: dict[str, np.ndarray], layout: list[tuple[str, int, bool]]) -> np.ndarray:
    """Inverse of :func:`unpack_fields`: int64 words up to 63 bits, an object array of
    Python ints for wider payloads."""
    total = sum(w for _, w, _ in layout)
    if total > 63:
        out = 0
        offset = 0
        for name, width, _signed in layout:
            v = np.array([int(x) & ((1 << width) - 1) for x in np.asarray(fields[name]).ravel()],
                         dtype=object)
            out = out + v * (1 << offset)
            offset += width
        return np.asarray(out, dtype=object)
    out = None
    offset = 0
    for name, width, _signed in layout:
        v = np.asarray(fields[name], dtype=np.int64) & np.int64((1 << width) - 1)
        out = (v << np.int64(offset)) if out is None else out | (v << np.int64(offset))
        offset += width
    return out


def resolve_port(dut, port):
    """``port`` as a ``Value``: a ``Value``/``ValueCastable`` of ``dut`` as is, or a port name
    as the Verilog export spells it (signature path joined with ``__``, e.g. ``"freq"``,
    ``"ctrl__step"``)."""
    if isinstance(port, str):
        for path, _member, value in dut.signature.flatten(dut):
            if "__".join(map(str, path)) == port:
                return value.as_value() if isinstance(value, ValueCastable) else value
        raise KeyError(f"{dut!r} has no port named {port!r}")
    return port


def input_items(inputs) -> list:
    """Constant ``inputs`` as a list of ``(port, value)`` pairs: a dict (port names as keys)
    or already pairs (Amaranth values are unhashable, so inputs keyed by ``Value`` objects
    come as pairs); ``None`` is no input."""
    if inputs is None:
        return []
    return list(inputs.items()) if isinstance(inputs, dict) else list(inputs)


def run_stream(dut, in_words=None, *, in_valid=None, out_ready=None, n_cycles=None,
               flush_cycles: int = 64, inputs: dict | list | None = None,
               writes: list | None = None, probe: dict | None = None,
               final: dict | None = None, clk_hz: float = 20e6, vcd: str | Path | None = None,
               vcd_window: tuple[int, int] | None = None) -> StreamResult:
    """Run ``dut`` cycle by cycle in ``amaranth.sim`` and collect its output stream.

    Parameters
    ----------
    dut : wiring.Component
        Has ``o`` (output stream) and, unless ``in_words`` is None, ``i`` (input stream).
    in_words : array of int, optional
        Packed input payloads, offered in order.
    in_valid : array of bool, optional
        Per-cycle: offer the next input word this cycle (default: every cycle). When the
        pattern runs out, input is offered every cycle.
    out_ready : array of bool, optional
        Per-cycle ``o.ready`` (default: always ready). Ignored if ``o`` is always-ready.
    n_cycles : int, optional
        Cycles to run; default: until every input is accepted, plus ``flush_cycles``.
    inputs : dict of port name -> int, or list of (port, int)
        Constant values for other input ports (port names as in the Verilog export, or
        ``Value`` objects of ``dut`` given as pairs: Amaranth values are unhashable).
    writes : list of (cycle, port, value)
        Register writes: ``port`` (name or ``Value``) takes ``value`` from ``cycle`` on.
    probe : dict of name -> Value
        Signals to record every cycle (sampled at the clock edge).
    final : dict of name -> Value or port name
        Signals to read once, after the last clock edge (``StreamResult.final``).
    vcd : path, optional
        Write a waveform (opt-in; place it under ``build/``). ``vcd_window`` is not
        supported by amaranth's VCD writer and is recorded whole.
    """
    in_words = None if in_words is None else np.asarray(in_words)
    n_in = 0 if in_words is None else len(in_words)
    in_valid = None if in_valid is None else np.asarray(in_valid, dtype=bool)
    out_ready = None if out_ready is None else np.asarray(out_ready, dtype=bool)
    writes = sorted(((c, resolve_port(dut, p), v) for c, p, v in (writes or [])),
                    key=lambda w: w[0])
    inputs = [(resolve_port(dut, p), v) for p, v in input_items(inputs)]
    probe = dict(probe or {})
    final = {k: resolve_port(dut, v) for k, v in (final or {}).items()}
    final_vals: dict[str, int] = {}
    has_in = in_words is not None

    i_payload = Value.cast(dut.i.payload) if has_in else None
    o_payload = Value.cast(dut.o.payload)
    o_ready_const = not hasattr(dut.o, "ready") or isinstance(dut.o.ready, int) or \
        getattr(dut.o.signature, "always_ready", False)
    i_has_ready = has_in and not getattr(dut.i.signature, "always_ready", False)

    out_words: list[int] = []
    out_cycles: list[int] = []
    probe_vals = {k: [] for k in probe}
    state = {"accepted": 0, "cycles": 0}

    async def testbench(ctx):
        for port, value in inputs:
            ctx.set(port, value)
        w_idx = 0
        cyc = 0
        flush_left = flush_cycles
        while True:
            if n_cycles is not None and cyc >= n_cycles:
                break
            if n_cycles is None and state["accepted"] >= n_in:
                if flush_left <= 0:
                    break
                flush_left -= 1
            while w_idx < len(writes) and writes[w_idx][0] <= cyc:
                ctx.set(writes[w_idx][1], writes[w_idx][2])
                w_idx += 1
            offer = False
            if has_in:
                k = state["accepted"]
                offer = k < n_in and (in_valid is None or cyc >= len(in_valid) or bool(in_valid[cyc]))
                ctx.set(dut.i.valid, 1 if offer else 0)
                if offer:
                    ctx.set(i_payload, int(in_words[k]))
            if not o_ready_const:
                rdy = True if out_ready is None or cyc >= len(out_ready) else bool(out_ready[cyc])
                ctx.set(dut.o.ready, 1 if rdy else 0)
            sampled = [dut.o.valid, o_payload]
            if not o_ready_const:
                sampled.append(dut.o.ready)
            if i_has_ready:
                sampled.append(dut.i.ready)
            sampled.extend(probe.values())
            res = await ctx.tick().sample(*sampled)
            vals = list(res[-len(sampled):])  # (clk, rst, *sampled)
            o_valid, o_pay = vals[0], vals[1]
            idx = 2
            o_rdy = 1
            if not o_ready_const:
                o_rdy = vals[idx]
                idx += 1
            i_rdy = 1
            if i_has_ready:
                i_rdy = vals[idx]
                idx += 1
            for name, v in zip(probe, vals[idx:]):
                probe_vals[name].append(int(v))
            if o_valid and o_rdy:
                out_words.append(int(o_pay))
                out_cycles.append(cyc)
            if offer and i_rdy:
                state["accepted"] += 1
            cyc += 1
        state["cycles"] = cyc
        for name, sig in final.items():
            final_vals[name] = int(ctx.get(sig))

    sim = Simulator(dut)
    sim.add_clock(1.0 / clk_hz)
    sim.add_testbench(testbench)
    if vcd is not None:
        Path(vcd).parent.mkdir(parents=True, exist_ok=True)
        with sim.write_vcd(str(vcd)):
            sim.run()
    else:
        sim.run()

    width = len(o_payload)
    if width <= 63:
        words = np.array(out_words, dtype=np.int64)
    else:
        words = np.array(out_words, dtype=object)
    return StreamResult(words=words, cycles=np.array(out_cycles, dtype=np.int64),
                        n_cycles=state["cycles"], in_accepted=state["accepted"],
                        probes={k: np.array(v, dtype=np.int64) for k, v in probe_vals.items()},
                        final=final_vals)


# -- a simulator kept running across steps ---------------------------------------------------
class PysimSession(FrontendSession):
    """A stream component in one ``amaranth.sim`` simulator, kept running across steps.

    The testbench is the per-cycle loop of :func:`run_stream` (same sampling,
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
        super().__init__()
        self.dut = dut
        self._resolve = lambda p: resolve_port(dut, p)
        self._inputs = [(resolve_port(dut, p), int(v)) for p, v in input_items(inputs)]
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
