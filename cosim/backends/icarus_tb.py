"""The cocotb test that runs inside Icarus Verilog's ``vvp`` for :mod:`cosim.backends.icarus`.

It is not a test of its own: :class:`cosim.backends.icarus.IcarusSession` starts ``vvp`` with
this module as cocotb's test module (``cocotb_tools.runner``) and then drives it over a
Unix socket (``KFNAV_ICARUS_SOCKET``): the session sends one message per step, this
coroutine runs the step's cycles on the design and answers with the output words.

Messages (pickled tuples, :class:`multiprocessing.connection.Connection`):

- ``("init", {port: value}, outputs)``: every input port of the top but ``clk`` set (``rst``
  and the inputs nobody writes to 0, the constant inputs to their values) and the clock
  started (a cocotb :class:`~cocotb.clock.Clock`, period 2 ns, first rising edge at 1 ns);
  ``outputs`` names the output ports; answer ``"ok"``.
- ``("step", words, valid, ready, n, writes, probes)``: run ``n`` cycles. ``words`` are the input
  payloads still queued (ints, already masked to the port width), offered one per cycle in
  order; ``valid`` (list of bool, may be shorter than ``n``: valid after its end) gates the
  offer; ``ready`` (list of bool, shorter: ready after its end) is ``o.ready``; ``writes``
  ``(cycle of the step, port, value)`` in cycle order set a port before that cycle's edge.
  ``probes`` names ports whose values are recorded at every edge (unsigned ints).
  Answer ``(out_words, out_cycles, accepted, unknown, probe_values)``, the cycles counted
  from the step's start, ``probe_values`` one list per probe; ``unknown`` is None, or ``(cycle, port, bits)`` for the first output found X or Z
  (four-state: ``bits`` as Verilog shows them, e.g. ``"0x1z"``), and the step ended at that
  cycle. Checked are, at every edge, ``o.valid``, ``i.ready`` when a word is offered and
  ``o.payload`` when it is taken, the probes at every edge, and at the step's last edge
  every output port.
- ``("read", port)``: the port's value after the last edge, settled: an unsigned int, or its
  bits as a string when some are X or Z.
- ``("close",)``: end the test (answer ``"ok"``).

The simulator does not advance while the coroutine waits for a message, so the clock stops
between steps. Per cycle it does what the Verilator harness
(:mod:`cosim.backends.verilator_harness`) and :func:`cosim.backends.pysim.run_stream` do:
the cycle's inputs (``i.valid``, ``i.payload`` only when offering, so it holds its last
value otherwise, ``o.ready``, the writes) are written after the previous rising edge (cocotb
applies writes in the read-write phase, after the edge's register updates) and settle before
the next; at that edge, before its updates, ``o.valid``/``o.payload`` and ``i.ready`` are
sampled (the values the edge sees). Only values that change are written. This module imports
nothing of the project: it runs in the simulator's embedded Python, and
``python -m cosim verilog --cocotb`` copies it beside an exported design as the driver
(:class:`StreamDriver`) of the standalone cocotb test (:mod:`cosim.tools.cocotb_export`).
"""
from __future__ import annotations

import os
import socket
from multiprocessing.connection import Connection

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import FallingEdge, ReadOnly, RisingEdge

#: Environment variable naming the session's socket (``cosim.backends.icarus.SOCKET_ENV``).
SOCKET_ENV = "KFNAV_ICARUS_SOCKET"


def _connect() -> Connection:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.connect(os.environ[SOCKET_ENV])
    return Connection(s.detach())


def _uint(v) -> int:
    """A resolvable value as an unsigned int (a ``LogicArray``, or a ``Logic`` of a 1-bit
    port)."""
    return v.to_unsigned() if hasattr(v, "to_unsigned") else int(v)


def _unsigned(handle):
    """The handle's value as an unsigned int, or its bits (a string) when some are X or Z."""
    v = handle.value
    return _uint(v) if v.is_resolvable else str(v)


