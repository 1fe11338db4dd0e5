"""The bit-exact model of the monopulse front end as a persistent session
(:class:`cosim.session.FrontendSession`): the ``model`` backend for
:class:`hdl.monopulse.params.MonopulseFrontendParams`, with the same ports and the same bits
as the ``pysim`` / ``verilator`` sessions of :class:`hdl.monopulse.frontend.MonopulseFrontEnd`.
"""
from __future__ import annotations

import numpy as np

from hdl.model.fifo import FifoState

from ..session import FrontendSession, fifo_step

__all__ = ["MonopulseModelSession", "write_register", "BUS_PORTS"]

#: The register bus ports (the only writable ports).
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


class MonopulseModelSession(FrontendSession):
    """:class:`~hdl.monopulse.model.MonopulseFrontendModel` (state carried) and the FIFO
    model (:func:`~hdl.model.fifo.fifo_model_events`, state carried) as a session.

    Input words are :func:`~hdl.monopulse.params.pack_input` words, one offered per cycle
    while queued. Writes are port writes on :data:`BUS_PORTS` (as the HDL sessions take
    them; :func:`write_register` makes one bus write); a register write happens in every
    cycle ``reg_we`` is high, with the ``reg_addr`` / ``reg_data`` of that cycle. Each step
    processes the snapshots that reach the correction stage before its last cycle (a later
    write may still precede their block boundary); a record written to the FIFO after the
    step waits for the next. Reads: ``overflow_count`` and the bus ports.

    Parameters
    ----------
    params : MonopulseFrontendParams
    log_ranges : bool
        Accepted for the :func:`cosim.session.open_frontend` interface; this model keeps no
        range log (ValueError if True).
    """

    backend = "model"

    def __init__(self, params, *, log_ranges: bool = False):
        from hdl.monopulse.model import MonopulseFrontendModel
        if log_ranges:
            raise ValueError("the monopulse front-end model keeps no range log "
                             "(log_ranges=False)")
        super().__init__()
        self.params = params
        self.model = MonopulseFrontendModel(params)
        self._fifo_state = FifoState()
        self._carry_c = np.zeros(0, np.int64)
        self._carry_w = np.zeros((0, params.record_words), np.int64)
        self._bus = {"reg_we": 0, "reg_addr": 0, "reg_data": 0}
        self.n_records = 0

    def _check_port(self, port) -> None:
        if port not in BUS_PORTS:
            raise KeyError(f"the monopulse front-end model's writable ports are "
                           f"{', '.join(BUS_PORTS)}, not {port!r}")

    def _read(self, port):
        if port == "overflow_count":
            return self._fifo_state.overflow
        if port in self._bus:
            return self._bus[port]
        raise KeyError(f"the monopulse front-end model reads overflow_count and "
                       f"{', '.join(BUS_PORTS)}, not {port!r}")

    @property
    def fifo_state(self) -> FifoState:
        return self._fifo_state

    def _bus_writes(self, writes, start: int, stop: int) -> list[tuple[int, int, int]]:
        """Port writes of the step -> register writes (cycle, reg, value). A held
        ``reg_we`` rewrites the same value each cycle, which changes nothing, so a write is
        emitted where ``reg_we`` rises or the address/data change while it is high."""
        out = []
        bus = self._bus
        k = 0
        while k < len(writes):
            c = writes[k][0]
            while k < len(writes) and writes[k][0] == c:
                bus[writes[k][1]] = writes[k][2]
                k += 1
            if bus["reg_we"]:
                out.append((c, bus["reg_addr"], bus["reg_data"]))
        return out

    def _step(self, queue, ready, n, writes):
        from hdl.monopulse.params import unpack_input
        p = self.params
        start, stop = self.cycle, self.cycle + n
        words = queue[:n]
        x, chips = unpack_input(words, p)
        reg = self._bus_writes(writes, start, stop)
        r = self.model.step(x, chips, reg, cycles=start + np.arange(x.shape[0]),
                            horizon=stop)
        self.n_records += len(r.values)
        w = np.array([p.record.to_words(v, p.fifo_width) for v in r.values],
                     np.int64).reshape(-1, p.record_words)
        wc = np.r_[self._carry_c, r.cycles]
        w = np.concatenate([self._carry_w, w])
        now = wc < stop
        self._carry_c, self._carry_w = wc[~now], w[~now]
        wc, w = wc[now], w[now]
        words, cycles, self._fifo_state = fifo_step(wc, w, ready, n, start, p.fifo,
                                                    self._fifo_state)
        return words, cycles, x.shape[0]