class StreamDriver:
    """The design's stream ports driven cycle by cycle (:meth:`step`), on the clock ``clk``
    the caller starts (here a cocotb :class:`~cocotb.clock.Clock`, 2 ns, first rising edge
    at 1 ns). ``outputs``: the output ports checked for X/Z at a step's last edge. Between
    steps the coroutine sits right after a rising edge (its writes still to come) or, after
    a read, in the read-only phase of one."""

    def __init__(self, dut, outputs=()):
        self.dut = dut
        self.outputs = [(name, getattr(dut, name)) for name in outputs]
        self.clk = dut.clk
        has_in = hasattr(dut, "i__valid")
        self.i_valid = dut.i__valid if has_in else None
        self.i_payload = dut.i__payload if has_in and hasattr(dut, "i__payload") else None
        self.i_ready = dut.i__ready if has_in and hasattr(dut, "i__ready") else None
        self.o_valid = dut.o__valid
        self.o_payload = dut.o__payload
        self.o_ready = dut.o__ready if hasattr(dut, "o__ready") else None
        self.edge = RisingEdge(self.clk)
        self.read_only = False

    async def writable(self):
        """Leave a read-only phase (to the falling edge: no rising edge is skipped)."""
        if self.read_only:
            await FallingEdge(self.clk)
            self.read_only = False

    async def settled(self):
        """The values after the last edge, settled (read-only phase)."""
        if not self.read_only:
            await ReadOnly()
            self.read_only = True

    async def step(self, msg):
        """One step (module doc): the inputs of cycle ``k`` are written before its edge
        (applied after the previous edge's register updates, as cocotb defers writes to the
        read-write phase), and at the edge the outputs are the values the edge sees."""
        _, words, valid, ready, n, writes, probes = msg
        await self.writable()
        dut, edge = self.dut, self.edge
        i_valid, i_payload, i_ready = self.i_valid, self.i_payload, self.i_ready
        o_valid, o_payload, o_ready = self.o_valid, self.o_payload, self.o_ready
        has_in = i_valid is not None
        handles = {p: getattr(dut, p) for _, p, _ in writes}
        probed = [(name, getattr(dut, name), []) for name in probes]
        pv = [vals for _, _, vals in probed]
        n_words, n_valid, n_ready, n_writes = len(words), len(valid), len(ready), len(writes)
        out_w, out_c = [], []
        accepted, w = 0, 0
        last_valid, last_ready = None, None
        for cyc in range(n):
            while w < n_writes and writes[w][0] <= cyc:
                handles[writes[w][1]].value = writes[w][2]
                w += 1
            offer = False
            if has_in:
                offer = accepted < n_words and (cyc >= n_valid or bool(valid[cyc]))
                if offer != last_valid:
                    i_valid.value = int(offer)
                    last_valid = offer
                if offer and i_payload is not None:
                    i_payload.value = words[accepted]
            rdy = True if cyc >= n_ready else bool(ready[cyc])
            if o_ready is not None and rdy != last_ready:
                o_ready.value = int(rdy)
                last_ready = rdy
            await edge
            v = o_valid.value
            if not v.is_resolvable:
                return out_w, out_c, accepted, (cyc, "o__valid", str(v)), pv
            for name, h, vals in probed:
                p = h.value
                if not p.is_resolvable:
                    return out_w, out_c, accepted, (cyc, name, str(p)), pv
                vals.append(_uint(p))
            if rdy and v:
                v = o_payload.value
                if not v.is_resolvable:
                    return out_w, out_c, accepted, (cyc, "o__payload", str(v)), pv
                out_w.append(_uint(v))
                out_c.append(cyc)
            if offer:
                if i_ready is not None:
                    v = i_ready.value
                    if not v.is_resolvable:
                        return out_w, out_c, accepted, (cyc, "i__ready", str(v)), pv
                    if not v:
                        continue
                accepted += 1
        if n:   # every output as the step's last edge saw it
            for name, h in self.outputs:
                v = h.value
                if not v.is_resolvable:
                    return out_w, out_c, accepted, (n - 1, name, str(v)), pv
        return out_w, out_c, accepted, None, pv


@cocotb.test()
async def serve(dut):
    """Serve the session's steps until it closes (module doc)."""
    conn = _connect()
    drv = None
    try:
        while True:
            msg = conn.recv()
            kind = msg[0]
            if kind == "init":
                for port, value in msg[1].items():
                    getattr(dut, port).value = value
                drv = StreamDriver(dut, msg[2])
                Clock(dut.clk, 2, unit="ns").start(start_high=False)
                conn.send("ok")
            elif kind == "step":
                conn.send(await drv.step(msg))
            elif kind == "read":
                await drv.settled()
                conn.send(_unsigned(getattr(dut, msg[1])))
            elif kind == "close":
                conn.send("ok")
                return
            else:
                raise ValueError(f"unknown message {kind!r}")
    finally:
        conn.close()
